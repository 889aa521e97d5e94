"""Compile time of a rollout and of its gradient: every jaxrot scheme against diffrax's Tsit5, Dopri5, Dopri8.

The problem is the one a fitting user compiles first: 200 fixed steps of the `heavy_top` scene
(dt = 0.005, one body, float64) saving every 10th state; the forward program returns the saved
orientations, the gradient program ``jax.grad`` of a scalar misfit of them with respect to the
inertia (3,) and the torque's argument (the centre-of-mass offset). diffrax integrates the same
`jaxrot.RigidBodyTerm` at the same constant step (`diffrax.ConstantStepSize`, its default
`RecursiveCheckpointAdjoint`).

Every cell is measured in a fresh Python process (JAX's in-memory caches of traced and compiled
functions start empty, as they do for a user's first call; the persistent cache is off):
``trace_s`` is tracing and lowering to StableHLO (``jit(f).lower``), ``compile_s`` XLA's
compilation of it (``.compile()``), and ``hlo_ops`` the number of instructions in the optimised
HLO (what XLA had to compile), ``run_ms`` the median of 7 runs of the compiled program once it
is compiled (one body: the fitting user's case). The table prints the totals against diffrax's
fastest-compiling solver of the same kind (forward or gradient), and the gradient's run time
against diffrax's fastest-running one, measured in the same run. ``name+loop`` rows are the
Lie-group Runge–Kutta schemes with ``loop_stages=True`` (stages in a loop everywhere),
``name+unrolled`` rows with ``loop_derivative_stages=False`` (the unrolled stages differentiated:
the default until the looped derivative rule).

    python benchmarks/compile.py                       # every scheme, writes docs/compile_cpu.json
    python benchmarks/compile.py --methods zhao,rkmk_dopri8,diffrax_dopri8 --out /tmp/c.json
"""

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path


STEPS, SAVE_EVERY = 200, 10
DIFFRAX = ("diffrax_tsit5", "diffrax_dopri5", "diffrax_dopri8")
KINDS = ("forward", "gradient")
RUNS = 7  # timed runs of each compiled program after the first; the median is reported
# The Lie-group Runge–Kutta schemes again with ``loop_stages=True`` (their stages in one loop), and
# with ``loop_derivative_stages=False`` (unrolled stages differentiated: the default before it).
VARIANTS = {"loop": {"loop_stages": True}, "unrolled": {"loop_derivative_stages": False}}
VARIANT_ROWS = tuple(f"{name}+{v}" for v in VARIANTS for name in ("rkmk4", "rkmk_dopri5", "rkmk_dopri8"))


def _programs(method):
    """(forward, gradient) functions of ``(inertia, args)`` and the example arguments."""
    import diffrax
    import jax
    import jax.numpy as jnp

    import jaxrot
    from jaxrot.scenes import heavy_top

    scene = heavy_top(jnp.float64)
    dt = scene.dt
    ts = dt * SAVE_EVERY * jnp.arange(STEPS // SAVE_EVERY + 1, dtype=jnp.float64)

    if method in DIFFRAX:
        solver = getattr(diffrax, method.removeprefix("diffrax_").capitalize())  # diffrax_tsit5 -> Tsit5

        def saved_q(inertia, args):
            sol = diffrax.diffeqsolve(
                jaxrot.RigidBodyTerm(inertia, scene.torque), solver(), 0.0, STEPS * dt, dt,
                scene.state, args=args, saveat=diffrax.SaveAt(ts=ts), max_steps=STEPS,
            )  # fmt: skip
            return sol.ys.q
    else:
        name, _, variant = method.partition("+")
        scheme = type(jaxrot.SCHEMES[name])(**VARIANTS[variant]) if variant else name

        def saved_q(inertia, args):
            traj = jaxrot.rollout(
                scheme, scene.state, inertia, dt, STEPS, torque=scene.torque, args=args, save_every=SAVE_EVERY
            )
            return traj.q

    weights = jnp.linspace(0.5, 1.5, 4, dtype=jnp.float64)

    def loss(inertia, args):
        return jnp.sum(saved_q(inertia, args) * weights)

    gradient = jax.grad(loss, argnums=(0, 1))
    return {"forward": saved_q, "gradient": gradient}, (scene.inertia, scene.args)


def measure_one(method, kind):
    """One cell, in this process: tracing/lowering and compile seconds, optimised HLO size."""
    import jax

    jax.config.update("jax_enable_x64", True)
    programs, example = _programs(method)
    start = time.perf_counter()
    lowered = jax.jit(programs[kind]).lower(*example)
    traced = time.perf_counter()
    compiled = lowered.compile()
    done = time.perf_counter()
    jax.block_until_ready(compiled(*example))  # the program runs: nothing was compiled lazily
    runs = []
    for _ in range(RUNS):
        start_run = time.perf_counter()
        jax.block_until_ready(compiled(*example))
        runs.append(time.perf_counter() - start_run)
    hlo = compiled.as_text() or ""
    ops = sum(1 for line in hlo.splitlines() if " = " in line and not line.lstrip().startswith("//"))
    return {
        "method": method,
        "kind": kind,
        "trace_s": traced - start,
        "compile_s": done - traced,
        "total_s": done - start,
        "hlo_ops": ops,
        "run_ms": 1e3 * sorted(runs)[len(runs) // 2],
    }


def table(rows):
    """Markdown table: one row per method, forward and gradient totals, ratio to diffrax's best."""
    best = {
        k: min((r["total_s"] for r in rows if r["kind"] == k and r["method"] in DIFFRAX), default=None)
        for k in KINDS
    }
    cells = {(r["method"], r["kind"]): r for r in rows}
    run_best = min(
        (r["run_ms"] for r in rows if r["kind"] == "gradient" and r["method"] in DIFFRAX and "run_ms" in r),
        default=None,
    )
    lines = [
        "| method | forward [s] | ÷ diffrax best | gradient [s] (trace + compile) | ÷ diffrax best "
        "| gradient HLO ops | gradient run [ms] | ÷ diffrax best |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for method in dict.fromkeys(r["method"] for r in rows):
        out = [f"`{method}`"]
        for kind in KINDS:
            r = cells.get((method, kind))
            if r is None:
                out += ["–", "–"]
                continue
            total = (
                f"{r['total_s']:.1f}"
                if kind == "forward"
                else f"{r['total_s']:.1f} ({r['trace_s']:.1f} + {r['compile_s']:.1f})"
            )
            out += [total, f"{r['total_s'] / best[kind]:.1f}×" if best[kind] else "–"]
        g = cells.get((method, "gradient"))
        out.append(str(g["hlo_ops"]) if g else "–")
        if g and "run_ms" in g:
            out += [f"{g['run_ms']:.2f}", f"{g['run_ms'] / run_best:.1f}×" if run_best else "–"]
        else:
            out += ["–", "–"]
        lines.append("| " + " | ".join(out) + " |")
    return "\n".join(lines)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--methods", default=None, help="comma-separated; default: every scheme and diffrax's three"
    )
    parser.add_argument("--kinds", default=",".join(KINDS))
    parser.add_argument(
        "--out", default=str(Path(__file__).resolve().parents[1] / "docs" / "compile_cpu.json")
    )
    parser.add_argument("--one", nargs=2, metavar=("METHOD", "KIND"), help=argparse.SUPPRESS)
    opts = parser.parse_args()
    if opts.one:
        print(json.dumps(measure_one(*opts.one)))
        return

    import jaxrot
    from jaxrot.comparison import machine_info

    methods = opts.methods.split(",") if opts.methods else [*jaxrot.SCHEMES, *VARIANT_ROWS, *DIFFRAX]
    jobs = [(m, k) for m in methods for k in opts.kinds.split(",")]
    rows = []
    try:
        from tqdm import tqdm

        jobs_iter = tqdm(jobs, desc="compile")
    except ImportError:
        jobs_iter = jobs
    for method, kind in jobs_iter:
        env = {"JAX_ENABLE_COMPILATION_CACHE": "false"}
        out = subprocess.run(
            [sys.executable, __file__, "--one", method, kind],
            capture_output=True, text=True, env={**os.environ, **env},
        )  # fmt: skip
        if out.returncode != 0:
            sys.exit(f"{method} {kind} failed:\n{out.stderr[-3000:]}")
        rows.append(json.loads(out.stdout.strip().splitlines()[-1]))
    result = {
        "machine": machine_info(),
        "problem": f"heavy_top float64, {STEPS} steps, save every {SAVE_EVERY}",
        "rows": rows,
    }
    Path(opts.out).write_text(json.dumps(result, indent=1) + "\n")
    print(table(rows))
    print(f"\nwritten: {opts.out}")


if __name__ == "__main__":
    main()
