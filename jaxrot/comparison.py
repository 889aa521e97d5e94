"""The speed/accuracy comparison behind ``python -m jaxrot compare``.

Example:
    >>> import jax; jax.config.update("jax_enable_x64", True)
    >>> from jaxrot import comparison
    >>> rows = comparison.compare(t_end=0.5, particles=2, coarse_steps=10, levels=2, schemes=["zhao"],
    ...                           solvers=["diffrax_tsit5"], tolerances=(1e-6,), repeats=1, progress=False)
    >>> [(r["method"], r["n_steps"]) for r in rows]
    [('zhao', 10), ('zhao', 20), ('diffrax_tsit5', 9)]
    >>> print(comparison.format_recommendation(rows))  # doctest: +ELLIPSIS
    fastest within error budget [rad] ...

Every scheme in `SCHEMES` runs on one scene at a ladder of time steps, and the
generic alternative (diffrax Tsit5 and Dopri8 with adaptive steps) at a ladder
of tolerances. Each run is timed over ``particles`` vmapped copies of the
scene's body and its first particle is compared with a tight diffrax reference.
A new scheme gets its rows with no change here.
"""

import csv
import datetime
import importlib.metadata
import json
import math
import os
import platform
import statistics
import subprocess
import time
from pathlib import Path
from typing import Any, NamedTuple

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
from tqdm import tqdm

from . import quaternion as quat
from ._compile import compiler_options
from ._diffrax._reference import adaptive_solve, reference_rollout
from ._inertia import body_inertia
from ._particles import PARTICLES, flatten_particles, split_per_body
from ._state import RotState
from ._validation import check_bodies
from .scenes import SCENES
from .schemes import SCHEMES


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
ASYMPTOTIC_ERROR = 0.1  # rad; above this the error saturates and says nothing about the order
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


def fit_order(dts, errors) -> float:
    """Slope of log(error) against log(dt): the measured order of accuracy."""
    slope, _ = np.polyfit(np.log(np.asarray(dts)), np.log(np.asarray(errors)), 1)
    return float(slope)


MIN_TIMED_S = 0.2  # a cheap run is repeated until this much time is sampled (at most 100 runs)


def time_compiled(fn, arg, repeats, compiler_options=None):
    """Compile ``fn`` for ``arg``, then time it: (output, compile s, median run s).

    ``compiler_options`` go to ``jax.jit`` (`jaxrot.compiler_options` for jaxrot's programs).
    Compilation is timed alone (``lower().compile()``); the runs are timed by `time_runs`.
    """
    start = time.perf_counter()
    compiled = jax.jit(fn, compiler_options=compiler_options).lower(arg).compile()
    compile_s = time.perf_counter() - start
    out, seconds = time_runs(compiled, (arg,), repeats)
    return out, compile_s, seconds


def time_runs(compiled, args, repeats):
    """``(output, median run s)`` of a compiled program on ``args``.

    One untimed run first. Then at least ``repeats`` runs, and more until `MIN_TIMED_S`
    is sampled: a run of a millisecond is at the mercy of the scheduler, and its median
    over a few samples moved 2× between neighbouring rungs.
    """
    out = jax.block_until_ready(compiled(*args))
    samples = []
    while len(samples) < repeats or (sum(samples) < MIN_TIMED_S and len(samples) < 100):
        start = time.perf_counter()
        jax.block_until_ready(compiled(*args))
        samples.append(time.perf_counter() - start)
    return out, statistics.median(samples)


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
    program for its whole ladder, ``dt`` and the step count runtime values, and each of its rows
    carries that program's time). Every program compiles with `jaxrot.compiler_options`.
    """
    tolerances, schemes, solvers = _check_compare_arguments(
        scene, dtype, particles, coarse_steps, levels, repeats, tolerances, schemes, solvers
    )
    problem = _set_up(scene, dtype, t_end, particles, coarse_steps)
    jobs = [("fixed", name, k) for name in schemes for k in range(levels + MAX_SATURATED_RUNGS)]
    jobs += [("adaptive", name, tol) for name in solvers for tol in tolerances]
    rows = []
    finished = set()  # schemes whose ladder reached its floor or that refuse the scene's torque
    runners = {}
    for kind, name, level in tqdm(jobs, desc="compare", disable=not progress, leave=False):
        if name in finished:
            continue
        if kind == "adaptive":
            rows.append(_adaptive_row(problem, name, level, repeats))
            continue
        if name not in runners:
            runners[name] = _fixed_runner(problem, SCHEMES[name])
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
            lambda c, t, i, a: scheme.step(c, t, dt, i, sc.torque, a),
            in_axes=(0, None, inertia_axis, p.args_axes),
            axis_name=PARTICLES,
        )

        def save(carry, k):
            def one_step(j, c):
                # t from the step index, as in `jaxrot.rollout`.
                return step(c, (k * factor + j).astype(dt.dtype) * dt, inertia, p.flat_args)

            carry = jax.lax.fori_loop(0, factor, one_step, carry)
            return carry, jax.vmap(scheme.state)(carry)

        carry = init(flat, inertia, p.flat_args)
        _, saved = jax.lax.scan(save, carry, jnp.arange(p.coarse_steps, dtype=jnp.int32))
        q = jnp.concatenate([flat.q[None], saved.q]).reshape(-1, *state.q.shape)
        omega = jnp.concatenate([flat.omega[None], saved.omega]).reshape(-1, *state.omega.shape)
        return RotState(q, omega)

    example = (p.batch, jnp.asarray(p.dt_coarse, DTYPES[p.dtype]), jnp.asarray(1, jnp.int32))
    start = time.perf_counter()
    try:
        compiled = jax.jit(run, compiler_options=compiler_options()).lower(*example).compile()
    except ValueError as err:
        if "depends on the angular velocity" not in str(err):
            raise
        return None
    return compiled, time.perf_counter() - start


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


def _adaptive_row(problem: _Problem, name, tol, repeats):
    """diffrax solver ``name`` with adaptive steps at rtol = atol = ``tol``."""
    solver, order, calls_per_step = ADAPTIVE_SOLVERS[name]
    p = problem

    def run(state):
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

    (traj, result, steps), compile_s, seconds = time_compiled(run, p.batch, repeats, compiler_options())
    if np.any(np.asarray(result != diffrax.RESULTS.successful)):
        raise RuntimeError(f"compare: {name} failed at tol={tol:g}; use looser tolerances.")
    mean_steps = float(np.mean(np.asarray(steps)))  # bodies of a cloud take different steps
    evals = int(round(calls_per_step * mean_steps)) + 1
    method = {"method": name, "kind": "adaptive", "order": order, "dt": None, "tol": tol}
    return _row(p, method, traj, int(round(mean_steps)), evals, seconds, compile_s)


def stalled(errors) -> bool:
    """Whether a ladder (errors in order of halving dt) has reached its floor: the last halving of dt
    gained less than a factor 2 below `ASYMPTOTIC_ERROR` (the reference's own error, or round-off)."""
    return len(errors) >= 2 and errors[-1] < ASYMPTOTIC_ERROR and errors[-1] > errors[-2] / 2


def measured_orders(rows) -> dict:
    """Per fixed-step scheme, the fitted order over its rungs between the floor and `ASYMPTOTIC_ERROR`.

    Above `ASYMPTOTIC_ERROR` the error saturates; where a ladder has `stalled`, rungs within a
    decade of its smallest error carry the floor's error, not the scheme's, and are left out too.
    None when fewer than three rungs qualify.
    """
    orders = {}
    fixed = [r for r in rows if r.get("kind", "fixed") == "fixed"]
    for name in dict.fromkeys(r["method"] for r in fixed):
        ladder = sorted(
            (r for r in fixed if r["method"] == name and math.isfinite(r["max_orientation_error_rad"])),
            key=lambda r: -r["dt"],
        )
        errors = [r["max_orientation_error_rad"] for r in ladder]
        floor = 10 * min(errors) if stalled(errors) else 0.0
        mine = [r for r, e in zip(ladder, errors, strict=True) if floor < e < ASYMPTOTIC_ERROR]
        errors = [r["max_orientation_error_rad"] for r in mine]
        orders[name] = fit_order([r["dt"] for r in mine], errors) if len(mine) >= 3 else None
    return orders


def setting_label(row) -> str:
    """``dt=…`` for a fixed-step row, ``tol=…`` for an adaptive one."""
    return f"dt={row['dt']:.3g}" if row["kind"] == "fixed" else f"tol={row['tol']:.0e}"


def recommend(rows, budgets=None):
    """For each error budget (rad), the row that meets it at the least wall time per particle.

    Default budgets: every decade from 1e-1 down to the smallest error on the
    table. Rows whose error is not finite (a step past a scheme's stability limit) meet no
    budget. Returns a list of ``(budget, row or None)``.
    """
    finite = [r for r in rows if math.isfinite(r["max_orientation_error_rad"])]
    if budgets is None:
        smallest = min((r["max_orientation_error_rad"] for r in finite), default=1.0)
        lowest = math.floor(math.log10(max(smallest, 1e-16)))
        budgets = [10.0**e for e in range(-1, lowest - 1, -1)] if lowest <= -1 else [1e-1]
    picks = []
    for budget in budgets:
        ok = [r for r in finite if r["max_orientation_error_rad"] <= budget]
        picks.append((budget, min(ok, key=lambda r: r["us_per_particle_run"]) if ok else None))
    return picks


def format_recommendation(rows) -> str:
    parts = []
    for budget, row in recommend(rows):
        if row is None:
            parts.append(f"≤{budget:.0e}: none")
        else:
            parts.append(
                f"≤{budget:.0e}: {row['method']} {setting_label(row)} ({row['us_per_particle_run']:.3g} µs)"
            )
    return "fastest within error budget [rad] (µs per particle over the horizon): " + "; ".join(parts)


def budget_table(rows, budgets=None) -> list:
    """Per error budget, each side's fastest row and how many times faster jaxrot's is.

    Returns ``[(budget, fastest jaxrot row or None, fastest diffrax row or None, ratio or None)]``
    with ``ratio`` = diffrax's wall time / jaxrot's (> 1: jaxrot is faster), at the budgets of
    `recommend` over all rows unless ``budgets`` are given.
    """
    budgets = [b for b, _ in recommend(rows, budgets)]
    ours = recommend([r for r in rows if not _is_diffrax(r)], budgets)
    theirs = recommend([r for r in rows if _is_diffrax(r)], budgets)
    table = []
    for (budget, mine), (_, best) in zip(ours, theirs, strict=True):
        ratio = best["us_per_particle_run"] / mine["us_per_particle_run"] if mine and best else None
        table.append((budget, mine, best, ratio))
    return table


def _is_diffrax(row) -> bool:
    """A diffrax solver's row (the ``diffrax_…`` methods: `ADAPTIVE_SOLVERS`, and Kvaerno5 in a fluid)."""
    return row["method"] in ADAPTIVE_SOLVERS or row["method"].startswith("diffrax_")


def format_budget_table(rows) -> str:
    """`budget_table` as text: one line per budget, the row to pick and its speed-up over diffrax."""

    def pick(row):
        return (
            "none"
            if row is None
            else f"{row['method']} {setting_label(row)} ({row['us_per_particle_run']:.3g} µs)"
        )

    head = (
        f"{'budget [rad]':>12}  {'fastest jaxrot row':<40} {'fastest diffrax row':<40} {'diffrax/jaxrot':>14}"
    )
    lines = [head, "-" * len(head)]
    for budget, mine, best, ratio in budget_table(rows):
        speed = "—" if ratio is None else f"{ratio:.1f}×"
        lines.append(f"{budget:>12.0e}  {pick(mine):<40} {pick(best):<40} {speed:>14}")
    return "\n".join(lines)


def _maybe(x):
    return "—" if x is None else f"{x:.2e}"


def format_table(rows) -> str:
    header = (
        f"{'method':<15} {'dt | tol':>12} {'steps':>7} {'max q err[rad]':>14} {'|Δω| final':>10} "
        f"{'rel ΔE':>9} {'torque ev':>9} {'µs/p-step':>9} {'µs/part.':>9} {'compile s':>9}"
    )
    lines = [header, "-" * len(header)]
    for r in rows:
        lines.append(
            f"{r['method']:<15} {setting_label(r):>12} {r['n_steps']:>7d} "
            f"{r['max_orientation_error_rad']:>14.3e} "
            f"{r['final_omega_error']:>10.2e} {_maybe(r['rel_energy_drift']):>9} {r['torque_evals']:>9d} "
            f"{r['us_per_particle_step']:>9.4f} {r['us_per_particle_run']:>9.3g} {r['compile_s']:>9.2f}"
        )
    for name, order in measured_orders(rows).items():
        fitted = (
            f"n/a: fewer than 3 rungs between {ASYMPTOTIC_ERROR} rad and the floor"
            if order is None
            else f"{order:.3f}"
        )
        nominal = next(r["order"] for r in rows if r["method"] == name)
        lines.append(f"measured order ({name}): {fitted} (nominal {nominal})")
    lines.append(format_recommendation(rows))
    if any(_is_diffrax(r) for r in rows) and not all(_is_diffrax(r) for r in rows):
        lines += ["", format_budget_table(rows)]
    return "\n".join(lines)


# Version of the provenance block that every results file carries under "machine"; a results file
# with an older one predates the fields the docs' tables read (tests/test_results.py).
RESULTS_SCHEMA = 2


def _git_commit():
    """The checkout's commit (``+dirty`` when the package or the benchmarks differ from it), or None
    outside a git checkout. Docs edited during a run do not mark it."""
    root = Path(__file__).resolve().parents[1]
    try:
        run = lambda *a: subprocess.run(["git", *a], cwd=root, capture_output=True, text=True, timeout=10)  # noqa: E731
        head = run("rev-parse", "--short=12", "HEAD")
        if head.returncode != 0:
            return None
        dirty = run(
            "status", "--porcelain", "--untracked-files=no", "--", "jaxrot", "benchmarks"
        ).stdout.strip()
        return head.stdout.strip() + ("+dirty" if dirty else "")
    except (OSError, subprocess.SubprocessError):
        return None


def machine_info() -> dict:
    """Where and from what a result was measured: machine, versions, commit, date (UTC), schema."""
    import diffrax as _diffrax

    return {
        "schema": RESULTS_SCHEMA,
        "date": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC"),
        "commit": _git_commit(),
        "machine": platform.machine(),
        "processor": platform.processor() or platform.machine(),
        "cpus": os.cpu_count(),
        "python": platform.python_version(),
        "jax": jax.__version__,
        "jaxlib": jax.lib.__version__ if hasattr(jax.lib, "__version__") else None,
        "diffrax": _diffrax.__version__,
        "jaxrot": importlib.metadata.version("jaxrot"),
        "backend": jax.default_backend(),
        "device": str(jax.devices()[0].device_kind),
        "xla_flags": os.environ.get("XLA_FLAGS", ""),
    }


def write_outputs(rows, out_dir, plot=True) -> list[Path]:
    """Write ``compare.csv``, ``compare.json`` and (optionally) ``compare.png`` to ``out_dir``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = [out / "compare.csv", out / "compare.json"]
    with open(written[0], "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    recommendation = [
        {"budget_rad": b, "method": r and r["method"], "setting": r and setting_label(r)}
        for b, r in recommend(rows)
    ]
    with open(written[1], "w") as f:
        json.dump(
            {
                "machine": machine_info(),
                "orders": measured_orders(rows),
                "recommendation": recommendation,
                "rows": rows,
            },
            f,
            indent=2,
        )
    if plot:
        written.append(plot_work_precision(rows, out / "compare.png"))
    return written


def plot_work_precision(rows, path=None, axes=None):
    """Work-precision plot: error against wall time per particle and against torque evaluations.

    Log-log, one line per method (fixed-step schemes solid with circles, adaptive diffrax
    dashed with squares), the legend outside the axes. Saves to ``path`` when given; draws on
    ``axes`` (two Axes) when given.
    """
    import matplotlib

    if axes is None:
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = None
    if axes is None:
        fig, axes = plt.subplots(1, 2, figsize=(12.5, 4.2), constrained_layout=True)
    ax_time, ax_evals = axes
    # Fixed-step schemes: solid, circles, the ten colours of tab10; adaptive solvers: dashed, in
    # greys with their own markers (with 13 methods one colour cycle would repeat).
    fixed_styles = iter(dict(marker="o", linestyle="-", color=c) for c in plt.get_cmap("tab10").colors * 2)
    adaptive_styles = iter(
        dict(marker=m, linestyle="--", color=c)
        for m, c in zip("sD^v" * 2, ("black", "dimgray", "darkgray", "silver") * 2, strict=True)
    )
    for name in dict.fromkeys(r["method"] for r in rows):
        mine = [r for r in rows if r["method"] == name]
        style = dict(next(fixed_styles if mine[0]["kind"] == "fixed" else adaptive_styles), label=name)
        err = [r["max_orientation_error_rad"] for r in mine]
        ax_time.loglog([r["us_per_particle_run"] for r in mine], err, **style)
        ax_evals.loglog([max(r["torque_evals"], 1) for r in mine], err, **style)
    first = rows[0]
    ax_time.set(
        xlabel="wall time per particle over the horizon [µs]",
        ylabel="max orientation error [rad]",
        title=f"{first['scene']}, {first['dtype']}, {first['particles']} particles",
    )
    ax_evals.set(xlabel="torque evaluations per particle", ylabel="max orientation error [rad]")
    for ax in axes:
        ax.grid(True, which="both", alpha=0.3)
    # Outside the axes: inside, it covered the high-order rows' lower-left corner.
    ax_evals.legend(fontsize="small", loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0)
    if path is not None:
        (fig or ax_time.figure).savefig(path, dpi=120)
    if fig is not None:
        plt.close(fig)
    return path
