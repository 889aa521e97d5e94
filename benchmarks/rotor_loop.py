"""The free rotor's while loop on a GPU: DMV steps per loop iteration (`_rotor_loop.LOOP_BATCH`) 1, 2, 4, 8.

The rotor covers each flow with ``n = ⌈|ω| t / 0.2⌉`` DMV steps per body; past the first two they
run in a while loop. On a GPU each iteration is a few kernel launches and a host read of the loop
predicate, so with few long steps (the race's coarse rungs) the rotor schemes have a floor set by
the iterations, not by the step count (docs/performance.md, "A second GPU"). This times the
race's fixed-step runner of the rotor schemes on the dipole scene (N = 1000, float64) at a few
step counts, for each loop batch in one process (caches cleared between them), and gives the
largest orientation difference from batch 1 (more, shorter DMV steps: the rotor's error, ~1e-13,
not the scheme's). ``--fixed-substeps 2`` adds rows with the count fixed (no while loop at all:
the floor the loop's host reads sit on; inexact where a flow turns more than 2 rad).
``--command-buffers`` adds rows compiled with `jaxrot.compiler_options("gpu")`: XLA's command
buffers (CUDA graphs) holding while loops and conditionals, a per-program compiler option (not the
process's XLA_FLAGS). The optimized program's text does not show them: only the timings do.

    python benchmarks/rotor_loop.py --json rotor_loop.json           # on the GPU machine
"""

import argparse
import json
import sys
import time
from pathlib import Path

import jax


jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp

import jaxrot
from jaxrot import quaternion as quat
from jaxrot._free_body import _rotor_loop
from jaxrot.comparison import machine_info


sys.path.insert(0, str(Path(__file__).parent))
from race import fixed_step_runner, random_bodies, timed  # noqa: E402


def main():
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--scene", default="dipole_rotating_field")
    parser.add_argument("--schemes", default="splitting,srkn6b,srkn14a")
    parser.add_argument("--steps", default="8,32,128,256")
    parser.add_argument("--batches", default="1,2,4,8")
    parser.add_argument("--n", type=int, default=1000)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument(
        "--fixed-substeps", type=int, default=None,
        help="also time each scheme with this fixed rotor count (no while loop; inexact at long flows)",
    )  # fmt: skip
    parser.add_argument(
        "--command-buffers",
        action="store_true",
        help='also time the batches of --command-buffer-batches compiled with jaxrot.compiler_options("gpu")',
    )
    parser.add_argument("--command-buffer-batches", default="1,4")
    parser.add_argument("--json", default=None)
    opts = parser.parse_args()
    scene = jaxrot.SCENES[opts.scene](jnp.float64)
    state = random_bodies(scene, opts.n, jnp.float64)
    steps_list = [int(s) for s in opts.steps.split(",")]
    batches = [int(b) for b in opts.batches.split(",")]
    info = machine_info() | {"stage_barriers": jaxrot._core._fusion._barriers()}
    print(f"machine: {info}\nN = {opts.n}")
    rows, first = [], {}
    settings = [(b, b, None, None) for b in batches]
    if opts.fixed_substeps:
        settings.append((f"fixed{opts.fixed_substeps}", 1, opts.fixed_substeps, None))
    if opts.command_buffers:
        cb = jaxrot.compiler_options("gpu")
        info["command_buffer_types"] = cb.get("xla_gpu_enable_command_buffer")
        for b in opts.command_buffer_batches.split(","):
            settings.append((f"{b}+cb", int(b), None, cb))
    for label, batch, fixed, options in settings:
        _rotor_loop.LOOP_BATCH = batch
        jax.clear_caches()  # the rotor's loop form is fixed when traced
        for name in opts.schemes.split(","):
            scheme = jaxrot.SCHEMES[name]
            if fixed is not None:
                scheme = type(scheme)(rotor_substeps=fixed)
            runner = fixed_step_runner(scheme, scene)
            start = time.perf_counter()
            compiled = runner.lower(state, jnp.asarray(1.0), 1).compile(compiler_options=options)
            compile_s = time.perf_counter() - start
            for steps in steps_list:
                out, seconds = timed(
                    compiled, state, jnp.asarray(scene.t_end / steps), steps, repeats=opts.repeats
                )
                ref = first.setdefault((name, steps), out.q)
                diff = float(jnp.max(quat.angle_between(out.q, ref)))
                ms = seconds * 1e3
                row = {"scheme": name, "steps": steps, "loop_batch": label, "ms": ms, "compile_s": compile_s,
                       "max_angle_from_batch_1": diff}  # fmt: skip
                rows.append(row)
                print(f"{name:10s} steps {steps:4d} batch {label}  {row['ms']:8.2f} ms  "
                      f"compile {compile_s:5.1f} s  Δ {diff:.1e}", flush=True)  # fmt: skip
    print("\nms per run (ratio to batch 1):")
    for name in opts.schemes.split(","):
        for steps in steps_list:
            ms = {r["loop_batch"]: r["ms"] for r in rows if r["scheme"] == name and r["steps"] == steps}
            cells = "  ".join(
                f"b{b} {ms[b]:8.2f} ({ms[batches[0]] / ms[b]:4.2f}x)" for b, *_ in settings if b in ms
            )
            print(f"{name:10s} {steps:4d}  {cells}")
    if opts.json:
        Path(opts.json).write_text(
            json.dumps({"machine": info, "options": vars(opts), "rows": rows}, indent=2)
        )


if __name__ == "__main__":
    main()
