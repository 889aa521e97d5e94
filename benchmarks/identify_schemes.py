"""Which scheme and step `jaxrot.identify` should default to: bias against cost on the test satellite.

Run: ``python benchmarks/identify_schemes.py`` (about 4 minutes on 2 cores). Prints a Markdown
table: for each scheme and step angle, the largest error of the fitted inertia and dipole on
noise-free reference data in units of the noisy fit's standard errors, the time of a compiled
fit, and of the first call (compile included).
"""

import pathlib
import sys
import time

import jax


jax.config.update("jax_enable_x64", True)
sys.path.insert(0, str(pathlib.Path(__file__).parents[1] / "tests"))

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from _telemetry import SATELLITE_DIPOLE, SATELLITE_INERTIA, dipole_torque, satellite_experiments  # noqa: E402

import jaxrot  # noqa: E402
import jaxrot._fit._identify._start as identify_start  # noqa: E402
from jaxrot.comparison import machine_info  # noqa: E402


print(machine_info())
exps, truth = satellite_experiments(0, noise=False)
noisy, _ = satellite_experiments(0)
args = {"dipole": jnp.zeros(3)}
ref = jaxrot.identify(noisy, torque=dipole_torque, args=args, free_args={"dipole": True}, scheme="rkmk4")
print("| scheme | step angle | substeps | bias / se (max over inertia, dipole) | run s | first call s |")
ANGLES = {  # label: (scheme, step angles in rad)
    "zhao": ("zhao", [0.05, 0.2]),
    "rkmk4": ("rkmk4", [0.05, 0.2, 0.5]),
    "rkmk_dopri5": ("rkmk_dopri5", [0.15, 0.3, 0.6]),
    'RKMKDopri5(chart="cayley")': (jaxrot.schemes.RKMKDopri5(chart="cayley"), [0.3, 0.6]),
    "splitting": ("splitting", [0.05]),
}
for label, (scheme, angles) in ANGLES.items():
    for angle in angles:
        identify_start.DEFAULT_STEP_ANGLE = angle
        try:
            t0 = time.perf_counter()
            fit = jaxrot.identify(
                exps, torque=dipole_torque, args=args, free_args={"dipole": True}, scheme=scheme
            )
            t1 = time.perf_counter()
            fit = jaxrot.identify(
                exps, torque=dipole_torque, args=args, free_args={"dipole": True}, scheme=scheme
            )
            t2 = time.perf_counter()
        except Exception as e:
            print(label, angle, "error", type(e).__name__, str(e)[:200])
            continue
        bias = max(
            np.max(np.abs(np.asarray(fit.inertia) - SATELLITE_INERTIA) / ref.stderr.inertia),
            np.max(np.abs(np.asarray(fit.args["dipole"]) - SATELLITE_DIPOLE) / ref.stderr.args["dipole"]),
        )
        substeps = round(600 / 120 / fit.dt)
        row = f"| {label} | {angle} | {substeps} | {bias:.2g} | {t2 - t1:.2f} | {t1 - t0:.1f} |"
        print(row, "converged" if fit.converged else "NOT converged", flush=True)
