"""The speed/accuracy comparison behind ``python -m jaxrot compare``.

The example is on the package's face (`jaxrot.comparison`).

Every scheme in `SCHEMES` runs on one scene at a ladder of time steps, and the
generic alternative (diffrax Tsit5 and Dopri8 with adaptive steps) at a ladder
of tolerances. Each run is timed over ``particles`` vmapped copies of the
scene's body and its first particle is compared with a tight diffrax reference.
A new scheme gets its rows with no change here.
"""

import os
from concurrent.futures import ThreadPoolExecutor
from typing import Any, NamedTuple

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
from tqdm import tqdm

from .. import quaternion as quat
from .._core._compile import compiler_options
from .._diffrax._reference import adaptive_solve, reference_rollout
from .._inertia import body_inertia
from .._integrate._saved_steps import saved_steps
from .._particles import PARTICLES, flatten_particles, split_per_body
from .._state import RotState
from .._validation import check_bodies
from ..scenes import SCENES
from ..schemes import SCHEMES
from ..schemes._base import advance
from ._report import (
    ASYMPTOTIC_ERROR,
    stalled,
)
from ._timing import compile_timed, time_runs


REFERENCE_TOL = 1e-13
DTYPES = {"float32": jnp.float32, "float64": jnp.float64}


def _adaptive_solver(cls):
    """``(constructor, order, torque calls per attempted step)``, read from the diffrax solver.

    A solve makes ``calls_per_step * steps + 1`` calls (an FSAL tableau reuses its last stage);
    tests/test_compare.py counts them."""
    tableau = cls.tableau
    order = cls().order(diffrax.ODETerm(lambda t, y, args: y))
    return cls, order, tableau.num_stages - (1 if tableau.fsal else 0)


# Generic adaptive solvers on the Euclidean quaternion ODE of `reference_rollout`.
ADAPTIVE_SOLVERS = {
    "diffrax_tsit5": _adaptive_solver(diffrax.Tsit5),
    "diffrax_dopri5": _adaptive_solver(diffrax.Dopri5),
    "diffrax_dopri8": _adaptive_solver(diffrax.Dopri8),
}
# A fixed-step ladder stops below this error (nothing left to resolve against the reference).
LADDER_FLOOR = 1e-12
TOLERANCES = {"float64": (1e-3, 1e-5, 1e-7, 1e-9, 1e-11), "float32": (1e-3, 1e-4, 1e-5, 1e-6)}
# A fixed-step ladder may halve dt this many times more than `levels` while its error is still above
# ASYMPTOTIC_ERROR (a first-order scheme on a coarse grid), and ends at a rung whose run takes
# longer than MAX_RUN_S: the coarsest rung is the same for every scheme, the finest is not.
MAX_SATURATED_RUNGS = 14
MAX_RUN_S = 2.0


def orientation_error(q, q_ref):
    """Largest geodesic angle (radians) between two orientation histories ``(n, ..., 4)``."""
    return float(jnp.max(quat.angle_between(jnp.asarray(q, jnp.float64), jnp.asarray(q_ref, jnp.float64))))


def relative_energy_drift(scene, q, omega):
    """``max_t |E(t) − E(0)| / |E(0)|`` of the scene's total energy (`Scene.energy`), in float64.

    ``q`` ``(n, *bodies, 4)``, ``omega`` ``(n, *bodies, 3)`` for a float64
    ``scene``; None when the scene's torque is not conservative.
    """
    energy = scene.energy(0.0, jnp.asarray(q, jnp.float64), jnp.asarray(omega, jnp.float64))
    if energy is None:
        return None
    return float(jnp.max(jnp.abs(energy - energy[0])) / jnp.abs(energy[0]))


class _Problem(NamedTuple):
    """What every row of one comparison runs on and is measured against."""

    scene: str
    dtype: str
    run_scene: Any  # the scene in the run's dtype
    ref_scene: Any  # the scene in float64, for the reference
    ts: jax.Array  # the coarse grid's times, where errors are measured
    dt_coarse: float
    coarse_steps: int
    ref: Any  # the reference trajectory at ``ts``
    batch: Any  # the timed state: ``particles`` copies of one body, or the scene's bodies
    particles: int
    single: bool  # one body copied ``particles`` times (errors from the first copy)
    inertia: jax.Array  # flattened per-particle inertia, for the adaptive solvers
    per_particle: bool
    flat_args: Any
    args_axes: Any


def compare(
    scene="heavy_top",
    *,
    t_end=None,
    particles=100,
    dtype="float64",
    coarse_steps=5,
    levels=8,
    tolerances=None,
    schemes=None,
    solvers=None,
    repeats=3,
    progress=True,
):
    """Run every scheme and the generic adaptive solvers against the diffrax reference.

    Each fixed-step ladder halves ``dt`` from ``t_end / coarse_steps`` until ``levels`` of its
    rungs have an error at or below `ASYMPTOTIC_ERROR` (0.1 rad), its error stalls at the
    reference's floor, or one run takes longer than `MAX_RUN_S`: so every scheme gets rungs
    from about 0.1 rad down, a high-order one from a coarse step, a first-order one from a fine
    one. The adaptive rows use each of ``tolerances`` (rtol = atol; default `TOLERANCES` for
    the dtype). Errors are measured at the coarse grid's times
    against Dopri8 at rtol = atol = 1e-13 in float64, whatever ``dtype`` runs.
    ``schemes`` (names in `SCHEMES`) and ``solvers`` (names in
    `ADAPTIVE_SOLVERS`) select rows; None means all.

    Each row holds: ``method``, ``kind`` (``"fixed"`` or ``"adaptive"``), nominal
    ``order``, ``dt`` or ``tol``, ``n_steps`` (attempted steps for adaptive
    solvers), ``max_orientation_error_rad`` (geodesic), ``final_omega_error``
    (rad/s, world frame), ``rel_energy_drift`` (`relative_energy_drift`),
    ``torque_evals`` per particle over the horizon, ``us_per_particle_step`` and
    ``us_per_particle_run`` (median compiled wall time over ``particles``
    vmapped bodies, per particle-step and per particle over the whole horizon)
    and ``compile_s`` (seconds to compile the row's program: a fixed-step scheme compiles one
    program for its whole ladder, ``dt`` and the step count runtime values, an adaptive solver one
    for all its tolerances, and each row carries its program's time). Every program compiles with
    `jaxrot.compiler_options`.
    """
    tolerances, schemes, solvers = _check_compare_arguments(
        scene, dtype, particles, coarse_steps, levels, repeats, tolerances, schemes, solvers
    )
    problem = _set_up(scene, dtype, t_end, particles, coarse_steps)
    jobs = [("fixed", name, k) for name in schemes for k in range(levels + MAX_SATURATED_RUNGS)]
    jobs += [("adaptive", name, tol) for name in solvers for tol in tolerances]
    rows = []
    finished = set()  # schemes whose ladder reached its floor or that refuse the scene's torque
    runners = _compile_runners(problem, schemes, solvers)
    for kind, name, level in tqdm(jobs, desc="compare", disable=not progress, leave=False):
        if name in finished:
            continue
        if kind == "adaptive":
            rows.append(_adaptive_row(problem, name, runners[name], level, repeats))
            continue
        if runners[name] is None:  # a splitting that cannot keep its order on this torque
            finished.add(name)
            continue
        row = _fixed_row(problem, name, runners[name], level, repeats)
        rows.append(row)
        ladder = [r["max_orientation_error_rad"] for r in rows if r["method"] == name]
        counted = sum(e <= ASYMPTOTIC_ERROR for e in ladder)
        too_long = row["us_per_particle_run"] * problem.particles * 1e-6 > MAX_RUN_S
        if counted >= levels or ladder[-1] < LADDER_FLOOR or stalled(ladder) or too_long:
            finished.add(name)
    return rows


def _compile_runners(problem: _Problem, schemes, solvers) -> dict:
    """``{name: runner}``: every row's program, compiled before any row is timed.

    On as many threads as the process has cores: XLA compiles a program on one core, and
    releases the GIL while it does, so two cores compile two programs at once (`compare`'s 13
    programs were about 40 % of its time, compiled one after another). Nothing is timed
    meanwhile; each runner's ``compile_s`` is its own program's compile time, on its own core
    while no more threads than cores compile.
    """
    jobs = {name: (_fixed_runner, SCHEMES[name]) for name in schemes}
    jobs.update({name: (_adaptive_runner, name) for name in solvers})
    workers = min(len(jobs), len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else 1)
    with ThreadPoolExecutor(max_workers=max(workers, 1)) as pool:
        futures = {name: pool.submit(build, problem, what) for name, (build, what) in jobs.items()}
        return {name: future.result() for name, future in futures.items()}


def _check_compare_arguments(
    scene, dtype, particles, coarse_steps, levels, repeats, tolerances, schemes, solvers
):
    """`compare`'s arguments checked before anything compiles; the defaults filled in."""
    if scene not in SCENES:
        raise ValueError(f"`scene` must be one of {sorted(SCENES)}; got {scene!r}.")
    if dtype not in DTYPES:
        raise ValueError(f"`dtype` must be one of {sorted(DTYPES)}; got {dtype!r}.")
    for name, value in (("particles", particles), ("coarse_steps", coarse_steps), ("levels", levels)):
        if not (isinstance(value, int) and value >= 1):
            raise ValueError(f"`{name}` must be an integer >= 1; got {value!r}.")
    if not (isinstance(repeats, int) and repeats >= 1):
        raise ValueError(f"`repeats` must be an integer >= 1; got {repeats!r}.")
    if not jax.config.jax_enable_x64:
        raise ValueError(
            'compare needs float64 for its reference: call jax.config.update("jax_enable_x64", True) first.'
        )
    tolerances = TOLERANCES[dtype] if tolerances is None else tuple(tolerances)
    schemes = list(SCHEMES) if schemes is None else list(schemes)
    solvers = list(ADAPTIVE_SOLVERS) if solvers is None else list(solvers)
    for label, chosen, known in (("schemes", schemes, SCHEMES), ("solvers", solvers, ADAPTIVE_SOLVERS)):
        unknown = [x for x in chosen if x not in known]
        if unknown:
            raise ValueError(f"`{label}` has unknown names {unknown}; known: {list(known)}.")
    if not schemes and not solvers:
        raise ValueError("`schemes` and `solvers` are both empty: nothing to compare.")
    if dtype == "float32" and any(tol < 1e-6 for tol in tolerances):
        raise ValueError(f"`tolerances` below 1e-6 cannot be met in float32; got {tolerances}.")
    return tolerances, schemes, solvers


def _set_up(scene, dtype, t_end, particles, coarse_steps) -> _Problem:
    """The scene in both dtypes, the coarse grid, the reference on it and the timed batch."""
    ref_scene = SCENES[scene](jnp.float64)
    run_scene = SCENES[scene](DTYPES[dtype])
    t_end = ref_scene.t_end if t_end is None else float(t_end)
    if not t_end > 0:
        raise ValueError(f"`t_end` must be > 0; got {t_end}.")
    dt_coarse = t_end / coarse_steps
    ts = jnp.arange(coarse_steps + 1, dtype=jnp.float64) * dt_coarse
    rs = ref_scene
    ref = reference_rollout(
        rs.state, rs.inertia, ts, torque=rs.torque, args=rs.args, rtol=REFERENCE_TOL, atol=REFERENCE_TOL
    )
    single = run_scene.state.q.ndim == 1
    if single:  # one body: time it over `particles` vmapped copies
        batch = jax.tree_util.tree_map(lambda x: jnp.broadcast_to(x, (particles, *x.shape)), run_scene.state)
    else:  # the scene's own bodies (they may interact)
        batch, particles = run_scene.state, run_scene.n_bodies
    _, inertia, per_particle = check_bodies(batch, run_scene.inertia)
    batch_shape = batch.q.shape[:-1]
    _, inertia = flatten_particles(batch, inertia, per_particle)
    flat_args, args_axes = split_per_body(run_scene.args, () if single else batch_shape)
    return _Problem(
        scene, dtype, run_scene, ref_scene, ts, dt_coarse, coarse_steps, ref, batch, particles, single,
        inertia, per_particle, flat_args, args_axes,
    )  # fmt: skip


def _accuracy(problem: _Problem, q, omega) -> dict:
    """A row's errors against the reference at the coarse grid's times."""
    if problem.single:
        q, omega = q[:, 0], omega[:, 0]
    omega_gap = jnp.asarray(omega[-1], jnp.float64) - problem.ref.omega[-1]
    return {
        "max_orientation_error_rad": orientation_error(q, problem.ref.q),
        "final_omega_error": float(jnp.max(jnp.linalg.norm(omega_gap, axis=-1))),
        "rel_energy_drift": relative_energy_drift(problem.ref_scene, q, omega),
    }


def _row(problem: _Problem, method, traj, n_steps, evals, seconds, compile_s) -> dict:
    """The fields every row shares: its setting is merged in by the caller."""
    return {
        "scene": problem.scene,
        "dtype": problem.dtype,
        "particles": problem.particles,
        **method,
        "n_steps": n_steps,
        **_accuracy(problem, traj.q, traj.omega),
        "torque_evals": evals,
        "us_per_particle_step": seconds / (problem.particles * max(n_steps, 1)) * 1e6,
        "us_per_particle_run": seconds / problem.particles * 1e6,
        "compile_s": compile_s,
    }


def _fixed_runner(problem: _Problem, scheme):
    """``(compiled, compile s)``: one program per ladder; None if the scheme refuses the torque.

    ``run(state, dt, factor)``: ``init``, then ``coarse_steps`` saves of ``factor`` steps each
    (both ``dt`` and ``factor`` runtime values), vmapped over the flattened bodies as in
    `jaxrot.rollout`; returns the saved ``(q, ω)``, the initial state first. One compilation per
    scheme instead of one per rung: the ladders of `compare` compile 10 programs, not about 50.
    A step with ``dt`` a runtime value runs as fast as with ``dt`` a constant: measured for every
    scheme on 100 heavy tops (rkmk_dopri8 ran 2.6× slower so until its stage sums scaled their
    weights by ``dt``, `jaxrot.schemes._lie_runge_kutta`).
    """
    p, sc = problem, problem.run_scene
    inertia = jax.vmap(body_inertia)(p.inertia) if p.per_particle else body_inertia(p.inertia)
    inertia_axis = 0 if p.per_particle else None
    t0 = jnp.zeros((), DTYPES[p.dtype])

    def run(state, dt, factor):
        flat = RotState(state.q.reshape(-1, 4), state.omega.reshape(-1, 3))
        init = jax.vmap(
            lambda s, i, a: scheme.init(s, t0, i, sc.torque, a),
            in_axes=(0, inertia_axis, p.args_axes),
            axis_name=PARTICLES,
        )
        step = jax.vmap(
            lambda c, t, k, i, a: advance(scheme, c, k, t, t0, dt, i, sc.torque, a),
            in_axes=(0, None, None, inertia_axis, p.args_axes),
            axis_name=PARTICLES,
        )

        carry = init(flat, inertia, p.flat_args)
        saved = saved_steps(
            carry,
            lambda c, t, k: step(c, t, k, inertia, p.flat_args),
            jax.vmap(scheme.state),
            dt,
            factor,
            p.coarse_steps,
        )
        q = jnp.concatenate([flat.q[None], saved.q]).reshape(-1, *state.q.shape)
        omega = jnp.concatenate([flat.omega[None], saved.omega]).reshape(-1, *state.omega.shape)
        return RotState(q, omega)

    example = (p.batch, jnp.asarray(p.dt_coarse, DTYPES[p.dtype]), jnp.asarray(1, jnp.int32))
    try:
        return compile_timed(run, *example, compiler_options=compiler_options())
    except ValueError as err:
        if "depends on the angular velocity" not in str(err):
            raise
        return None


def _fixed_row(problem: _Problem, name, runner, level, repeats):
    """Scheme ``name`` at ``dt_coarse / 2**level``, run by its `_fixed_runner` ``(compiled, compile s)``."""
    scheme, sc = SCHEMES[name], problem.run_scene
    compiled, compile_s = runner
    factor = 2**level
    dt, n_steps = problem.dt_coarse / factor, problem.coarse_steps * factor
    dtype = DTYPES[problem.dtype]
    args = (problem.batch, jnp.asarray(dt, dtype), jnp.asarray(factor, jnp.int32))
    traj, seconds = time_runs(compiled, args, repeats)
    evals = 0 if sc.torque is None else scheme.torque_evals_per_step * n_steps + scheme.torque_evals_at_init
    method = {"method": name, "kind": "fixed", "order": scheme.order, "dt": dt, "tol": None}
    return _row(problem, method, traj, n_steps, evals, seconds, compile_s)


def _adaptive_runner(problem: _Problem, name):
    """``(compiled, compile s)``: diffrax solver ``name``'s one program for every tolerance.

    ``run(state, tol)`` with rtol = atol = ``tol`` a runtime value: the tolerance ladder compiles
    one program per solver instead of one per rung (15 → 3 programs in `compare`'s default).
    """
    solver = ADAPTIVE_SOLVERS[name][0]
    p = problem

    def run(state, tol):
        q, omega = state.q.reshape(-1, 4), state.omega.reshape(-1, 3)
        traj, result, steps = adaptive_solve(
            solver(), q, omega, p.inertia, p.per_particle, p.ts.astype(q.dtype),
            p.run_scene.torque, p.flat_args, tol, tol, 1_000_000, p.args_axes,
        )  # fmt: skip
        shape = (len(p.ts), *state.q.shape[:-1])
        return (
            traj._replace(q=traj.q.reshape(*shape, 4), omega=traj.omega.reshape(*shape, 3)),
            result,
            steps,
        )

    tol = jnp.asarray(1e-3, p.batch.q.dtype)
    return compile_timed(run, p.batch, tol, compiler_options=compiler_options())


def _adaptive_row(problem: _Problem, name, runner, tol, repeats):
    """diffrax solver ``name`` with adaptive steps at rtol = atol = ``tol``, run by its `_adaptive_runner`."""
    _, order, calls_per_step = ADAPTIVE_SOLVERS[name]
    compiled, compile_s = runner
    args = (problem.batch, jnp.asarray(tol, problem.batch.q.dtype))
    (traj, result, steps), seconds = time_runs(compiled, args, repeats)
    if np.any(np.asarray(result != diffrax.RESULTS.successful)):
        raise RuntimeError(f"compare: {name} failed at tol={tol:g}; use looser tolerances.")
    mean_steps = float(np.mean(np.asarray(steps)))  # bodies of a cloud take different steps
    evals = int(round(calls_per_step * mean_steps)) + 1
    method = {"method": name, "kind": "adaptive", "order": order, "dt": None, "tol": tol}
    return _row(problem, method, traj, int(round(mean_steps)), evals, seconds, compile_s)
