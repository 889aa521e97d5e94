"""MuJoCo 4.0 against jaxrot on the free body: error against cost per body, both measured in one process.

The problem: ``--n`` bodies (default 1000) with principal moments I = (1, 2, 3), random
orientations and random body-frame rates (each component normal, 1 rad/s), torque-free, to
t = ``--t-end`` (10), float64. Torque-free because it is the motion MuJoCo's free joint models with
nothing added (a torque model would be a callback or an actuator of MuJoCo's, whose cost would be
measured instead of the integrators'), and its exact solution (`jaxrot.analytic.free_top`, elliptic
functions) is the reference: the error of a row is the largest geodesic orientation error over the
bodies at the final time.

MuJoCo's side: its integrators Euler (semi-implicit), implicit, implicitfast and RK4, gravity,
contacts and constraints off, each body on its own free joint (``qpos[3:7]`` its orientation,
scalar first, body → world; ``qvel[3:6]`` its angular velocity in the **body** frame), and the
ways to run it, each timed:

- ``one_model``: one model holding all bodies, ``mj_step`` in a Python loop (the issue's cheapest);
- ``rollout``: the same model through ``mujoco.rollout`` (the loop in C, the states recorded);
- ``rollout_threads``: ``--n`` one-body rollouts of a one-body model, ``mujoco.rollout`` on a pool of
  ``os.cpu_count()`` threads (MuJoCo's way to use every core);
- ``rollout_groups``: the same pool running models of `GROUP` bodies each (``--n / GROUP`` rollouts);
- ``--joints free,ball`` adds ``one_model`` with ball joints (rotation only, nothing translated).

A MuJoCo step costs the same at any step size (no contacts, no solver iterations), so each path is
timed once (``--timing-steps`` steps, median of ``--repeats``) and its cost per body-step applies to
every rung; the errors come from one untimed run per rung of the ``rollout_groups`` path (the same
orbits as the other paths' to round-off: ``path_agreement_rad``). Groups, because a one-body model
pays MuJoCo's fixed cost per step for every body (4-5x the CPU time per body-step of a 20-body
model under Euler and RK4, measured) and one model of 1000 bodies costs the implicit integrator
tens of µs per body-step (its dense factorisation). jaxrot's side: every scheme in `jaxrot.SCHEMES`
through `jaxrot.rollout`, each rung timed (the rotor schemes' cost depends on the step) until a run
passes ``--time-cap`` and run once, untimed, past it (its error still goes to the accuracy table;
the splitting, exact here, meets every budget in 32 steps, far below the cap), compiled with
`jaxrot.compiler_options`. Both
ladders halve the step from ``--t-end / 32`` until the error is below 1e-12, stops falling, or the
number of steps passes ``--max-steps``. ``--no-timing`` measures the errors only (the timing fields
null): errors do not depend on the machine's load, timings do.

    python benchmarks/mujoco_free_body.py --json docs/mujoco_free_body_cpu.json   # ~10 min, 2 cores
    python benchmarks/mujoco_free_body.py --n 10 --t-end 1 --max-steps 1000 --timing-steps 50  # check

Needs ``pip install -e ".[mujoco]"``; without MuJoCo it prints why and exits 0.
"""

import argparse
import importlib.util
import json
import os
import sys
import time

import jax


jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np
from _mujoco_paths import (  # noqa: E402 (benchmarks/)
    INTEGRATORS,
    MOMENTS,
    model_xml,  # noqa: E402, F401  (mjx_peer.py imports it from here)
    mujoco_final,
    mujoco_path_costs,
)

import jaxrot
from jaxrot import quaternion as quat
from jaxrot.comparison import fit_order, machine_info, time_compiled


BUDGETS = [10.0**-k for k in range(1, 11)]
FLOOR = 1e-12  # below this the ladder stops: the reference and round-off
ASYMPTOTIC = 0.5  # rad; orders are fitted on rungs between 10·FLOOR and this (first order: 0.4, 0.2, 0.1)
STALL = 0.1  # rad; below this a rung that does not cut the error by 30 % ends its ladder


def bodies(n, seed=0):
    """``(q (n, 4), omega_body (n, 3))``: random orientations and body-frame rates."""
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True), rng.normal(size=(n, 3))


def max_angle(q, q_ref):
    """The largest geodesic angle between two batches of orientations; None for a blown-up run."""
    if q is None:
        return None
    error = float(jnp.max(quat.angle_between(jnp.asarray(q), jnp.asarray(q_ref))))
    return error if np.isfinite(error) else None


def ladder(max_steps, start=32):
    """Step counts from ``start``, doubling, up to ``max_steps``."""
    n_steps = start
    while n_steps <= max_steps:
        yield n_steps
        n_steps *= 2


def _done(error, previous):
    """The ladder stops at the floor, or where the error stopped falling below the saturated range."""
    return error is not None and (error < FLOOR or (error < STALL and error > 0.7 * previous))


def mujoco_rows(q, omega_body, q_ref, t_end, max_steps, log=print):
    rows = []
    for integrator in INTEGRATORS:
        previous = float("inf")
        for n_steps in ladder(max_steps):
            error = max_angle(mujoco_final(integrator, q, omega_body, t_end / n_steps, n_steps), q_ref)
            rows.append(
                {
                    "side": "mujoco",
                    "method": f"mujoco_{integrator}",
                    "n_steps": n_steps,
                    "dt": t_end / n_steps,
                    "error_rad": error,
                }
            )
            log(f"mujoco_{integrator:13s} {n_steps:7d} steps  error {error} rad")
            if _done(error, previous):
                break
            previous = float("inf") if error is None else error
    return rows


def jaxrot_rows(q, omega_body, q_ref, t_end, max_steps, repeats, timing, time_cap, log=print):
    q = jnp.asarray(q)
    state = jaxrot.RotState(q, quat.rotate(q, jnp.asarray(omega_body)))
    moments = jnp.asarray(MOMENTS)
    rows = []
    for name in jaxrot.SCHEMES:
        previous = float("inf")
        timed = timing  # until a run passes the time cap
        for n_steps in ladder(max_steps):

            def run(state, name=name, n_steps=n_steps):
                traj = jaxrot.rollout(name, state, moments, t_end / n_steps, n_steps, save_every=n_steps)
                return traj.q[-1]

            if timed:
                q_end, compile_s, seconds = time_compiled(run, state, repeats, jaxrot.compiler_options())
            else:
                compiled = jax.jit(run, compiler_options=jaxrot.compiler_options()).lower(state).compile()
                start = time.perf_counter()
                q_end = jax.block_until_ready(compiled(state))
                seconds, compile_s = time.perf_counter() - start, None
            error = max_angle(q_end, q_ref)
            row = {
                "side": "jaxrot",
                "method": name,
                "n_steps": n_steps,
                "dt": t_end / n_steps,
                "error_rad": error,
                "ns_per_body_step": None,
                "us_per_body": None,
                "compile_s": compile_s,
            }
            if timed:
                row["ns_per_body_step"] = 1e9 * seconds / (len(q) * n_steps)
                row["us_per_body"] = 1e6 * seconds / len(q)
            rows.append(row)
            log(f"{name:19s} {n_steps:7d} steps  error {error} rad  {row['ns_per_body_step'] or 0:.1f} ns")
            if _done(error, previous):
                break
            timed = timed and seconds <= time_cap
            previous = error
    return rows


def orders(rows):
    """Per method, the slope of log(error) against log(dt) over its rungs in (10·FLOOR, ASYMPTOTIC)."""
    out = {}
    for name in dict.fromkeys(r["method"] for r in rows):
        mine = [
            r
            for r in rows
            if r["method"] == name and r["error_rad"] is not None and 10 * FLOOR < r["error_rad"] < ASYMPTOTIC
        ]
        out[name] = (
            fit_order([r["dt"] for r in mine], [r["error_rad"] for r in mine]) if len(mine) >= 2 else None
        )
    return out


def budgets(rows):
    """For each budget, the cheapest row of each side meeting it (cost per body over the horizon)."""
    out = []
    for budget in BUDGETS:
        best = {}
        for side in ("mujoco", "jaxrot"):
            meeting = [
                r
                for r in rows
                if r["side"] == side
                and r["error_rad"] is not None
                and r["error_rad"] <= budget
                and r["us_per_body"]
            ]
            best[side] = min(meeting, key=lambda r: r["us_per_body"]) if meeting else None
        m, j = best["mujoco"], best["jaxrot"]
        out.append(
            {
                "budget_rad": budget,
                "mujoco": m and {k: m[k] for k in ("method", "path", "n_steps", "error_rad", "us_per_body")},
                "jaxrot": j and {k: j[k] for k in ("method", "n_steps", "error_rad", "us_per_body")},
                "ratio": m["us_per_body"] / j["us_per_body"] if m and j else None,
            }
        )
    return out


def plot(rows, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    timed = any(r.get("us_per_body") for r in rows)
    fig, axes = plt.subplots(
        1, 2 if timed else 1, figsize=(12.5 if timed else 7, 4.2), constrained_layout=True
    )
    axes = np.atleast_1d(axes)
    colours = iter(plt.get_cmap("tab20").colors)
    for name in dict.fromkeys(r["method"] for r in rows):
        mine = [r for r in rows if r["method"] == name]
        style = dict(
            marker="s" if mine[0]["side"] == "mujoco" else "o",
            label=name,
            color=next(colours),
            linestyle="--" if mine[0]["side"] == "mujoco" else "-",
        )
        mine = [r for r in mine if r["error_rad"] is not None]  # blown-up rungs are left out
        axes[0].loglog([r["dt"] for r in mine], [r["error_rad"] for r in mine], **style)
        if timed:
            mine = [r for r in mine if r.get("us_per_body")]  # rungs past the time cap: untimed
            axes[1].loglog([r["us_per_body"] for r in mine], [r["error_rad"] for r in mine], **style)
    axes[0].set(xlabel="time step", ylabel="max orientation error at t_end [rad]")
    if timed:
        axes[1].set(xlabel="wall time per body over the horizon [µs]")
        axes[1].legend(loc="center left", bbox_to_anchor=(1.0, 0.5), fontsize=8)
    else:
        axes[0].legend(loc="center left", bbox_to_anchor=(1.0, 0.5), fontsize=8)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=1000, help="bodies")
    parser.add_argument("--t-end", type=float, default=10.0)
    parser.add_argument("--max-steps", type=int, default=65536, help="the ladders' last rung at most")
    parser.add_argument("--timing-steps", type=int, default=200, help="MuJoCo steps per timed run")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument(
        "--time-cap", type=float, default=1.0, help="s; past a jaxrot run this long its ladder runs untimed"
    )
    parser.add_argument("--joints", default="free,ball", help="one_model joint kinds timed")
    parser.add_argument("--no-timing", action="store_true", help="errors only (timing fields null)")
    parser.add_argument("--json", default=None)
    parser.add_argument("--png", default=None, help="the work-precision figure")
    opts = parser.parse_args(argv)
    if importlib.util.find_spec("mujoco") is None:
        print('mujoco_free_body: MuJoCo is not installed (pip install -e ".[mujoco]"); nothing measured')
        return 0
    import mujoco

    timing = not opts.no_timing
    info = machine_info() | {"mujoco": mujoco.__version__}
    print(", ".join(f"{k} {v}" for k, v in info.items()))
    q, omega_body = bodies(opts.n)
    state = jaxrot.RotState(jnp.asarray(q), quat.rotate(jnp.asarray(q), jnp.asarray(omega_body)))
    q_ref = jaxrot.analytic.free_top(state, jnp.asarray(MOMENTS), jnp.array([0.0, opts.t_end])).q[-1]
    rows = mujoco_rows(q, omega_body, q_ref, opts.t_end, opts.max_steps)
    paths, agreement = [], {}
    for integrator in INTEGRATORS:
        # Untimed, the paths still run once each: their orbits' agreement is recorded either way.
        costs, finals = mujoco_path_costs(
            q,
            omega_body,
            integrator,
            opts.timing_steps,
            opts.repeats if timing else 1,
            opts.joints.split(","),
        )
        base = finals["one_model"]
        agreement[integrator] = {p: max_angle(f, base) for p, f in finals.items() if p != "one_model"}
        print(f"mujoco_{integrator:13s} paths against one_model: {agreement[integrator]}")
        if not timing:
            continue
        for path, seconds in costs.items():
            paths.append({"integrator": integrator, "path": path, "ns_per_body_step": 1e9 * seconds})
            print(f"mujoco_{integrator:13s} {path:16s} {1e9 * seconds:8.1f} ns per body-step")
        cheapest = min(
            (p for p in paths if p["integrator"] == integrator and p["path"] != "one_model_ball"),
            key=lambda p: p["ns_per_body_step"],
        )
        for r in rows:
            if r["method"] == f"mujoco_{integrator}":
                r.update(
                    path=cheapest["path"],
                    ns_per_body_step=cheapest["ns_per_body_step"],
                    us_per_body=cheapest["ns_per_body_step"] * r["n_steps"] / 1e3,
                )
    for r in rows:
        r.setdefault("path", None), r.setdefault("ns_per_body_step", None), r.setdefault("us_per_body", None)
    rows += jaxrot_rows(q, omega_body, q_ref, opts.t_end, opts.max_steps, opts.repeats, timing, opts.time_cap)
    result = {
        "machine": info,
        "settings": {
            "n": opts.n,
            "t_end": opts.t_end,
            "moments": MOMENTS,
            "omega_body_std": 1.0,
            "max_steps": opts.max_steps,
            "timing_steps": opts.timing_steps,
            "repeats": opts.repeats,
            "timed": timing,
            "order_fit_rad": [10 * FLOOR, ASYMPTOTIC],
            "threads": os.cpu_count(),
        },
        "mujoco_paths": paths,
        "path_agreement_rad": agreement,
        "orders": orders(rows),
        "budgets": budgets(rows) if timing else [],
        "rows": rows,
    }
    print("orders:", ", ".join(f"{k} {v:.2f}" for k, v in result["orders"].items() if v is not None))
    for b in result["budgets"]:
        m, j = b["mujoco"], b["jaxrot"]
        print(
            f"{b['budget_rad']:.0e}: mujoco {m and m['method']} {m and m['us_per_body']:.4g} µs, "
            f"jaxrot {j and j['method']} {j and j['us_per_body']:.4g} µs, ratio {b['ratio']}"
        )
    if opts.json:
        with open(opts.json, "w") as f:
            json.dump(result, f, indent=1)
    if opts.png:
        plot(rows, opts.png)
    return 0


if __name__ == "__main__":
    sys.exit(main())
