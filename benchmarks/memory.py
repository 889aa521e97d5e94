"""Peak memory of a `jaxrot.rollout` of 10⁶ bodies, every scheme, and its growth with the saved states.

Each configuration runs in a fresh subprocess, so the peak resident set size
(``ru_maxrss``) is that run's alone. Printed per row: the process peak, the
same process's peak just before the rollout (Python, jax, the input state and
the compilation), and XLA's own accounting of the compiled program (arguments, outputs,
temporaries). The heavy-top torque and random orientations are those of
`benchmarks/throughput.py`.

    python benchmarks/memory.py                       # 10⁶ bodies × 20 steps, saving 2 or 11 states
    python benchmarks/memory.py --json docs/memory_cpu.json   # the results file the docs render
    python benchmarks/memory.py --n 100000 --steps 100,1000,10000 --save-every 100
"""

import argparse
import json
import os
import platform
import subprocess
import sys


CHILD = r"""
import json, resource, sys, time
import jax
jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp
sys.path.insert(0, {bench_dir!r})
import jaxrot
from throughput import bodies

n, steps, save_every, scheme, chunk = {n}, {steps}, {save_every}, {scheme!r}, {chunk}
state, scene = bodies(n, jnp.float64)
jax.block_until_ready(state)


def run(s, chunk_steps=None):
    return jaxrot.rollout(scheme, s, scene.inertia, 1e-3, steps, torque=scene.torque, args=scene.args,
                          save_every=save_every, chunk_steps=chunk_steps)


stats = jax.jit(run).lower(state).compile().memory_analysis()
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
start = time.perf_counter()
traj = run(state, chunk or None)
jax.block_until_ready(traj)
seconds = time.perf_counter() - start
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(json.dumps({{
    "peak_rss_mib": peak / 1024, "rss_before_mib": before / 1024, "seconds": seconds,
    "xla_argument_mib": stats.argument_size_in_bytes / 2**20,
    "xla_output_mib": stats.output_size_in_bytes / 2**20,
    "xla_temp_mib": stats.temp_size_in_bytes / 2**20,
    "saved_states": int(traj.q.shape[0]),
}}))
"""


def measure(n, steps, save_every, scheme, chunk=0):
    code = CHILD.format(
        bench_dir=os.path.dirname(os.path.abspath(__file__)),
        n=n,
        steps=steps,
        save_every=save_every,
        scheme=scheme,
        chunk=chunk,
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    row = json.loads(out.stdout.strip().splitlines()[-1])
    row.update(n=n, steps=steps, save_every=save_every, scheme=scheme, chunk_steps=chunk or None)
    return row


def main(argv=None):
    import jax

    import jaxrot
    from jaxrot.comparison import machine_info

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--n", type=int, default=1_000_000)
    parser.add_argument("--steps", default="20", help="comma-separated step counts")
    parser.add_argument("--save-every", default="20,2", help="comma-separated")
    parser.add_argument("--schemes", default=",".join(jaxrot.SCHEMES), help="comma-separated (default: all)")
    parser.add_argument("--chunk-steps", type=int, default=0, help="also run in chunks of this many steps")
    parser.add_argument("--json", default=None)
    ns = parser.parse_args(argv)

    print(
        f"jaxrot rollout memory — heavy top, float64, N = {ns.n:.0e}; {platform.machine()}, "
        f"{os.cpu_count()} CPUs, python {platform.python_version()}, jax {jax.__version__}"
    )
    head = (
        "| scheme | steps | save every | saved | chunk | peak RSS [MiB] | peak RSS before the run [MiB] | "
        "XLA args [MiB] | XLA output [MiB] | XLA temp [MiB] | run [s] |"
    )
    print(head)
    print("|" + "---|" * (head.count("|") - 1))
    rows = []
    for scheme in ns.schemes.split(","):
        for steps in [int(float(s)) for s in ns.steps.split(",")]:
            for save_every in [int(float(k)) for k in ns.save_every.split(",")]:
                # Chunks end on saved steps: only chunk sizes that are multiples of save_every.
                chunked = ns.chunk_steps and ns.chunk_steps % save_every == 0 and ns.chunk_steps < steps
                chunks = [0] + ([ns.chunk_steps] if chunked else [])
                for chunk in chunks:
                    r = measure(ns.n, steps, save_every, scheme, chunk)
                    rows.append(r)
                    print(
                        f"| {scheme} | {steps} | {save_every} | {r['saved_states']} | {chunk or '—'} | "
                        f"{r['peak_rss_mib']:.0f} | {r['rss_before_mib']:.0f} | "
                        f"{r['xla_argument_mib']:.1f} | "
                        f"{r['xla_output_mib']:.1f} | {r['xla_temp_mib']:.1f} | {r['seconds']:.1f} |",
                        flush=True,
                    )
    if ns.json:
        with open(ns.json, "w") as f:
            json.dump({"machine": machine_info(), "options": vars(ns), "rows": rows}, f, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
