"""The race in a fluid: a spheroid in shear at Stokes numbers 1e-1, 1e-3, 1e-5, jaxrot against diffrax.

1000 prolate spheroids (aspect ratio 4, Perrin's frictions, uniform density; `jaxrot.scenes.
spheroid_shear`) in the simple shear u = (y, 0, 0) of rate 1, with random orientations (seed 0),
each released turning at its overdamped angular velocity, over one Jeffery period (26.7), float64.
The Stokes number St = I_⊥ γ̇ / ζ_⊥ sets the friction's stiffness: ζΔt/I ≈ 10 Δt at 1e-1, 1e5 Δt at
1e-5. Rows:

- jaxrot, inertial: ``exp_rk4`` and ``exp_midpoint`` with ``fluid=`` (step ladders as in
  ``benchmarks/race.py``), and ``exp_rk4`` with ``graded_start=False`` ("plain start"); at St = 1e-1
  also ``rkmk_dopri8`` with the fluid's torque as a plain callable, which is stable while ζΔt/I < ~2.5
  (its ladder starts inside that);
- jaxrot, overdamped: `jaxrot.overdamped_rollout`'s ``rkmk4`` and ``lie_midpoint``:
  no inertia, so their error against the inertial reference stops at the model's own, of order St;
  the table says below which budget that disqualifies them;
- diffrax, as a user would write it: the Euclidean quaternion ODE of `jaxrot.reference_rollout`
  (``q̇ = ½ q ⊗ (0, ω_b)``, Euler's equations) with the fluid's torque as a plain callable, a PID
  controller at rtol = atol = tol on a half-decade ladder, vmapped: ``Tsit5`` (explicit),
  ``Kvaerno5`` (implicit, for stiff problems) and ``KenCarp4`` (IMEX: the friction implicit, the rest
  explicit, a ``MultiTerm``). ``Tsit5``, whose step the friction's stability limit holds, is probed on 8
  bodies at tol 1e-3 first: past ``--max-steps`` steps per body it is reported and not raced (the
  implicit ones are not held to it: a probe of theirs would be a second compilation, about a minute,
  that never skipped one); a tolerance at which some body exceeds the step budget is "not reached": it
  is recorded and ends that solver's ladder (a tighter one costs more).

The error of a row is the largest geodesic orientation error over the bodies at the final time
against ExpRK4 at 2^14 steps (checked at St = 1e-1 and 1e-3 against `jaxrot.reference_rollout`,
Dopri8 at 1e-13, on 16 bodies: the gap is in the results file). Each row is one compiled program;
each rung of a ladder is timed by ``--repeats`` runs (median). A ladder ends once a rung is slower than
``--band`` (2) times the fastest row of its side that meets the smallest budget (1e-8): that row meets
every budget, so the rung and the slower ones after it can be the fastest at none. The rows within
``--band`` of a budget's fastest on their side are re-timed round-robin, ``--rounds`` rounds, both
sides under the same load; the file records each one's ladder time and its rounds' spread.

    python benchmarks/fluid_race.py --time-cap 2        # docs/fluid_race_cpu.json and .png (~10 min, 2 cores)
    python benchmarks/fluid_race.py --quick             # a small check that it runs; writes nothing to docs/
"""

import argparse
import json
import math
import statistics
import sys
import time
from pathlib import Path

import jax


jax.config.update("jax_enable_x64", True)

import diffrax
import jax.numpy as jnp
import numpy as np
from _fluid_race_runners import bodies, diffrax_runner, explicit_runner  # noqa: E402 (benchmarks/)
from _fluid_race_tables import (  # noqa: E402 (benchmarks/)
    BUDGETS,
    DIFFRAX,
    budget_table,
    is_diffrax,
    overdamped_floor,
    plot,
)
from race import seconds_of_one_run as seconds_of, step_ladder  # noqa: E402 (benchmarks/)

import jaxrot
from jaxrot import quaternion as quat
from jaxrot.comparison import machine_info
from jaxrot.comparison._fluid import FLUID_ROWS, inertial_runner, overdamped_runner, plain_fluid_torque
from jaxrot.scenes import spheroid_shear
from jaxrot.schemes import OVERDAMPED_SCHEMES, ExpRK4


ROOT = Path(__file__).resolve().parents[1]
STOKES = (1e-1, 1e-3, 1e-5)
REFERENCE_STEPS = 2**14
RERUN = "_rerun"


def timed_runs(compiled, args, repeats):
    """The output and the median seconds of ``repeats`` runs of an ahead-of-time compiled program
    (the first included: compiled ahead, it has no compilation to leave out)."""
    start = time.perf_counter()
    out = jax.block_until_ready(compiled(*args))
    seconds = [time.perf_counter() - start] + [seconds_of(compiled, *args) for _ in range(repeats - 1)]
    return out, statistics.median(seconds)


def error_of(q, q_ref):
    return float(jnp.max(quat.angle_between(q, q_ref)))


def race_one(stokes, n, repeats, time_cap, floor, max_steps, quick, band, log):
    scene = spheroid_shear(stokes=stokes)
    state = bodies(scene, n)
    t_end = scene.t_end
    log(
        f"== St = {stokes:g}: ζ/I = {float(jnp.min(scene.fluid.friction / scene.inertia)):.3g} … "
        f"{float(jnp.max(scene.fluid.friction / scene.inertia)):.3g}, N = {n}, t = {t_end:.4g}"
    )
    compile_seconds, programs = {}, {}

    def program(label, run):
        """``run`` compiled once for this Stokes number's bodies: dt and n are runtime values."""
        if label not in programs:
            start = time.perf_counter()
            programs[label] = jax.jit(run, static_argnums=3).lower(state, jnp.asarray(1.0), 1, 1).compile()
            compile_seconds[label] = time.perf_counter() - start
        return programs[label]

    # The reference is the exp_rk4 row's own program, at 2^14 steps.
    ref_run = program("exp_rk4", inertial_runner(FLUID_ROWS["exp_rk4"], scene, n))
    ref_steps = REFERENCE_STEPS // (16 if quick else 1)
    q_ref = ref_run(state, jnp.asarray(t_end / ref_steps), ref_steps).q[-1]
    check = None
    if stokes >= 1e-3:  # the fine ExpRK4 against Dopri8 where Dopri8 can still afford the friction
        few = jax.tree_util.tree_map(lambda x: x[:16], state)
        dopri = jaxrot.reference_rollout(
            few,
            scene.inertia,
            jnp.array([0.0, t_end]),
            torque=plain_fluid_torque(scene),
            rtol=1e-13,
            atol=1e-13,
            max_steps=10**7,
        ).q[-1]
        check = error_of(dopri, q_ref[:16])
        log(f"  reference: ExpRK4, {ref_steps} steps; Dopri8 (1e-13) differs by {check:.2e} rad on 16 bodies")
    rows = []
    common = {"stokes": stokes, "particles": n}

    def outclassed(row):
        """Whether ``row`` is slower than ``band`` times a row of its own side that met the smallest
        budget: that row meets every budget, so this ladder's later rungs (slower still) can be the
        fastest at none (``band``: the spread of one ladder timing, see `retime`)."""
        best = min(
            (
                r["seconds"]
                for r in rows
                if is_diffrax(r) == is_diffrax(row) and r["max_orientation_error_rad"] <= BUDGETS[-1]
            ),
            default=math.inf,
        )
        return row["seconds"] > band * best

    def fixed(name, label, run, order, first, evals_per_step):
        compiled = program(label, run)
        errors = []
        for steps in step_ladder(order, first):
            dt = t_end / steps
            out, seconds = timed_runs(compiled, (state, jnp.asarray(dt), steps), repeats)
            err = error_of(out.q[-1], q_ref)
            rows.append(
                {
                    **common,
                    "method": label,
                    "kind": "fixed",
                    "model": "overdamped" if "overdamped" in label else "inertial",
                    "n_steps": steps,
                    "dt": dt,
                    "tol": None,
                    "max_orientation_error_rad": err,
                    "torque_evals": evals_per_step * steps,
                    "seconds": seconds,
                    RERUN: (compiled, (state, jnp.asarray(dt), steps)),
                }
            )
            log(f"  {label:24s} steps {steps:7d}  err {err:9.2e}  {seconds * 1e3:9.2f} ms")
            errors.append(err)
            # Stalled: at the model's floor (the overdamped rows) or round-off, not while saturated.
            # (an overdamped row at any level: at St = 1e-1 its floor is above 0.1 rad)
            stalled = (
                len(errors) >= 3
                and 0.7 * errors[-3] < errors[-1]
                and (errors[-1] < 0.1 or "overdamped" in label)
            )
            if err < floor or seconds > time_cap or stalled or (quick and (len(errors) >= 12 or err < 1e-4)):
                break
            if outclassed(rows[-1]):
                log(f"  {label}: stopped, slower than {band:g}x a jaxrot row that meets every budget")
                break

    # The rows likeliest to meet the smallest budget cheaply run first, so that `outclassed` ends the
    # others' ladders early: the order-5 scheme, the plain start (these bodies start at their slow
    # velocity, where the graded start, tens of substeps once per run, buys little: a row a user can
    # choose), the order-8 scheme inside its stability limit; then the rest.
    plain = ExpRK4(graded_start=False)
    ladders = [
        ("exp_rk5", inertial_runner(FLUID_ROWS["exp_rk5"], scene, n), FLUID_ROWS["exp_rk5"]),
        ("exp_rk4 (plain start)", inertial_runner(plain, scene, n), plain),
    ]
    if stokes >= 1e-1:
        # inside its stability limit, ζΔt/I < 2.5
        first = int(math.ceil(t_end * float(jnp.max(scene.fluid.friction / scene.inertia)) / 2.5))
        dopri8 = jaxrot.SCHEMES["rkmk_dopri8"]
        ladders.append(("rkmk_dopri8 (plain torque)", explicit_runner("rkmk_dopri8", scene), dopri8, first))
    ladders += [
        (name, inertial_runner(s, scene, n), s) for name, s in FLUID_ROWS.items() if name != "exp_rk5"
    ]
    for name in ("rkmk4", "lie_midpoint"):
        scheme = OVERDAMPED_SCHEMES[name].overdamped()  # the stepper of the overdamped model
        ladders.append((f"overdamped_{name}", overdamped_runner(scheme, scene, n), scheme))
    for label, run, scheme, *first in ladders:
        evals = getattr(scheme, "torque_evals_per_step", None) or scheme.velocity_evals_per_step
        fixed(label, label, run, scheme.order, first[0] if first else 8, evals)
    skipped, rows_failed = {}, []
    for name, solver in DIFFRAX.items():
        if name == "diffrax_tsit5":  # the probe before the full program: unraced, it is not compiled
            start = time.perf_counter()
            probe = jax.tree_util.tree_map(lambda x: x[:8], state)
            _, result, steps = diffrax_runner(solver, scene, max_steps)(probe, jnp.asarray(1e-3))
            compile_seconds[f"{name} (probe, 8 bodies)"] = time.perf_counter() - start
            if np.any(np.asarray(result != diffrax.RESULTS.successful)):
                skipped[name] = f"more than {max_steps} steps per body at tol 1e-3 (8 bodies probed)"
                log(f"  {name}: not raced: {skipped[name]}")
                continue
        start = time.perf_counter()
        compiled = diffrax_runner(solver, scene, max_steps).lower(state, jnp.asarray(1e-6)).compile()
        compile_seconds[name] = time.perf_counter() - start
        for tol in [10 ** (-k / 2) for k in range(4, 27)]:
            # One run first: a tolerance that is not reached, or that already takes long, is not repeated.
            start = time.perf_counter()
            q, result, steps = jax.block_until_ready(compiled(state, jnp.asarray(tol)))
            seconds = time.perf_counter() - start
            reached = not np.any(np.asarray(result != diffrax.RESULTS.successful))
            if reached and seconds <= 4 * time_cap and repeats > 1:
                more = [seconds_of(compiled, state, jnp.asarray(tol)) for _ in range(repeats - 1)]
                seconds = statistics.median([seconds, *more])
            if np.any(np.asarray(result != diffrax.RESULTS.successful)):
                # Not reached within the step budget: a tighter tolerance would only cost more, so the
                # ladder ends here (the file records the tolerance and how many bodies failed).
                failed = int(np.sum(np.asarray(result != diffrax.RESULTS.successful)))
                log(f"  {name}: not reached at tol {tol:.1e} ({failed} of {n} bodies past max_steps)")
                rows_failed.append({"method": name, "tol": tol, "bodies_failed": failed, "not_reached": True})
                break
            err = error_of(q, q_ref)
            mean_steps = float(np.mean(np.asarray(steps)))
            rows.append(
                {
                    **common,
                    "method": name,
                    "kind": "adaptive",
                    "model": "inertial",
                    "n_steps": int(round(mean_steps)),
                    "dt": None,
                    "tol": tol,
                    "max_orientation_error_rad": err,
                    "torque_evals": None,
                    "seconds": seconds,
                    RERUN: (compiled, (state, jnp.asarray(tol))),
                }
            )
            log(f"  {name:24s} tol {tol:8.1e} steps {mean_steps:9.1f} err {err:9.2e} {seconds * 1e3:9.2f} ms")
            if err < floor or seconds > 4 * time_cap or (quick and tol < 1e-5):
                break
            if outclassed(rows[-1]):
                log(f"  {name}: stopped, slower than {band:g}x a diffrax row that meets every budget")
                break
    log("  compile seconds: " + ", ".join(f"{k} {v:.1f}" for k, v in compile_seconds.items()))
    return rows, check, {"not_raced": skipped, "failed": rows_failed}, ref_steps, compile_seconds


def finalists(rows, band):
    """Per budget and side, each method's fastest row that meets it, where within ``band`` times the
    side's fastest: the rows one ladder timing cannot rank (``band``: that timing's spread, see
    `retime`). A method's slower rungs (more steps, a tighter tolerance) are not re-timed."""
    chosen = {}
    for budget in BUDGETS:
        fastest = {}
        for r in (r for r in rows if r["max_orientation_error_rad"] <= budget):
            if r["method"] not in fastest or r["seconds"] < fastest[r["method"]]["seconds"]:
                fastest[r["method"]] = r
        for side in (True, False):
            mine = [r for r in fastest.values() if is_diffrax(r) == side]
            if mine:
                best = min(r["seconds"] for r in mine)
                chosen.update((id(r), r) for r in mine if r["seconds"] <= band * best)
    return list(chosen.values())


def retime(rows, rounds, band, time_cap, log):
    """Round-robin re-timing of the `finalists`: both sides of a ratio see the same machine load.

    A finalist gets ``rounds`` rounds, fewer when its run is long: at most ``time_cap`` seconds of
    them, one at least (a run of seconds carries little of the scheduler's jitter; the published
    file's slow diffrax rows, 5–36 s, win budgets at ratios of 75x and more). Each re-timed row keeps
    its ladder time (``ladder_seconds``) and, from two rounds up, their spread (``rounds_spread``:
    (max − min) / median): the spread of one ladder timing against the rounds' median bounds
    ``band`` (in the 2026-11-27 file the ladder/median ratios spanned 0.55–1.15, under 2x), the
    rounds' spread the noise of the ratios the table reports."""
    final = finalists(rows, band)
    wanted = {id(r): max(1, min(rounds, int(time_cap // r["seconds"]))) for r in final}
    samples = {id(r): [] for r in final}
    for k in range(rounds):
        for r in (r for r in final if wanted[id(r)] > k):
            compiled, args = r[RERUN]
            samples[id(r)].append(seconds_of(compiled, *args))
    for r in final:
        mine = samples[id(r)]
        r["ladder_seconds"], r["seconds"] = r["seconds"], statistics.median(mine)
        r["rounds_spread"] = (max(mine) - min(mine)) / r["seconds"] if len(mine) > 1 else None
    spreads = [r["rounds_spread"] for r in final if r["rounds_spread"] is not None]
    spread = statistics.median(spreads) if spreads else None
    shown = "—" if spread is None else f"{spread:.0%}"
    log(f"  re-timed {len(final)} finalists side by side, up to {rounds} rounds (median spread {shown})")
    return spread


def main(argv=None):
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--n", type=int, default=1000)
    parser.add_argument("--stokes", default=",".join(f"{s:g}" for s in STOKES))
    parser.add_argument("--repeats", type=int, default=1, help="runs per rung (median)")
    parser.add_argument("--time-cap", type=float, default=4.0, help="stop a ladder past this many s per run")
    parser.add_argument(
        "--max-steps",
        type=int,
        default=4096,
        help="diffrax's steps per body, at most: diffrax's default, as a user would run it (a failing "
        "tolerance runs all bodies this far: Kvaerno5's at St = 1e-3, ~12 us a body-step, ~200 s at 16384)",
    )
    parser.add_argument("--rounds", type=int, default=7, help="round-robin re-timing rounds")
    parser.add_argument(
        "--band",
        type=float,
        default=2.0,
        help="re-time the rows within this factor of a budget's fastest on their side; end a ladder "
        "past this factor of its side's fastest row that meets every budget",
    )
    parser.add_argument("--out", default=None, help="folder for fluid_race_cpu.json/.png (default docs/)")
    parser.add_argument(
        "--quick", action="store_true", help="16 bodies, short ladders; writes nothing unless --out"
    )
    ns = parser.parse_args(argv)
    if ns.quick:
        ns.n, ns.repeats, ns.rounds = min(ns.n, 16), 1, 1
    out = Path(ns.out) if ns.out else (None if ns.quick else ROOT / "docs")
    log = lambda s: print(s, flush=True)  # noqa: E731
    info = machine_info()
    log(f"machine: {info}")
    report = {"machine": info, "options": vars(ns), "budgets": BUDGETS, "runs": []}
    for stokes in (float(s) for s in ns.stokes.split(",")):
        start = time.perf_counter()
        rows, check, skipped, ref_steps, compile_seconds = race_one(
            stokes, ns.n, ns.repeats, ns.time_cap, BUDGETS[-1] / 3, ns.max_steps, ns.quick, ns.band, log
        )
        spread = retime(rows, ns.rounds, ns.band, ns.time_cap, log)
        log(f"  St = {stokes:g}: {time.perf_counter() - start:.0f} s in all")
        table = budget_table(rows)
        floor = overdamped_floor(rows)
        log(f"  overdamped model's smallest error against the inertial reference: {floor:.2e} rad")
        for line in table:
            ratio = "—" if line["ratio"] is None else f"{line['ratio']:.1f}x"
            log(f"  {line['budget']:.0e}: {line['jaxrot']} | {line['diffrax']} | {ratio}")
        report["runs"].append(
            {
                "stokes": stokes,
                "reference_steps": ref_steps,
                "reference_vs_dopri8": check,
                "diffrax_failures": skipped,
                "overdamped_floor": floor,
                "rounds_spread": spread,
                "compile_seconds": compile_seconds,
                "table": table,
                "rows": [{k: v for k, v in r.items() if k != RERUN} for r in rows],
            }
        )
        # Written after each Stokes number: a run stopped later keeps what it measured (the file
        # says which Stokes numbers it holds).
        if out is not None:
            out.mkdir(parents=True, exist_ok=True)
            (out / "fluid_race_cpu.json").write_text(json.dumps(report, indent=2))
            plot(report, out / "fluid_race_cpu.png")
            log(f"wrote {out / 'fluid_race_cpu.json'} and .png ({len(report['runs'])} Stokes numbers)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
