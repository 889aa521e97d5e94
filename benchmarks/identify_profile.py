"""Where `jaxrot.identify`'s compiled time goes, on `benchmarks/identify_speed.py`'s problems.

``--problem satellite`` (default): the test satellite (`tests/_telemetry.py`: 3 manoeuvres of 121
samples, 27 parameters), the problem of the diffrax + optimistix comparison. ``--problem mujoco``: MuJoCo's
three 10 s manoeuvres (`tests/_mujoco_telemetry.py`, 1 ms held body-frame torques, 100 Hz samples) with
ideal sensors; ``mujoco-real``: the same seen through real sensors (`_mujoco_telemetry.sensor_manoeuvres`:
a gyro bias per manoeuvre, gyro scale and delay, tracker mount and delay), all of them fitted.

The problem is prepared as `identify` prepares it (its scheme choice included), everything compiled
first; each figure is the median of ``--rounds`` rounds in which every item runs once (interleaved, so
a drift of the machine moves all alike):

- one Jacobian evaluation of the whole record (residuals + forward-mode tangents), one residual
  evaluation alone, and (``mujoco-real``) one Jacobian evaluation of the same data with the sensor
  parameters held instead of fitted: ideal, with the delays only, with bias, scale and mount only;
- the Gauss–Newton solve (one compiled loop, `_solve`) as `identify` runs it, with its iterations and
  evaluations (time per evaluation = solve / evaluations);
- the uncertainty stage (covariance, identifiability) and the health check (`_health.diagnose`).

    python benchmarks/identify_profile.py [--problem satellite|mujoco|mujoco-real]
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
sys.path.insert(0, str(pathlib.Path(__file__).parent))

import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from _telemetry import dipole_torque, satellite_experiments  # noqa: E402
from identify_speed import INERTIA0  # noqa: E402

from jaxrot import quaternion as quat  # noqa: E402
from jaxrot._fit._identify import _solve  # noqa: E402
from jaxrot._fit._identify._check import check_arguments  # noqa: E402
from jaxrot._fit._identify._health import diagnose  # noqa: E402
from jaxrot._fit._identify._jacobian import n_dynamic, residuals_and_jacobian  # noqa: E402
from jaxrot._fit._identify._model import n_head, n_own, residuals  # noqa: E402
from jaxrot._fit._identify._problem import build_problem  # noqa: E402
from jaxrot._fit._identify._scheme import choose_scheme  # noqa: E402
from jaxrot._fit._identify._start import starting_point  # noqa: E402
from jaxrot._fit._identify._uncertainty import uncertainty  # noqa: E402


ALL_SENSORS = ("gyro_bias", "gyro_scale", "gyro_delay", "tracker_mount", "tracker_delay")


def inputs(problem, fitted=ALL_SENSORS):
    """``(experiments, keywords of identify)`` of a ``--problem``; ``fitted``: the real sensors' fitted
    parameters (the others held at their true values)."""
    if problem == "satellite":  # identify_speed's start: a diagonal inertia, the first samples' states
        experiments, _ = satellite_experiments(0)
        q0 = np.stack([e.q[0] for e in experiments])
        rates = jnp.asarray(np.stack([e.omega_body[0] for e in experiments]))
        omega0 = np.asarray(quat.rotate(jnp.asarray(q0), rates))
        return experiments, {
            "torque": dipole_torque, "args": {"dipole": jnp.zeros(3)}, "free_args": {"dipole": True},
            "inertia0": INERTIA0, "q0": q0, "omega0": omega0,
        }  # fmt: skip
    import _mujoco_telemetry as mt
    from identify_speed import mujoco_identify_inputs

    if problem == "mujoco":
        return mujoco_identify_inputs(mt.manoeuvres(noise_seed=0))
    experiments, keywords = mujoco_identify_inputs(mt.sensor_manoeuvres(noise_seed=0))
    sensors = {name: True if name in fitted else mt.TRUE_SENSORS[name] for name in ALL_SENSORS}
    return experiments, keywords | {"sensors": sensors}


def prepared(experiments, keywords):
    """``(settings, start, problem)`` as `identify` makes them before its solve."""
    arguments = dict(
        torque=None, args=None, free_args=None, inertia0=None, free_inertia=True, scheme=None, dt=None,
        q0=None, omega0=None, max_iter=100, ftol=1e-10, rcond=None, sensors=None,
    )  # fmt: skip
    settings = check_arguments(experiments, **(arguments | keywords))
    start = starting_point(settings)
    problem, _ = choose_scheme(settings, build_problem(settings, start), start.max_step)
    return settings, start, problem


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--problem", default="satellite", choices=("satellite", "mujoco", "mujoco-real"))
    opts = parser.parse_args(argv)
    settings, start, problem = prepared(*inputs(opts.problem))
    model = problem.model
    jacobian, residual = eqx.filter_jit(residuals_and_jacobian), eqx.filter_jit(residuals)

    def solve():
        return _solve.solve(problem, settings, start.speed)

    as_run = solve()
    found = uncertainty(as_run, settings)
    z = jnp.asarray(as_run.phi)
    items = {
        "one Jacobian evaluation (whole record)": lambda: jax.block_until_ready(jacobian(z, model)),
        "one residual evaluation (whole record)": lambda: jax.block_until_ready(residual(z, model)),
    }
    if opts.problem == "mujoco-real":
        variants = {"ideal sensors (none fitted)": (), "delays fitted": ("gyro_delay", "tracker_delay"),
                    "bias, scale, mount fitted": ("gyro_bias", "gyro_scale", "tracker_mount")}  # fmt: skip
        for label, fitted in variants.items():
            _, _, p = prepared(*inputs(opts.problem, fitted))
            phi = jnp.asarray(p.phi0)
            items[f"one Jacobian evaluation, {label}, {phi.size} columns"] = lambda p=p, phi=phi: (
                jax.block_until_ready(jacobian(phi, p.model))
            )
    items |= {
        f"solve as identify runs it (windows: {as_run.windowed}, {as_run.n_iterations} iterations, "
        f"{as_run.evaluations} evaluations)": solve,
        "uncertainty (covariance, identifiability)": lambda: uncertainty(as_run, settings),
        "health check": lambda: diagnose(settings, as_run, found, problem.estimated),
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
    tangents = n_head(model.layout) + n_own(model.layout)
    moving = sum(n_dynamic(model.layout))
    print(
        f"{opts.problem}: {settings.k} experiments, {steps} steps each, scheme {model.scheme.name}, "
        f"J {as_run.jac.shape}, {tangents} tangents per experiment's readings, {moving} in its rollout; "
        f"window steps {_solve.windows(model, settings)}"
    )
    print(f"iterations {as_run.n_iterations}, evaluations (residuals + Jacobian) {as_run.evaluations}, "
          f"converged {as_run.converged}, loss {as_run.history[-1]:.6g}")  # fmt: skip
    print("| stage | median [ms] |\n|---|---|")
    for name, values in times.items():
        print(f"| {name} | {1e3 * statistics.median(values):.2f} |")
    solve_ms = 1e3 * statistics.median(next(v for k, v in times.items() if k.startswith("solve")))
    print(f"solve per evaluation: {solve_ms / as_run.evaluations:.2f} ms")


if __name__ == "__main__":
    main()
