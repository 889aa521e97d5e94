"""Rerun the benchmarks behind every published number: each writes the results file its docs page renders.

Every table and figure of README.md and the documentation site is rendered (by
``docs/_hooks/tables.py``) from a results file under ``docs/``, and each results file records
the machine, the versions, the commit and the date it was measured on
(`jaxrot.comparison.machine_info`). This script reruns the benchmarks that write them, one after
another in fresh processes, so that nothing else competes for the cores while one is timed.

    python benchmarks/regenerate.py --list              # the jobs, their files and rough times
    python benchmarks/regenerate.py                     # all of them (about 2 h on 2 cores)
    python benchmarks/regenerate.py --quick             # all but the long ones (races, compile, MuJoCo...)
    python benchmarks/regenerate.py --only memory,stability

The GPU results under ``docs/gpu_h100/`` and ``docs/gpu_h200/`` need a GPU machine: the first were
made there by hand with the commands of docs/performance.md ("On a GPU"), the second by
``benchmarks/gpu.sh``. The ``jax_md`` column of the throughput table needs
``pip install -e ".[peers]"`` (Python 3.12: jax-md excludes jax 0.10.2); without it the column is
left out. The ``jax_md_rigid`` job needs ``.[jax_md]`` (Python 3.12); without it, it says so and
leaves its file as it was: run it with ``--only jax_md_rigid --python <py312 venv>/bin/python``. The
``mujoco_free_body`` job needs ``pip install -e ".[mujoco]"``. Run from the
repository root with a clean checkout: a results file made from uncommitted package or benchmark
code carries ``+dirty`` in its commit.
"""

import argparse
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import NamedTuple


ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"


class Job(NamedTuple):
    files: tuple[str, ...]  # under docs/
    argv: tuple[str, ...]  # after the interpreter
    minutes: float  # on this project's 2-core CPU
    long: bool = False
    # (file in the job's scratch folder ``{tmp}``, file under docs/) copied once the job has run
    copies: tuple[tuple[str, str], ...] = ()


JOBS = {
    "compare": Job(
        ("compare_heavy_top.json", "compare_heavy_top.png"),
        ("-m", "jaxrot", "compare", "--out", "{tmp}"),
        4,
        True,
        (("compare.json", "compare_heavy_top.json"), ("compare.png", "compare_heavy_top.png")),
    ),
    "race64": Job(
        ("race_cpu/race_float64.json",),
        ("benchmarks/race.py", "--repeats", "3", "--time-cap", "1.0", "--out", "docs/race_cpu"),
        31,
        True,
    ),
    # Draws only: the headline figure of README and the home page, from race64's results.
    "headline": Job(("headline.png",), ("benchmarks/headline.py",), 0.1),
    "race32": Job(
        ("race_cpu/race_float32.json",),
        (
            "benchmarks/race.py",
            "--dtype",
            "float32",
            "--repeats",
            "3",
            "--time-cap",
            "1.0",
            "--out",
            "docs/race_cpu",
        ),
        12,
        True,
    ),
    "compile": Job(("compile_cpu.json",), ("benchmarks/compile.py",), 8, True),
    "throughput": Job(
        ("throughput_cpu.json",),
        (
            "benchmarks/throughput.py",
            "--n",
            "1000,10000,100000,1000000",
            "--json",
            "docs/throughput_cpu.json",
        ),
        12,
    ),
    # jax 0.10.2 (the default install of Python 3.11) beside the newest jax of the throughput job.
    "throughput_jax010": Job(
        ("throughput_cpu_jax010.json",),
        (
            "benchmarks/throughput.py",
            "--n",
            "1000,10000,100000,1000000",
            "--dtype",
            "float32,float64",
            "--no-peer",
            "--json",
            "docs/throughput_cpu_jax010.json",
        ),  # fmt: skip
        9,
    ),
    # The same with XLA's default options instead of jaxrot.compiler_options(): the YNN trap.
    "throughput_jax010_xla_defaults": Job(
        ("throughput_cpu_jax010_xla_defaults.json",),
        (
            "benchmarks/throughput.py",
            "--n",
            "1000,10000,100000",
            "--dtype",
            "float64",
            "--schemes",
            "zhao,rozmanov,no_squish",
            "--no-peer",
            "--xla-defaults",
            "--json",
            "docs/throughput_cpu_jax010_xla_defaults.json",
        ),  # fmt: skip
        1.5,
    ),
    "memory": Job(("memory_cpu.json",), ("benchmarks/memory.py", "--json", "docs/memory_cpu.json"), 5),
    "stability": Job(
        ("stability_cpu.json",), ("benchmarks/stability.py", "--json", "docs/stability_cpu.json"), 5
    ),
    # Accuracy only: the fourth-order Lie-group methods (MuJoCo's row needs `pip install mujoco`).
    "order4": Job(("order4.json",), ("benchmarks/order4.py", "--json", "docs/order4.json"), 9),
    # Accuracy only: each scheme's float32 run against its float64 run (docs/stability.md).
    "float32": Job(
        ("float32_horizon.json",), ("benchmarks/float32.py", "--json", "docs/float32_horizon.json"), 12
    ),
    "identify_speed": Job(
        ("identify_speed_cpu.json",),
        ("benchmarks/identify_speed.py", "--json", "docs/identify_speed_cpu.json"),
        8,
        quick=("benchmarks/identify_speed.py", "--quick", "--json", "docs/identify_speed_cpu.json"),
        sources=(
            "benchmarks/identify_speed.py",
            "tests/_telemetry.py",
            "tests/_mujoco_telemetry.py",
            "tests/_mujoco_sysid.py",
            "jaxrot/_fit",
            "jaxrot/schemes",
            "jaxrot/_integrate",
        ),
    ),
    # MuJoCo 4.0 against jaxrot on the free body (needs `pip install -e ".[mujoco]"`; without it the
    # benchmark says so and writes nothing).
    "mujoco_free_body": Job(
        ("mujoco_free_body_cpu.json", "mujoco_free_body_cpu.png"),
        (
            "benchmarks/mujoco_free_body.py",
            "--json",
            "docs/mujoco_free_body_cpu.json",
            "--png",
            "docs/mujoco_free_body_cpu.png",
        ),
        40,
        True,
    ),
    # Accuracy only (weak orders of the thermal schemes): no timing, any machine; long on 2 cores.
    "thermal_orders": Job(
        ("thermal_orders.json",), ("benchmarks/thermal_orders.py", "--bodies", "20000"), 15, True
    ),
    # Biases against dt and, timed, the cost per body-step against jax_md (Python 3.12) and diffrax.
    "thermal_peers": Job(("thermal_peers.json",), ("benchmarks/thermal_peers.py", "--timing"), 25, True),
    # jaxrot.jax_md against jax_md's rigid-body nvt_langevin / nve: temperature per axis against dt, energy
    # error, cost per body-step (Python 3.12 with jax_md: --python <venv312>/bin/python).
    "jax_md_rigid": Job(("jax_md_cpu.json", "jax_md_cpu.png"), ("benchmarks/jax_md_rigid.py",), 20, True),
    "rotor_choice": Job(
        ("rotor_choice_cpu.json",),
        ("benchmarks/rotor.py", "--choice-only", "--rounds", "61", "--json", "docs/rotor_choice_cpu.json"),
        1.5,
    ),
    # Bodies in a fluid (docs/fluid.md): the orders (accuracy only) and the race against diffrax.
    "fluid_orders": Job(("fluid_orders.json",), ("benchmarks/fluid_orders.py",), 12),
    "fluid_layer": Job(("fluid_layer.json",), ("benchmarks/fluid_layer.py",), 8),
    "overdamped_cost": Job(
        ("overdamped_cost_cpu.json",),
        ("benchmarks/overdamped_cost.py", "--json", "docs/overdamped_cost_cpu.json"),
        2,
    ),
    "fluid_race": Job(("fluid_race_cpu.json", "fluid_race_cpu.png"), ("benchmarks/fluid_race.py",), 60, True),
}


def run_job(name, job, python):
    """Run one job; ``{tmp}`` in its argv is a scratch folder whose outputs are copied to ``docs/``."""
    with tempfile.TemporaryDirectory() as tmp:
        argv = [python, *(a.replace("{tmp}", tmp) for a in job.argv)]
        print(f"== {name}: {' '.join(argv)}", flush=True)
        start = time.perf_counter()
        subprocess.run(argv, cwd=ROOT, check=True)
        for source, target in job.copies:
            shutil.copy(Path(tmp) / source, DOCS / target)
        print(
            f"== {name}: {(time.perf_counter() - start) / 60:.1f} min; wrote {', '.join(job.files)}",
            flush=True,
        )


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", default=None, help=f"comma-separated jobs of {list(JOBS)}")
    parser.add_argument("--quick", action="store_true", help="skip the long jobs")
    parser.add_argument("--list", action="store_true", help="list the jobs and exit")
    parser.add_argument("--python", default=sys.executable, help="interpreter for the benchmarks")
    opts = parser.parse_args(argv)
    if opts.list:
        for name, job in JOBS.items():
            files = ", ".join(f"docs/{f}" for f in job.files)
            print(f"{name:15s} ~{job.minutes:>3.0f} min {'long' if job.long else '':5s} {files}")
        return 0
    chosen = (
        opts.only.split(",") if opts.only else [n for n, j in JOBS.items() if not (opts.quick and j.long)]
    )
    unknown = [n for n in chosen if n not in JOBS]
    if unknown:
        parser.error(f"unknown jobs {unknown}; known: {list(JOBS)}")
    for name in chosen:
        run_job(name, JOBS[name], opts.python)
    return 0


if __name__ == "__main__":
    sys.exit(main())
