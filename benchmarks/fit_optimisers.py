"""`fit_inertia`'s optimiser (Gauss–Newton, damped) against optimistix's ``least_squares`` solvers.

Run: ``python benchmarks/fit_optimisers.py`` (float64, CPU; ``--repeats 5`` by default).

The problems are those of ``tests/test_fit.py`` (and ``benchmarks/fit_memory.py``): a
body with moments (2, 3, 4) in a rotated body frame, 200 noisy orientations (1e-3 rad
per rotation-vector component) over 10 s of the reference solution, torque-free and as
a heavy top; and noise-free orientations stepped by Zhao itself (400 steps, every 20th
saved), torque-free and as a heavy top. Every optimiser starts from `fit_inertia`'s own
start (the linear angular-momentum estimate) and works on the same objective:

- ``GN (jaxrot)``: ``jaxrot._fit._fit_inertia._solve.solve``, `fit_inertia`'s optimiser with its
  defaults (Gauss–Newton with a backtracking Armijo search, one compiled loop,
  forward-mode Jacobian, ``ftol=1e-7`` or the round-off floor, the loss history kept);
- ``LM`` and ``GN (optimistix)``: ``optimistix.least_squares`` with
  ``LevenbergMarquardt`` / ``GaussNewton`` (``rtol=atol=1e-10``, their own Cauchy
  termination, ``jax.linearize`` Jacobians) on the residual vector whose sum of squares
  is `fit_inertia`'s objective (``jaxrot._fit._fit_inertia._residuals.residuals``).

Each optimiser runs once to compile; then the three run interleaved ``--repeats`` times
and the median wall time is printed, with the ratio to ``GN (jaxrot)``'s median of the
same run (the ratios hold on a loaded machine, the seconds less so), the iterations, the
final objective, whether the optimiser reported success and the fitted principal
moments (divided by the smallest for torque-free fits). The table of the L-BFGS
optimiser that Gauss–Newton replaced is in ``jaxrot/_fit/_optimiser.py``.
"""

import argparse
import os
import platform
import statistics
import time

import jax


jax.config.update("jax_enable_x64", True)

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import optimistix as optx

import jaxrot
from jaxrot import _fit, quaternion as quat
from jaxrot._fit._fit_inertia import _model, _residuals, _start
from jaxrot._fit._fit_inertia._solve import round_off_floor, solve
from jaxrot._fit._parameterisation import _flat, _unflat


MOMENTS = jnp.array([2.0, 3.0, 4.0])
PRINCIPAL_TO_BODY = quat.exp(jnp.array([0.4, -0.7, 0.25]))
TENSOR = quat.to_matrix(PRINCIPAL_TO_BODY) @ jnp.diag(MOMENTS) @ quat.to_matrix(PRINCIPAL_TO_BODY).T
STATE = jaxrot.RotState(quat.exp(jnp.array([0.1, 0.2, 0.3])), jnp.array([0.8, -0.5, 1.5]))
ARGS = {"offset": jnp.array([0.1, 0.05, 0.3]), "weight": jnp.array([0.0, 0.0, -9.81])}
NOISE = 1e-3
TOL = 1e-10


def gravity(t, q, omega, args):
    return jnp.cross(quat.rotate(q, args["offset"]), args["weight"])


def noisy(torque_on, n=200, t_end=10.0):
    ts = jnp.linspace(0.0, t_end, n)
    ref = jaxrot.reference_rollout(
        STATE, TENSOR, ts, torque=gravity if torque_on else None, args=ARGS, rtol=1e-12, atol=1e-12
    )
    noise = NOISE * jax.random.normal(jax.random.PRNGKey(0), (n, 3), dtype=jnp.float64)
    return jaxrot.Trajectory(ts, quat.multiply(quat.exp(noise), ref.q), None)


def noise_free(torque_on):
    torque = dict(torque=gravity, args=ARGS) if torque_on else {}
    return jaxrot.rollout("zhao", STATE, TENSOR, 0.01, 400, save_every=20, **torque)


CASES = {
    "noisy, torque-free": (lambda: noisy(False), False, {}),
    "noisy, heavy top": (lambda: noisy(True), True, {}),
    "noise-free, torque-free": (lambda: noise_free(False), False, {"substeps": 20}),
    "noise-free, heavy top": (lambda: noise_free(True), True, {"substeps": 20}),
}


def set_up(obs, torque_on, options):
    """`fit_inertia`'s problem, start parameters, free coordinates and round-off floor."""
    torque = dict(torque=gravity, args=ARGS) if torque_on else dict(torque=None, args=None)
    unit_trace = not torque_on
    problem, observations = _model.build_model(obs, segments=1, unit_trace=unit_trace, **torque, **options)
    params = _start.starting_point(
        observations, **torque, unit_trace=unit_trace, segments=1, inertia0=None, omega0=None
    )
    free = np.arange(1 if unit_trace else 0, 12)
    floor = round_off_floor(problem, float(np.max(np.linalg.norm(observations.omega_estimate, axis=-1))))
    return problem, params, free, floor


def jaxrot_gn(problem, params, free, floor):
    out = solve(
        params, problem, free, adam_steps=0, adam_learning_rate=1e-2, max_iter=500, ftol=1e-7, floor=floor
    )
    return out.params, out.n_iterations, out.converged


@eqx.filter_jit
def _solve(solver, x0, free, like, problem):
    def residuals(z, _):
        return _residuals.residuals(_unflat(x0.at[free].set(z), like, x0.dtype), problem)[0]

    sol = optx.least_squares(residuals, solver, x0[free], max_steps=200, throw=False)
    return x0.at[free].set(sol.value), sol.stats["num_steps"], sol.result == optx.RESULTS.successful


def optimistix(solver, problem, params, free):
    x, steps, ok = _solve(solver, jnp.asarray(_flat(params)), jnp.asarray(free), params, problem)
    return _unflat(x, params, jnp.float64), int(steps), bool(ok)


OPTIMISERS = {
    "GN (jaxrot)": jaxrot_gn,
    "LM (optimistix)": lambda problem, params, free, floor: optimistix(
        optx.LevenbergMarquardt(rtol=TOL, atol=TOL), problem, params, free
    ),
    "GN (optimistix)": lambda problem, params, free, floor: optimistix(
        optx.GaussNewton(rtol=TOL, atol=TOL), problem, params, free
    ),
}


def run_case(name, repeats):
    make, torque_on, options = CASES[name]
    problem, params, free, floor = set_up(make(), torque_on, options)
    objective = jax.jit(_residuals.objective)
    results, first, times = {}, {}, {label: [] for label in OPTIMISERS}
    for label, optimise in OPTIMISERS.items():
        start = time.perf_counter()
        results[label] = optimise(problem, params, free, floor)
        first[label] = time.perf_counter() - start
    for _ in range(repeats):
        for label, optimise in OPTIMISERS.items():
            start = time.perf_counter()
            out = optimise(problem, params, free, floor)
            times[label].append(time.perf_counter() - start)
            assert np.array_equal(_flat(out[0]), _flat(results[label][0]))  # deterministic
    base = statistics.median(times["GN (jaxrot)"])
    rows = []
    for label in OPTIMISERS:
        fitted, iterations, ok = results[label]
        moments = np.linalg.eigvalsh(
            np.asarray(_fit.inertia_from_cholesky(fitted.chol, unit_trace=problem.unit_trace))
        )
        if problem.unit_trace:
            moments = moments / moments[0]
        median = statistics.median(times[label])
        rows.append(
            (
                name,
                label,
                first[label],
                median,
                median / base,
                iterations,
                float(objective(fitted, problem)),
                ok,
                moments,
            )
        )
    return rows


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--cases", nargs="*", default=list(CASES), choices=list(CASES))
    opts = parser.parse_args()
    print(
        f"machine: {platform.machine()} {platform.processor() or ''} · {os.cpu_count()} CPUs · "
        f"load average {os.getloadavg()[0]:.1f} · Python {platform.python_version()} · "
        f"jax {jax.__version__} · "
        f"optimistix {getattr(optx, '__version__', '?')} · backend {jax.default_backend()} · float64 · "
        f"median of {opts.repeats} interleaved runs"
    )
    print()
    print(
        "| data | optimiser | first call s (compiles) | median s | × GN (jaxrot) | iterations "
        "| final objective | success | fitted moments |"
    )
    print("|---|---|---:|---:|---:|---:|---:|---|---|")
    for name in opts.cases:
        for row in run_case(name, opts.repeats):
            data, label, first, median, ratio, iterations, loss, ok, moments = row
            shown = ", ".join(f"{m:.10f}" for m in moments)
            print(
                f"| {data} | {label} | {first:.2f} | {median:.3f} | {ratio:.2f} | {iterations} | {loss:.4e} "
                f"| {ok} | {shown} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
