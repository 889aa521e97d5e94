"""Where `jaxrot.identify`'s compiled time goes on `benchmarks/identify_speed.py`'s problem.

The test satellite (`tests/_telemetry.py`: 3 manoeuvres of 121 samples, 27 parameters) is fitted
stage by stage, with everything compiled first; each figure is the median of ``--rounds`` rounds in
which every item runs once (interleaved, so a drift of the machine moves all alike):

- one Jacobian evaluation of the whole record (residuals + forward-mode tangents) and one residual
  evaluation alone;
- the Gauss–Newton solve (one compiled loop, `_solve`) as `identify` runs it (the windows only for a
  far start) and forced through the growing windows, with the iterations and the largest difference
  of the optimum;
- the uncertainty stage (covariance, identifiability) and the health check (`_health.diagnose`).

    python benchmarks/identify_profile.py             # ~1 minute on 2 idle cores
    XLA_FLAGS="--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1" \\
        python benchmarks/identify_profile.py         # one thread: steadier on a loaded machine
"""

import argparse
import pathlib
import statistics
import sys
import time

import jax


jax.config.update("jax_enable_x64", True)
sys.path.insert(0, str(pathlib.Path(__file__).parents[1] / "tests"))

import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from _telemetry import dipole_torque, satellite_experiments  # noqa: E402

from jaxrot._fit._identify import _solve  # noqa: E402
from jaxrot._fit._identify._check import check_arguments  # noqa: E402
from jaxrot._fit._identify._health import diagnose  # noqa: E402
from jaxrot._fit._identify._identify import DEFAULT_SCHEME  # noqa: E402
from jaxrot._fit._identify._model import residuals, residuals_and_jacobian  # noqa: E402
from jaxrot._fit._identify._problem import build_problem  # noqa: E402
from jaxrot._fit._identify._start import starting_point  # noqa: E402
from jaxrot._fit._identify._uncertainty import uncertainty  # noqa: E402


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=7)
    opts = parser.parse_args(argv)
    experiments, _ = satellite_experiments(0)
    settings = check_arguments(
        experiments, torque=dipole_torque, args={"dipole": jnp.zeros(3)}, free_args={"dipole": True},
        inertia0=None, free_inertia=True, scheme=DEFAULT_SCHEME, dt=None, q0=None, omega0=None,
        max_iter=100, ftol=1e-10, rcond=None, sensors=None,
    )  # fmt: skip
    start = starting_point(settings)
    problem = build_problem(settings, start)
    model = problem.model
    jacobian, residual = eqx.filter_jit(residuals_and_jacobian), eqx.filter_jit(residuals)

    def solve(use_windows):
        return _solve.solve(problem, settings, start.speed, use_windows=use_windows)

    as_run, with_w = solve(None), solve(True)
    found = uncertainty(with_w, settings)
    z = jnp.asarray(with_w.phi)
    items = {
        "one Jacobian evaluation (whole record)": lambda: jax.block_until_ready(jacobian(z, model)),
        "one residual evaluation (whole record)": lambda: jax.block_until_ready(residual(z, model)),
        f"solve as identify runs it (windows: {as_run.windowed}, {as_run.n_iterations} iterations)": (
            lambda: solve(None)
        ),
        f"solve forced through the windows ({with_w.n_iterations} iterations)": lambda: solve(True),
        "uncertainty (covariance, identifiability)": lambda: uncertainty(with_w, settings),
        "health check": lambda: diagnose(settings, with_w, found, problem.estimated),
    }
    for fn in items.values():
        fn()  # compiled before timing
    times = {name: [] for name in items}
    for _ in range(opts.rounds):
        for name, fn in items.items():
            t = time.perf_counter()
            fn()
            times[name].append(time.perf_counter() - t)
    steps = model.data.step_start.shape[1]
    shown = _solve.windows(model, settings)
    print(f"{settings.k} experiments, {steps} steps each, J {with_w.jac.shape}; window steps {shown}")
    print(f"optimum as run and through the windows: max |Δφ| {np.max(np.abs(with_w.phi - as_run.phi)):.2g}")
    print(f"evaluations (residuals + Jacobian): as run {as_run.evaluations}, windows {with_w.evaluations}")
    print("| stage | median [ms] |\n|---|---|")
    for name, values in times.items():
        print(f"| {name} | {1e3 * statistics.median(values):.2f} |")


if __name__ == "__main__":
    main()
