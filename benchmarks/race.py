"""The speed/accuracy race: every jaxrot scheme against diffrax's Tsit5, Dopri5 and Dopri8.

For each scene, ``N`` bodies (default 1000) get random orientations and random
body-frame spins (each component normal with standard deviation 3 rad/s) and keep the
scene's inertia, torque and horizon. Every scheme in `jaxrot.SCHEMES`, and the variants
in ``VARIANTS`` (rkmk_dopri8 with the Cayley chart), runs on a ladder of step counts
growing by 10^(1/(2·order)), at most √2 (`step_ladder`: half a decade of error per rung, as
diffrax's half-decade tolerance ladder; from 8 steps over the horizon until the error is below
``--floor``, stops falling, or a run takes longer than ``--time-cap`` seconds); diffrax's Tsit5, Dopri5 and
Dopri8 run on the same `Euclidean` quaternion ODE as `jaxrot.reference_rollout`
(normalised at the end) with a PID controller at rtol = atol on a half-decade ladder
1e-2 … 1e-13 (until the error is below the floor or a run takes longer than ``--adaptive-cap``
seconds), and so do jaxrot's Lie-group pairs rkmk_dopri5 and rkmk_dopri8 as diffrax
solvers (`jaxrot.solver`, rows ``jaxrot_*_pid``, each body adapting its own steps). The
error of a row is the largest geodesic orientation error over all bodies at the final
time against Dopri8 at rtol = atol = 1e-14 in float64, solving the problem the row was
given (in float32: the rounded initial state and scene, cast up). Each row is one
compiled program (step count and tolerance are runtime values, so each method compiles
once, and runs once untimed on its first rung) timed as the median of ``--repeats`` runs of the
whole batch. Then the rows that can win a
budget (`finalists`: the three fastest methods of each side at each budget, each within
`FINALIST_WITHIN` of its side's fastest) are timed again
round-robin, seven rounds, and keep those medians (`retime_side_by_side`): both sides of a ratio
are measured in the same minute, not minutes apart.

The table gives, for each budget 1e-2 … 1e-10 rad (1e-2 … 1e-5 in float32), the
fastest jaxrot row and the fastest diffrax row meeting it and their ratio
(> 1: jaxrot is faster). A plot of error against wall time goes to ``--out``.

    python benchmarks/race.py                                  # the three race scenes, float64
    python benchmarks/race.py --scenes heavy_top --dtype float32 --n 1000

A race stopped before its side-by-side re-timing (a time limit on a lent GPU) still printed every
ladder row; ``--from-log LOG`` rebuilds the table of each scene in LOG from those first-pass
timings (each row timed minutes apart from the others) and writes it with ``"retimed": false``.
"""

import argparse
import json
import math
import statistics
import time
from pathlib import Path

import jax


jax.config.update("jax_enable_x64", True)

import diffrax
import jax.numpy as jnp
import numpy as np
from _race_tables import (  # noqa: E402 (benchmarks/)
    BUDGETS,
    DIFFRAX,
    _is_diffrax,
    _seconds,
    _table_json,
    format_race,
    race_table,
    table_from_log,
)

import jaxrot
import jaxrot._core._fusion
from jaxrot import quaternion as quat
from jaxrot._diffrax._reference import adaptive_solve
from jaxrot._inertia import body_inertia
from jaxrot._particles import PARTICLES
from jaxrot.comparison import machine_info, plot_work_precision


# jaxrot's Lie-group pairs with diffrax's PID controller (`jaxrot.solver`): each body adapts its own steps.
LIE_ADAPTIVE = ("rkmk_dopri5", "rkmk_dopri8")
# Fixed-step variants of registered schemes, raced as rows of their own.
VARIANTS = {"rkmk_dopri8_cayley": jaxrot.schemes.RKMKDopri8(chart="cayley")}
# A row's key for the compiled program and arguments that reproduce its run (not saved).
RERUN = "_rerun"
REFERENCE_TOL = 1e-14
# A finalist is at most this much slower, on the ladder, than its side's fastest row at the budget.
# In the published race (float64 and float32, three scenes each, 2026-11-26/27) each budget's winner
# after the re-timing had been at most 1.20x its side's fastest on the ladder; the docs give a third
# as a cell's noise between runs. Without this bound the three fastest of each side were 150 rows
# there, whose 7 rounds cost ~9 min of the float64 race; with it 82 rows, ~2.3 min.
FINALIST_WITHIN = 1.5


def random_bodies(scene, n, dtype, seed=0):
    """``n`` bodies with the scene's inertia: random orientations, random spins of a few rad/s."""
    key_q, key_w = jax.random.split(jax.random.PRNGKey(seed))
    q = quat.normalize(jax.random.normal(key_q, (n, 4), dtype=jnp.float64))
    omega_body = 3.0 * jax.random.normal(key_w, (n, 3), dtype=jnp.float64)
    return jaxrot.RotState(q.astype(dtype), quat.rotate(q, omega_body).astype(dtype))


def step_ladder(order, start=8, stop=10**6):
    """Step counts from ``start`` growing by ``min(√2, 10^(1/(2·order)))``, each a distinct integer.

    diffrax's rows step through tolerances half a decade apart, and their errors follow the
    tolerance; a fixed-step scheme of order p moves its error by half a decade when its step count
    grows by 10^(1/(2p)) (1.15 at order 8). Both sides of the race then sample their work-precision
    curves equally finely, so a budget picks neither side's row from a coarser grid (on a √2 ladder
    an order-8 scheme's errors are 1.2 decades apart). Orders below 3 keep √2.
    """
    growth = min(math.sqrt(2.0), 10.0 ** (1.0 / (2.0 * order)))
    steps, k = start, 0
    while steps <= stop:
        yield steps
        k += 1
        steps = max(steps + 1, int(round(start * growth**k)))


def seconds_of_one_run(compiled, *args):
    start = time.perf_counter()
    jax.block_until_ready(compiled(*args))
    return time.perf_counter() - start


def timed(compiled, *args, repeats):
    out = jax.block_until_ready(compiled(*args))
    return out, statistics.median(seconds_of_one_run(compiled, *args) for _ in range(repeats))


def timed_warm(compiled, *args, repeats):
    """`timed` for a program already run once (`race` warms each program on its first rung): every
    run is timed, the last one's output kept. A rung's first-pass time only picks the `finalists`
    and draws the figure; the ratios come from `retime_side_by_side`, so an untimed run per rung
    would cost a quarter of the ladder at ``repeats=3`` (all of it at 1) and buy nothing read."""
    samples = []
    for _ in range(repeats):
        start = time.perf_counter()
        out = jax.block_until_ready(compiled(*args))
        samples.append(time.perf_counter() - start)
    return out, statistics.median(samples)


def fixed_step_runner(scheme, scene):
    """One compiled program for any step count: ``init``, then ``n`` steps, vmapped over bodies."""
    inertia = body_inertia(scene.inertia)

    def run(state, dt, n):
        def one(q, omega):
            carry = scheme.init(
                jaxrot.RotState(q, omega), jnp.zeros((), q.dtype), inertia, scene.torque, scene.args
            )

            def body(i, c):
                return scheme.step(c, i.astype(q.dtype) * dt, dt, inertia, scene.torque, scene.args)

            return scheme.state(jax.lax.fori_loop(0, n, body, carry))

        return jax.vmap(one, axis_name=PARTICLES)(state.q, state.omega)

    return jax.jit(run)


def adaptive_runner(solver, scene, t_end):
    def run(state, tol):
        ts = jnp.array([0.0, t_end], state.q.dtype)
        traj, result, steps = adaptive_solve(
            solver(), state.q, state.omega, scene.inertia, False, ts, scene.torque, scene.args, tol, tol,
            1_000_000, None,
        )  # fmt: skip
        return jaxrot.RotState(traj.q[-1], traj.omega[-1]), result, steps

    return jax.jit(run)


def lie_adaptive_runner(name, scene, t_end):
    """`jaxrot.solver(name)` in `diffrax.diffeqsolve` on a `jaxrot.RigidBodyTerm`, vmapped over bodies."""
    term = jaxrot.RigidBodyTerm(scene.inertia, scene.torque)
    solver = jaxrot.solver(name)

    def run(state, tol):
        def one(q, omega):
            sol = diffrax.diffeqsolve(
                term, solver, 0.0, t_end, None, jaxrot.RotState(q, omega), args=scene.args,
                stepsize_controller=diffrax.PIDController(rtol=tol, atol=tol), max_steps=1_000_000,
                throw=False,
            )  # fmt: skip
            return jaxrot.RotState(sol.ys.q[-1], sol.ys.omega[-1]), sol.result, sol.stats["num_steps"]

        return jax.vmap(one, axis_name=PARTICLES)(state.q, state.omega)

    return jax.jit(run)


def lie_adaptive_torque_evals(name, mean_steps):
    """Torque calls of a `jaxrot.solver` pair: every stage but the first (reused), and one at the start."""
    return (jaxrot.SCHEMES[name].tableau.num_stages - 1) * mean_steps + 1


def _cast(tree, dtype):
    """``tree`` with its floating-point array leaves in ``dtype`` (other leaves unchanged)."""

    def cast(x):
        return x.astype(dtype) if isinstance(x, jax.Array) and jnp.issubdtype(x.dtype, jnp.floating) else x

    return jax.tree_util.tree_map(cast, tree)


def error_of(q, q_ref):
    return float(jnp.max(quat.angle_between(jnp.asarray(q, jnp.float64), q_ref)))


def race(
    scene_name, *, n=1000, dtype="float64", repeats=3, floor=None, time_cap=2.0, adaptive_cap=None,
    schemes=None, log=print,
):  # fmt: skip
    dtype_ = {"float64": jnp.float64, "float32": jnp.float32}[dtype]
    scene = jaxrot.SCENES[scene_name](dtype_)
    t_end = scene.t_end
    floor = floor if floor is not None else BUDGETS[dtype][-1] / 3
    adaptive_cap = 4 * time_cap if adaptive_cap is None else adaptive_cap
    state = random_bodies(scene, n, dtype_)
    # The reference solves the problem the methods were given: the float32 initial state and scene
    # parameters, exactly (their rounding alone moves the final orientations by up to 4e-4 rad).
    state64, scene64 = _cast(state, jnp.float64), _cast(scene, jnp.float64)
    ref = jaxrot.reference_rollout(
        state64, scene64.inertia, jnp.array([0.0, t_end]), torque=scene64.torque, args=scene64.args,
        rtol=REFERENCE_TOL, atol=REFERENCE_TOL,
    )  # fmt: skip
    q_ref = ref.q[-1]
    rows = []
    common = {"scene": scene_name, "dtype": dtype, "particles": n}
    candidates = {**jaxrot.SCHEMES, **VARIANTS}
    for name in schemes or list(candidates):
        scheme = candidates[name]
        try:
            runner = fixed_step_runner(scheme, scene)
            start = time.perf_counter()
            compiled = runner.lower(state, jnp.asarray(1.0, dtype_), 1).compile()
        except ValueError as err:  # a splitting refusing a velocity-dependent torque
            log(f"  {name}: skipped ({str(err).split('.')[0]})")
            continue
        compile_s = time.perf_counter() - start
        jax.block_until_ready(compiled(state, jnp.asarray(t_end / 8, dtype_), 8))  # warm: the first rung
        errors = []
        for steps in step_ladder(scheme.order):
            dt = t_end / steps
            out, seconds = timed_warm(compiled, state, jnp.asarray(dt, dtype_), steps, repeats=repeats)
            err = error_of(out.q, q_ref)
            evals = (
                0
                if scene.torque is None
                else scheme.torque_evals_per_step * steps + scheme.torque_evals_at_init
            )
            rows.append(
                {**common, "method": name, "kind": "fixed", "dt": dt, "tol": None, "n_steps": steps,
                 "max_orientation_error_rad": err, "torque_evals": evals, "seconds": seconds,
                 "us_per_particle_run": seconds / n * 1e6, "compile_s": compile_s,
                 RERUN: (compiled, (state, jnp.asarray(dt, dtype_), steps))}
            )  # fmt: skip
            log(f"  {name:12s} steps {steps:7d}  err {err:9.2e}  {seconds * 1e3:9.2f} ms")
            errors.append(err)
            stalled = len(errors) >= 3 and errors[-1] > 0.7 * errors[-3] and errors[-1] < 1e-3
            if err < floor or seconds > time_cap or stalled or not math.isfinite(err) and steps > 8000:
                break
    adaptive = [(name, adaptive_runner(solver, scene, t_end), solver) for name, solver in DIFFRAX.items()]
    adaptive += [
        (f"jaxrot_{name}_pid", lie_adaptive_runner(name, scene, t_end), name) for name in LIE_ADAPTIVE
    ]
    for name, runner, solver in adaptive:
        start = time.perf_counter()
        compiled = runner.lower(state, jnp.asarray(1e-6, dtype_)).compile()
        compile_s = time.perf_counter() - start
        jax.block_until_ready(compiled(state, jnp.asarray(1e-2, dtype_)))  # warm: the first rung
        lowest = 13 if dtype == "float64" else 7
        for tol in [10 ** (-k / 2) for k in range(4, 2 * lowest + 1)]:
            (out, result, steps), seconds = timed_warm(
                compiled, state, jnp.asarray(tol, dtype_), repeats=repeats
            )
            if np.any(np.asarray(result != diffrax.RESULTS.successful)):
                log(f"  {name}: failed at tol {tol:.1e}")
                continue
            err = error_of(out.q, q_ref)
            mean_steps = float(np.mean(np.asarray(steps)))
            if isinstance(solver, str):
                evals = lie_adaptive_torque_evals(solver, mean_steps)
            else:
                evals = (solver.tableau.num_stages - (1 if solver.tableau.fsal else 0)) * mean_steps + 1
            evals = 0 if scene.torque is None else int(round(evals))
            rows.append(
                {**common, "method": name, "kind": "adaptive", "dt": None, "tol": tol,
                 "n_steps": int(round(mean_steps)), "max_orientation_error_rad": err, "torque_evals": evals,
                 "seconds": seconds, "us_per_particle_run": seconds / n * 1e6, "compile_s": compile_s,
                 RERUN: (compiled, (state, jnp.asarray(tol, dtype_)))}
            )  # fmt: skip
            log(f"  {name:15s} tol {tol:8.1e} steps {mean_steps:8.1f} err {err:9.2e} {seconds * 1e3:9.2f} ms")
            if err < floor or seconds > adaptive_cap:
                break
    return rows


def finalists(rows, budgets, per_side=3, within=FINALIST_WITHIN):
    """The rows that can win a budget: each method's fastest row meeting it, for the ``per_side``
    fastest methods of each side (jaxrot, diffrax) that are at most ``within`` times the side's
    fastest, over all budgets."""
    chosen = {}
    for budget in budgets:
        fastest = {}
        for r in (r for r in rows if r["max_orientation_error_rad"] <= budget):
            current = fastest.get(r["method"])
            if current is None or r["seconds"] < current["seconds"]:
                fastest[r["method"]] = r
        for side in (True, False):
            ranked = sorted((r for r in fastest.values() if _is_diffrax(r) == side), key=_seconds)
            chosen.update(
                (id(r), r) for r in ranked[:per_side] if _seconds(r) <= within * _seconds(ranked[0])
            )
    return list(chosen.values())


def retime_side_by_side(rows, budgets, rounds=7, log=print):
    """Time the `finalists` again, round-robin, in place: each round runs every finalist once, in turn.

    A ladder times each method minutes after the others; load on the machine drifts over that span
    (the same compiled rkmk_dopri8 step measured 1.5x apart in two runs of the race). Interleaved,
    both sides of a ratio see the same drift. Each finalist's ``seconds`` becomes the median of its
    ``rounds`` runs; the ladder's figure stays as ``ladder_seconds``."""
    final = finalists(rows, budgets)
    samples = {id(r): [] for r in final}
    for _ in range(rounds):
        for r in final:
            compiled, args = r[RERUN]
            samples[id(r)].append(seconds_of_one_run(compiled, *args))
    for r in final:
        r["ladder_seconds"] = r["seconds"]
        r["seconds"] = statistics.median(samples[id(r)])
        r["us_per_particle_run"] = r["seconds"] / r["particles"] * 1e6
    log(f"  re-timed {len(final)} finalists side by side, {rounds} rounds")


def main():
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--scenes", default="heavy_top,viscous_drag,dipole_rotating_field")
    parser.add_argument("--dtype", default="float64", choices=["float64", "float32"])
    parser.add_argument("--n", type=int, default=1000)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument(
        "--time-cap", type=float, default=2.0, help="stop a fixed-step ladder past this many s per run"
    )
    parser.add_argument(
        "--adaptive-cap", type=float, default=None, help="the same for a tolerance ladder (4x --time-cap)"
    )
    parser.add_argument("--schemes", default=None, help="comma-separated names (default: all)")
    parser.add_argument("--out", default="docs/race_cpu", help="folder of race_DTYPE.json and the plots")
    parser.add_argument(
        "--barriers", choices=["auto", "on", "off"], default="auto", help="`stage` barriers (auto: CPU only)"
    )
    parser.add_argument("--from-log", default=None, help="rebuild the tables from this race log and stop")
    opts = parser.parse_args()
    if opts.from_log:
        Path(opts.out).mkdir(parents=True, exist_ok=True)
        table_from_log(opts.from_log, opts.dtype, opts.out)
        return
    jaxrot._core._fusion.BARRIERS = {"auto": None, "on": True, "off": False}[opts.barriers]
    out = Path(opts.out)
    out.mkdir(parents=True, exist_ok=True)
    info = machine_info() | {"stage_barriers": jaxrot._core._fusion._barriers()}
    print(f"machine: {info}")
    report = {"machine": info, "options": vars(opts), "scenes": {}}
    schemes = opts.schemes.split(",") if opts.schemes else None
    for scene_name in opts.scenes.split(","):
        print(f"== {scene_name} ({opts.dtype}, N = {opts.n})", flush=True)
        rows = race(scene_name, n=opts.n, dtype=opts.dtype, repeats=opts.repeats, time_cap=opts.time_cap,
                    adaptive_cap=opts.adaptive_cap, schemes=schemes,
                    log=lambda s: print(s, flush=True))  # fmt: skip
        retime_side_by_side(rows, BUDGETS[opts.dtype], log=lambda s: print(s, flush=True))
        table = race_table(rows, BUDGETS[opts.dtype])
        print(format_race(scene_name, opts.dtype, table), flush=True)
        stem = f"race_{scene_name}_{opts.dtype}"
        plot_work_precision(rows, out / f"{stem}.png")
        report["scenes"][scene_name] = {
            "rows": [{k: v for k, v in r.items() if k != RERUN} for r in rows],
            "table": _table_json(table),
        }
        with open(out / f"race_{opts.dtype}.json", "w") as f:
            json.dump(report, f, indent=2)


if __name__ == "__main__":
    main()
