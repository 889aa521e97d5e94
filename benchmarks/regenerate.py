"""Rerun the benchmarks behind every published number: each writes the results file its docs page renders.

Every table and figure of README.md and the documentation site is rendered (by
``docs/_hooks/tables.py``) from a results file under ``docs/``, and each results file records
the machine, the versions, the commit and the date it was measured on
(`jaxrot.comparison.machine_info`), and, once written through this script, a fingerprint of every
source file its numbers depend on (``machine["sources"]``: the job's ``sources``) and what the rest of
the machine computed meanwhile (``machine["load"]``). This script reruns the benchmarks that write them,
one after another in fresh processes, printing its plan with each job's expected time first.

    python benchmarks/regenerate.py --list              # the jobs, their files, full and quick times
    python benchmarks/regenerate.py --stale             # the results whose measured code has changed
    python benchmarks/regenerate.py --only memory,stability
    python benchmarks/regenerate.py --only fluid_race --quick   # within 10 min, into quick/, not docs/
    python benchmarks/regenerate.py --peers-python <py312 venv>/bin/python   # all of them (~90 min)

``--stale`` prints nothing and exits 0 when every result measures the code as it is now; otherwise it
names each stale job, the command that reruns it and the files that changed, and exits 1.

A timed result is only written when the machine was quiet: a job during which the rest of the machine
used more than ``_harness.QUIET_OTHER_CORES`` cores on average leaves its files as they were and the
script exits 1 (``--allow-load`` writes them, marked ``"allowed": true`` in their load block). Jobs
marked ``timed=False`` (accuracy only) are written either way, with their load recorded.

The GPU results under ``docs/gpu_h100/`` and ``docs/gpu_h200/`` need a GPU machine: the first were
made there by hand with the commands of docs/performance.md ("On a GPU"), the second by
``benchmarks/gpu.sh``; they are not jobs here. The ``jax_md`` column of the throughput table needs
``pip install -e ".[peers]"`` (Python 3.12: jax-md excludes jax 0.10.2). The jobs marked ``peers``
(throughput, thermal_peers, jax_md_rigid, jax_md_brownian) run under ``--peers-python`` (default: the
environment's ``JAXROT_PEERS_PYTHON``, else ``--python``), with this checkout on ``PYTHONPATH`` so that
interpreter needs no jaxrot install; where it cannot import jax_md the job says so, leaves its files as
they were and the script exits 1. The
``mujoco_free_body`` job needs ``pip install -e ".[mujoco]"``, the ``mjx`` job ``pip install -e ".[mjx]"``
(without it, it says so and leaves its file as it was). Run from the
repository root with a clean checkout: a results file made from uncommitted package or benchmark
code carries ``+dirty`` in its commit (its source hashes still say what it measured).
"""

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import _harness
from _jobs import JOBS, Job  # noqa: F401  (Job: for tests and callers)


ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"


def _minutes(job, quick):
    return job.quick_minutes if quick and job.quick else job.minutes


def print_plan(chosen, quick):
    """The jobs about to run, each with its mode and expected time, and the total."""
    total = sum(_minutes(JOBS[n], quick) for n in chosen)
    print(f"== plan: {len(chosen)} job(s), about {total:.0f} min on 2 quiet cores", flush=True)
    for name in chosen:
        job = JOBS[name]
        mode = "quick" if quick and job.quick else "full"
        target = "quick/" if mode == "quick" else ", ".join(f"docs/{f}" for f in job.files)
        print(f"   {name:31s} {mode:5s} ~{_minutes(job, quick):>4.1f} min -> {target}", flush=True)


def run_job(name, job, python, *, quick=False, allow_load=False):
    """Run one job and return whether its results stand.

    ``{tmp}`` in its argv is a scratch folder: its outputs are copied to ``docs/`` (or, in quick mode,
    to ``quick/NAME/``, never to docs/). A timed job's files are restored to what they were when the
    rest of the machine computed during the run, unless ``allow_load``; the files it writes record
    their sources and the load either way.
    """
    quick = quick and job.quick is not None
    targets = [DOCS / f for f in job.files]
    before = {t: t.read_bytes() if t.exists() else None for t in targets}
    with tempfile.TemporaryDirectory() as tmp:
        argv = [python, *(a.replace("{tmp}", tmp) for a in (job.quick if quick else job.argv))]
        print(f"== {name}{' (quick)' if quick else ''}: {' '.join(argv)}", flush=True)
        with _harness.LoadWatch() as watch:
            done = subprocess.run(argv, cwd=ROOT, env=_checkout_env())
        load = watch.record
        if done.returncode != 0:
            _restore(before)
            print(f"== {name}: FAILED (exit {done.returncode}); its files left as they were", flush=True)
            return False
        if quick:
            out = ROOT / "quick" / name
            shutil.rmtree(out, ignore_errors=True)
            shutil.copytree(tmp, out)
            # Laid out as under docs/, so that the docs' tables render from it.
            for f in job.files:
                if (out / Path(f).name).exists() and Path(f).name != f:
                    (out / f).parent.mkdir(parents=True, exist_ok=True)
                    shutil.copy(out / Path(f).name, out / f)
            for path in out.rglob("*.json"):
                _harness.annotate(path, job.sources, load)
            print(f"== {name} (quick): {load['seconds'] / 60:.1f} min; its files in {out}", flush=True)
            compare_tables(job, out)
            return True
        for source, target in job.copies:
            shutil.copy(Path(tmp) / source, DOCS / target)
    busy = job.timed and load["quiet"] is False
    if busy and not allow_load:
        _restore(before)
        print(
            f"== {name}: NOT WRITTEN: the rest of the machine used {load['other_cores']} cores on average "
            f"during this timed run (quiet: <= {_harness.QUIET_OTHER_CORES}; load average "
            f"{load['loadavg_before'][0]} before, {load['loadavg_after'][0]} after). Rerun on quiet cores, "
            "or pass --allow-load to write it marked as measured under load.",
            flush=True,
        )
        return False
    for target in targets:
        if target.suffix == ".json":
            _harness.annotate(target, job.sources, {**load, "allowed": busy})
    print(
        f"== {name}: {load['seconds'] / 60:.1f} min, others {load['other_cores']} cores"
        f"{' (UNDER LOAD, allowed)' if busy else ''}; wrote {', '.join(job.files)}",
        flush=True,
    )
    return True


def _restore(before):
    """Put each results file back as it was before a job that did not stand (or remove a new one)."""
    for target, content in before.items():
        if content is None:
            target.unlink(missing_ok=True)
        else:
            target.write_bytes(content)


def _checkout_env():
    """The environment with this checkout first on PYTHONPATH: an interpreter without jaxrot installed
    (the peers' Python 3.12) measures this checkout's code, like the default one's editable install."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), env.get("PYTHONPATH")) if p)
    return env


def interpreter(job, python, peers_python):
    """The interpreter a job runs under: ``python``, or for a job marked peers ``peers_python`` where it
    imports jax_md (``None`` where it does not: the caller skips the job, saying so)."""
    if not job.peers:
        return python
    probe = subprocess.run([peers_python, "-c", "import jax_md"], capture_output=True, env=_checkout_env())
    if probe.returncode != 0:
        return None
    return peers_python


def compare_tables(job, quick_docs):
    """Print each headline table of ``job`` as published (docs/) and as its quick run gives it."""
    if not job.tables:
        return
    import importlib.util

    spec = importlib.util.spec_from_file_location("_docs_tables", DOCS / "_hooks" / "tables.py")
    hooks = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(hooks)
    for table in job.tables:
        for label, docs in (("published", DOCS), ("quick", quick_docs)):
            try:
                text = hooks.TABLES[table](docs)
            except (OSError, KeyError, ValueError) as error:  # the quick form wrote no such file
                text = f"(not rendered: {type(error).__name__}: {error})"
            print(f"-- {table}, {label}:\n{text}\n", flush=True)


def stale_jobs(names=None):
    """``{job: [reasons]}`` for the jobs whose results files measure code that has changed since."""
    stale = {}
    for name in names or JOBS:
        job = JOBS[name]
        for f in job.files:
            path = DOCS / f
            if path.suffix != ".json" or not path.exists():
                continue
            machine = json.loads(path.read_text()).get("machine")
            if not isinstance(machine, dict):
                continue
            reasons = _harness.stale_sources(machine, job.sources)
            if reasons:
                stale.setdefault(name, []).extend(f"docs/{f}: {r}" for r in reasons)
    return stale


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", default=None, help=f"comma-separated jobs of {list(JOBS)}")
    parser.add_argument(
        "--quick", action="store_true", help="each job in its quick form where it has one (into quick/)"
    )
    parser.add_argument("--list", action="store_true", help="list the jobs and exit")
    parser.add_argument(
        "--stale", action="store_true", help="list the results whose measured code changed; exit 1 if any"
    )
    parser.add_argument(
        "--allow-load", action="store_true", help="write timed results measured beside other computation"
    )
    parser.add_argument("--python", default=sys.executable, help="interpreter for the benchmarks")
    parser.add_argument(
        "--peers-python",
        default=os.environ.get("JAXROT_PEERS_PYTHON"),
        help="interpreter with jax_md and the newest jax (Python 3.12) for the jobs marked peers",
    )
    opts = parser.parse_args(argv)
    if opts.list:
        for name, job in JOBS.items():
            files = ", ".join(f"docs/{f}" for f in job.files)
            quick = f"quick ~{job.quick_minutes:>2.0f}" if job.quick else " " * 8
            print(f"{name:31s} ~{job.minutes:>3.0f} min {quick} {'timed' if job.timed else '     '} {files}")
        return 0
    chosen = opts.only.split(",") if opts.only else list(JOBS)
    unknown = [n for n in chosen if n not in JOBS]
    if unknown:
        parser.error(f"unknown jobs {unknown}; known: {list(JOBS)}")
    if opts.stale:
        stale = stale_jobs(chosen)
        for name, reasons in stale.items():
            print(f"{name}: python benchmarks/regenerate.py --only {name}")
            for reason in reasons:
                print(f"    {reason}")
        return 1 if stale else 0
    print_plan(chosen, opts.quick)
    refused, started = [], time.monotonic()
    for name in chosen:
        job = JOBS[name]
        python = interpreter(job, opts.python, opts.peers_python or opts.python)
        if python is None:
            print(
                f"== {name}: SKIPPED: needs jax_md (Python 3.12 with the newest jax): pass --peers-python "
                "<py312 venv>/bin/python or set JAXROT_PEERS_PYTHON; its files left as they were",
                flush=True,
            )
            refused.append(name)
        elif not run_job(name, job, python, quick=opts.quick, allow_load=opts.allow_load):
            refused.append(name)
    print(f"== {len(chosen)} job(s) in {(time.monotonic() - started) / 60:.1f} min", flush=True)
    if refused:
        print(f"== not written (failed, skipped or the machine was busy): {', '.join(refused)}", flush=True)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
