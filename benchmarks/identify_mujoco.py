"""`jaxrot.identify` against MuJoCo 4.0's `mujoco.sysid` on data MuJoCo made: ideal sensors and real ones.

Part of `benchmarks/identify_speed.py` (its ``--mujoco-seeds`` and ``--sensor-seeds``), which writes
these rows beside the diffrax + optimistix ones. The data (`tests/_mujoco_telemetry.py`): a free body
with a full inertia tensor, three 10 s manoeuvres under body-frame motor torques held for each 1 ms
step, orientation and gyro at 100 Hz, σ = 1e-4 rad and rad/s.

- **ideal sensors** (`mujoco_rows`, key ``"mujoco"``): sysid as a user writes it
  (`tests/_mujoco_sysid.py`), fitting each manoeuvre's initial state too (a custom rollout), and with
  sysid's default initial state (the first samples); jaxrot with the controls as MuJoCo applies them
  (``control_frame="body"``, ``control_hold="previous"``).
- **real sensors** (key ``"mujoco_sensors"``): the same manoeuvres seen through a gyro with a bias per
  manoeuvre, a scale error and a 4 ms delay, and a star tracker mounted 0.023 rad off the body axes
  with a 7 ms delay (`_mujoco_telemetry.sensor_manoeuvres`). Each tool fits the inertia, every
  initial state and all five flaws: jaxrot with ``identify(sensors=...)``, sysid with the expressions
  of `tests/_mujoco_sysid_sensors.py` (it has one for each flaw: a row lists any flaw a tool left out).

Both start from the same sphere (0.045 kg m²), ideal sensors and the first samples; for each noise
seed every fit runs once, round-robin; a row gives the median wall time (jaxrot's compiled, and its
first call), the median relative error ‖I − I_true‖_F / ‖I_true‖_F, and how often the 95 % intervals
of the six inertia elements hold the truth (over 4 seeds: 24 intervals, so a calibrated 0.95 reads
0.88-1.0 with probability 0.9 for independent elements). `capabilities` (`_identify_capabilities`)
is what each tool can express, written beside the rows. Skipped with a message where
``mujoco[sysid]`` is not installed (``pip install -e ".[mujoco]"``).
"""

import pathlib
import statistics
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np


sys.path.insert(0, str(pathlib.Path(__file__).parents[1] / "tests"))

import jaxrot  # noqa: E402
from jaxrot import quaternion as quat  # noqa: E402


Z95 = 1.959963984540054
SENSORS = ("gyro_bias", "gyro_scale", "gyro_delay", "tracker_mount", "tracker_delay")


def mujoco_identify_inputs(manoeuvres):
    """``(experiments, keywords)`` of `jaxrot.identify` for MuJoCo's manoeuvres (`tests/_mujoco_telemetry.py`;
    needs MuJoCo): their held body-frame motor torques, the initial states from the first samples."""
    import _mujoco_sysid as ms

    experiments = [
        jaxrot.Experiment(
            m.t, q=m.q, omega_body=m.omega_body, sigma_q=m.sigma_q, sigma_omega=m.sigma_omega,
            control=(m.t_c, m.tau_c), control_frame="body", control_hold="previous",
        )
        for m in manoeuvres
    ]  # fmt: skip
    q0 = np.stack([m.q[0] for m in manoeuvres])
    omega0 = np.asarray(
        quat.rotate(jnp.asarray(q0), jnp.asarray(np.stack([m.omega_body[0] for m in manoeuvres])))
    )
    return experiments, {"inertia0": ms.INERTIA0, "q0": q0, "omega0": omega0}


def _table(rows, title):
    print(f"\n{title}\n| fit | median wall time [s] | relative error | 95 % interval coverage |")
    print("|---|---|---|---|")
    for row in rows:
        cells = [
            row["fit"],
            f"{row['median_s']:.2f}",
            f"{row['relative_error']:.1e}",
            f"{row['coverage95']:.2f}",
        ]
        print("| " + " | ".join(cells) + " |")


def _compare(fits, make_data, n_seeds, first_calls, truth, extra=None):
    """Each of ``fits`` (label -> fn(manoeuvres) -> (inertia, stderr)) once per seed, round-robin: rows."""
    upper = np.triu_indices(3)
    results = {label: [] for label in fits}
    for seed in range(n_seeds):
        manoeuvres = make_data(seed)
        for label, fit in fits.items():
            t0 = time.perf_counter()
            inertia, se = jax.block_until_ready(fit(manoeuvres))
            seconds = time.perf_counter() - t0
            error = float(np.linalg.norm(inertia - truth) / np.linalg.norm(truth))
            inside = np.abs(inertia - truth)[upper] <= Z95 * se[upper]
            results[label].append((seconds, error, inside))
            print(f"  seed {seed}: {label}: {seconds:.2f} s, error {error:.2e}, {inside.sum()}/6 inside")
    return [
        {
            "fit": label,
            "median_s": statistics.median(r[0] for r in runs),
            "first_call_s": first_calls.get(label),
            "relative_error": statistics.median(r[1] for r in runs),
            "coverage95": float(np.mean([r[2] for r in runs])),
            "seeds": n_seeds,
            **(extra or {}).get(label, {}),
        }
        for label, runs in results.items()
    ]


def _sensor_report(label, fitted, se):
    """Print each fitted sensor parameter's largest |estimate − truth| in its standard errors."""
    import _mujoco_telemetry as mt

    worst = {
        name: float(
            np.max(np.abs(np.ravel(fitted[name]) - np.ravel(mt.TRUE_SENSORS[name])) / np.ravel(se[name]))
        )
        for name in SENSORS
    }
    print(f"    {label}: sensors' |error| / se: " + ", ".join(f"{k} {v:.1f}" for k, v in worst.items()))


def mujoco_rows(n_seeds, sensor_seeds):
    """``{"mujoco": ideal rows, "mujoco_sensors": real-sensor rows, "capabilities": ...}`` (module
    docstring), or None without MuJoCo; ``n_seeds`` / ``sensor_seeds`` noise seeds (0: no such rows)."""
    try:
        import _mujoco_sysid as ms
        import _mujoco_sysid_sensors as mss
        import _mujoco_telemetry as mt
        from _identify_capabilities import CAPABILITIES
        from mujoco import sysid

        if not hasattr(sysid, "optimize"):
            raise ImportError("mujoco.sysid without its extra")
    except ImportError as error:
        print(f"\nmujoco.sysid rows skipped ({error}): pip install -e '.[mujoco]'")
        return None
    truth = mt.true_inertia()
    out = {"capabilities": [list(row) for row in CAPABILITIES]}

    def jaxrot_fit(manoeuvres, sensors=None):
        experiments, keywords = mujoco_identify_inputs(manoeuvres)
        if sensors:
            keywords["sensors"] = dict.fromkeys(sensors, True)
        fit = jaxrot.identify(experiments, **keywords)
        if sensors:
            _sensor_report("jaxrot", fit.sensors, fit.stderr.sensors)
        return np.asarray(fit.inertia), fit.stderr.inertia

    def sysid_fit(manoeuvres, fit_initial_state):
        fit = ms.sysid_fit(manoeuvres, fit_initial_state=fit_initial_state)
        return fit.inertia, fit.inertia_stderr

    def sysid_sensor_fit(manoeuvres):
        fit = mss.sysid_sensor_fit(manoeuvres)
        se = np.sqrt(np.diag(fit.covariance))
        index = {name: i for i, name in enumerate(fit.names)}
        k = len(manoeuvres)
        stderr = {
            name: se[[index[f"{name}[{i}]"] for i in range(fit.extra[name].size)]]
            for name in mss.SENSOR_NAMES
        }
        stderr["gyro_bias"] = np.stack(
            [se[[index[f"gyro_bias_{j}[{i}]"] for i in range(3)]] for j in range(k)]
        )
        _sensor_report("sysid", fit.extra, stderr)
        return fit.inertia, fit.inertia_stderr

    def first_call(fn, data):
        t0 = time.perf_counter()
        jax.block_until_ready(fn(data))
        return time.perf_counter() - t0

    if n_seeds:
        ours = "jaxrot.identify (controls held in the body frame)"
        fits = {
            ours: jaxrot_fit,
            "mujoco.sysid, fitting the initial state too (a custom rollout)": lambda m: sysid_fit(m, True),
            "mujoco.sysid, initial state from the first samples (its default)": lambda m: sysid_fit(m, False),
        }
        first = {ours: first_call(jaxrot_fit, mt.manoeuvres(noise_seed=0))}
        out["mujoco"] = _compare(fits, lambda seed: mt.manoeuvres(noise_seed=seed), n_seeds, first, truth)
        _table(out["mujoco"], "Ideal sensors:")
    if sensor_seeds:
        ours = "jaxrot.identify, fitting the five sensor flaws"
        theirs = "mujoco.sysid, fitting the five sensor flaws and the initial states"
        fits = {ours: lambda m: jaxrot_fit(m, SENSORS), theirs: sysid_sensor_fit}
        first = {ours: first_call(fits[ours], mt.sensor_manoeuvres(noise_seed=0))}
        # Both fit every flaw (sysid with the expressions of `SYSID_EXPRESSES`); "left_out" names any not.
        extra = {
            ours: {"fitted": list(SENSORS), "left_out": []},
            theirs: {
                "fitted": sorted(mss.SYSID_EXPRESSES),
                "left_out": sorted(set(SENSORS) - set(mss.SYSID_EXPRESSES)),
            },
        }
        make = lambda seed: mt.sensor_manoeuvres(noise_seed=seed)  # noqa: E731
        out["mujoco_sensors"] = _compare(fits, make, sensor_seeds, first, truth, extra)
        _table(
            out["mujoco_sensors"],
            "Real sensors (gyro bias per manoeuvre, scale, delay; tracker mount, delay):",
        )
    return out
