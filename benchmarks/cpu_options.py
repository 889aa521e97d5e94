"""XLA:CPU's vector width: each scheme's rollout with 512-bit vectors against XLA's 256, same process.

Whether `jaxrot.compiler_options()` should ask XLA:CPU for 512-bit vectors where the CPU has
AVX-512 (measured on an AMD EPYC: median 1.05x, 0.79-1.16x, so it does not; docs/performance.md).
The throughput program of `benchmarks/throughput.py` (N heavy tops, one `jaxrot.rollout`)
compiled twice, with ``xla_cpu_prefer_vector_width`` 512 and 256 (XLA's default), the rest of
jaxrot's options the same, timed in alternation (``--rounds`` rounds, median), and the final
states compared bit for bit.

    python benchmarks/cpu_options.py                                  # ~7 minutes on 2 cores
    python benchmarks/cpu_options.py --json docs/cpu_vector_width.json   # the file the docs render
"""

import argparse
import json
import statistics

import jax


jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np
from throughput import bodies, jaxrot_run
from tqdm import tqdm

import jaxrot
from jaxrot.comparison import machine_info, time_runs


def cpu_description():
    """``(model name, whether the CPU has AVX-512F)`` from Linux's /proc/cpuinfo (``("?", False)``
    where there is none)."""
    try:
        with open("/proc/cpuinfo") as f:
            lines = f.read().splitlines()
    except OSError:
        return "?", False
    model = next((line.split(":", 1)[1].strip() for line in lines if line.startswith("model name")), "?")
    return model, any(line.startswith("flags") and "avx512f" in line.split() for line in lines)


def measure(cells, schemes, work, rounds):
    base = jaxrot.compiler_options("cpu")
    rows = []
    for dtype_name, n in tqdm(cells, desc="vector width"):
        state, scene = bodies(n, {"float32": jnp.float32, "float64": jnp.float64}[dtype_name])
        steps = int(np.clip(work // n, 10, 10_000))
        for scheme in schemes:
            programs = {
                width: jax.jit(
                    jaxrot_run(scheme, scene, steps),
                    compiler_options=base | {"xla_cpu_prefer_vector_width": width},
                )
                .lower(state)
                .compile()
                for width in (512, 256)
            }
            seconds = {width: [] for width in programs}
            outputs = {}
            for _ in range(rounds):
                for width, program in programs.items():
                    outputs[width], s = time_runs(program, (state,), 3)
                    seconds[width].append(s)
            rate = {w: n * steps / statistics.median(s) for w, s in seconds.items()}
            rows.append(
                {
                    "dtype": dtype_name,
                    "n": n,
                    "scheme": scheme,
                    "steps": steps,
                    "rate_512": rate[512],
                    "rate_256": rate[256],
                    "same_bits": bool(np.array_equal(outputs[512], outputs[256])),
                }
            )
    return rows


def table(rows):
    lines = ["| dtype | N | " + " | ".join(dict.fromkeys(r["scheme"] for r in rows)) + " |"]
    lines.append("|" + "---|" * (lines[0].count("|") - 1))
    for key in dict.fromkeys((r["dtype"], r["n"]) for r in rows):
        cells = [f"{r['rate_512'] / r['rate_256']:.2f}" for r in rows if (r["dtype"], r["n"]) == key]
        lines.append(f"| {key[0]} | {key[1]:.0e} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--cells", default="float64:1000,float64:10000,float64:100000,float32:10000", help="dtype:N,..."
    )
    parser.add_argument("--schemes", default=",".join(jaxrot.SCHEMES))
    parser.add_argument("--work", type=float, default=1e6, help="particle-steps per timed run")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--json", default=None)
    ns = parser.parse_args(argv)
    cells = [(c.split(":")[0], int(c.split(":")[1])) for c in ns.cells.split(",")]
    model, avx512 = cpu_description()
    info = machine_info() | {
        "cpu_model": model,
        "avx512f": avx512,
        "jaxrot_compiler_options": jaxrot.compiler_options("cpu"),
    }
    print(info)
    rows = measure(cells, ns.schemes.split(","), ns.work, ns.rounds)
    print("Throughput with 512-bit vectors over 256-bit (XLA's default), same process:")
    print(table(rows))
    print("same bits:", all(r["same_bits"] for r in rows))
    if ns.json:
        with open(ns.json, "w") as f:
            json.dump({"machine": info, "rows": rows}, f, indent=1)


if __name__ == "__main__":
    main()
