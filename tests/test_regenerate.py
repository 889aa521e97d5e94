"""The benchmarks' harness (benchmarks/regenerate.py, benchmarks/_harness.py): stale results, the load
guard, the plan. Everything here runs in a scratch folder standing for docs/; nothing is timed."""

import json
import subprocess
import sys
import time
from pathlib import Path

import pytest


sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

import _harness  # noqa: E402
import regenerate  # noqa: E402


def test_fingerprint_ignores_docstrings_comments_and_layout_but_not_code():
    code = 'def f(x):\n    """Twice x."""\n    return 2 * x\n'
    same = "def f(x):  # why: a comment\n\n    return 2*x\n"
    other = 'def f(x):\n    """Twice x."""\n    return 3 * x\n'
    assert _harness.fingerprint("m.py", code) == _harness.fingerprint("m.py", same)
    assert _harness.fingerprint("m.py", code) != _harness.fingerprint("m.py", other)
    # Other files are hashed as they are.
    assert _harness.fingerprint("a.json", "{}") != _harness.fingerprint("a.json", "{ }")


def test_every_job_names_existing_sources_and_quick_forms_write_to_scratch():
    for name, job in regenerate.JOBS.items():
        if job.files[0].endswith(".json"):
            assert job.sources, f"{name}: no sources, so --stale could never call it stale"
        files = _harness.source_files(job.sources)
        missing = [s for s in job.sources if not any(f == s or f.startswith(s + "/") for f in files)]
        assert not missing, f"{name}: sources {missing} do not exist"
        if job.quick is not None:
            assert job.quick_minutes is not None and job.quick_minutes <= 10, name
            assert not any("docs/" in a for a in job.quick), f"{name}: its quick form writes to docs/"
        if job.minutes > 10:
            assert job.quick is not None, f"{name}: over 10 minutes without a quick form"
        unknown = set(job.tables) - set(_docs_tables().TABLES)
        assert not unknown, f"{name}: no docs tables {unknown}"


def _docs_tables():
    import importlib.util

    spec = importlib.util.spec_from_file_location("_docs_tables", regenerate.DOCS / "_hooks" / "tables.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_a_quick_run_prints_its_headline_tables_beside_the_published_ones(tmp_path, capsys):
    job = regenerate.JOBS["fluid_race"]
    regenerate.compare_tables(job, tmp_path)  # an empty quick folder: the quick side is not rendered
    out = capsys.readouterr().out
    assert "-- fluid_race_table, published:\n|" in out
    assert "-- fluid_race_table, quick:\n*Not measured yet" in out


def test_stale_sources_names_the_changed_file():
    sources = ("benchmarks/_harness.py", "benchmarks/regenerate.py")
    machine = {"sources": _harness.source_hashes(sources)}
    assert _harness.stale_sources(machine, sources) == []
    machine["sources"]["benchmarks/_harness.py"] = "0" * 16
    (reason,) = _harness.stale_sources(machine, sources)
    assert "benchmarks/_harness.py" in reason and "regenerate.py" not in reason
    # A file written before fingerprints were recorded is judged by its commit; one from
    # uncommitted code cannot be judged, and says so.
    assert "uncommitted" in _harness.stale_sources({"commit": "0123abcd+dirty"}, sources)[0]
    assert "not in this repository" in _harness.stale_sources({"commit": "0" * 12}, sources)[0]


class _Watch:
    """A LoadWatch that reports a given verdict (the real one is tested below)."""

    quiet = True

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.record = {
            "loadavg_before": [0.0] * 3,
            "loadavg_after": [0.0] * 3,
            "job_cores": 1.0,
            "other_cores": 0.0 if self.quiet else 1.0,
            "seconds": 0.1,
            "quiet": self.quiet,
        }
        return False


@pytest.fixture
def scratch_docs(tmp_path, monkeypatch):
    monkeypatch.setattr(regenerate, "DOCS", tmp_path)
    (tmp_path / "r.json").write_text(json.dumps({"machine": {"commit": "old"}, "rows": [1]}, indent=1))
    writer = f"import json, pathlib; pathlib.Path({str(tmp_path / 'r.json')!r}).write_text(json.dumps("
    writer += "{'machine': {'commit': 'new'}, 'rows': [2]}, indent=1))"
    return regenerate.Job(("r.json",), ("-c", writer), 0.01, sources=("benchmarks/_harness.py",))


@pytest.mark.parametrize("timed", [True, False])
def test_a_busy_machine_leaves_timed_results_as_they_were(scratch_docs, monkeypatch, timed, capsys):
    job = scratch_docs._replace(timed=timed)
    monkeypatch.setattr(_Watch, "quiet", False)
    monkeypatch.setattr(_harness, "LoadWatch", _Watch)
    written = regenerate.run_job("r", job, sys.executable)
    data = json.loads((regenerate.DOCS / "r.json").read_text())
    if timed:
        assert not written and data["rows"] == [1] and "NOT WRITTEN" in capsys.readouterr().out
    else:  # accuracy only: written, with its load recorded
        assert written and data["rows"] == [2] and data["machine"]["load"]["quiet"] is False
    # --allow-load writes it, marked.
    assert regenerate.run_job("r", job, sys.executable, allow_load=True)
    data = json.loads((regenerate.DOCS / "r.json").read_text())
    assert data["rows"] == [2] and data["machine"]["load"]["allowed"] is timed
    assert data["machine"]["sources"] == _harness.source_hashes(job.sources)


def test_a_quiet_run_is_written_with_its_sources_and_is_then_current(scratch_docs, monkeypatch):
    monkeypatch.setattr(_harness, "LoadWatch", _Watch)
    monkeypatch.setitem(regenerate.JOBS, "r", scratch_docs)
    assert regenerate.run_job("r", scratch_docs, sys.executable)
    machine = json.loads((regenerate.DOCS / "r.json").read_text())["machine"]
    assert machine["load"]["quiet"] is True and machine["load"]["allowed"] is False
    assert regenerate.stale_jobs(["r"]) == {}


def test_load_watch_sees_another_process_compute():
    """A busy loop outside the job shows as other cores; the job's own sleep does not."""
    busy = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        time.sleep(0.2)  # it has started
        with _harness.LoadWatch() as watch:
            subprocess.run([sys.executable, "-c", "import time; time.sleep(0.6)"], check=True)
    finally:
        busy.kill()
        busy.wait()
    record = watch.record
    # The loop holds a core unless the machine is oversubscribed three times over: >= 1/3 of one.
    assert record["other_cores"] >= 0.33 and record["quiet"] is False, record
    assert record["job_cores"] < 0.33, record  # a sleeping job (and the interpreter's start)


def test_plan_lists_each_job_with_its_time(capsys):
    regenerate.print_plan(["fluid_race", "memory"], quick=True)
    out = capsys.readouterr().out
    assert "2 job(s)" in out and "fluid_race" in out and "quick" in out and "memory" in out


@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_the_race_jobs_sizing_replayed_on_the_published_race_gives_its_cells(dtype, capsys):
    """race64/race32's caps (_jobs.RACE) and race.finalists, replayed on the published race file with its
    own first-pass and re-timed seconds, pick the same row and ratio in every cell (issue 76: the
    jobs were cut from 31.8 and 13.1 quiet minutes to about 9.5 and 4.5 on this evidence)."""
    import race_replay
    from _jobs import RACE

    data = json.loads((Path(regenerate.DOCS) / "race_cpu" / f"race_{dtype}.json").read_text())
    caps = {flag: float(RACE[RACE.index(flag) + 1]) for flag in ("--time-cap", "--adaptive-cap")}
    _, changed = race_replay.replay(data, dtype, caps["--time-cap"], caps["--adaptive-cap"])
    assert changed == 0, capsys.readouterr().out


def test_a_failed_job_leaves_its_files_and_the_run_goes_on(scratch_docs, monkeypatch, capsys):
    """One job that raises costs the whole run nothing but its own files: the next job still runs."""
    monkeypatch.setattr(_harness, "LoadWatch", _Watch)
    failing = scratch_docs._replace(argv=("-c", "raise SystemExit(3)"))
    monkeypatch.setattr(regenerate, "JOBS", {"bad": failing, "good": scratch_docs})
    assert regenerate.main([]) == 1
    out = capsys.readouterr().out
    assert "bad: FAILED (exit 3)" in out and "not written" in out and "bad" in out.splitlines()[-1]
    assert json.loads((regenerate.DOCS / "r.json").read_text())["rows"] == [2]  # good ran after it


def test_a_peers_job_without_jax_md_is_skipped_saying_how(scratch_docs, monkeypatch, capsys):
    """A job marked peers runs under --peers-python; an interpreter without jax_md leaves its files."""
    monkeypatch.setattr(_harness, "LoadWatch", _Watch)
    monkeypatch.setattr(regenerate, "JOBS", {"p": scratch_docs._replace(peers=True)})
    # The current interpreter, with an import of jax_md made to fail, stands for Python 3.11's.
    monkeypatch.setenv("PYTHONPATH", str(_no_jax_md(regenerate.DOCS)))
    assert regenerate.main(["--peers-python", sys.executable]) == 1
    assert "p: SKIPPED: needs jax_md" in capsys.readouterr().out
    assert json.loads((regenerate.DOCS / "r.json").read_text())["rows"] == [1]
    assert regenerate.interpreter(regenerate.JOBS["p"]._replace(peers=False), "py", "peers") == "py"


def _no_jax_md(folder):
    """A folder whose jax_md package raises ImportError, to put first on PYTHONPATH."""
    package = folder / "shadow" / "jax_md"
    package.mkdir(parents=True)
    (package / "__init__.py").write_text("raise ImportError('no jax_md here')\n")
    return package.parent


def test_every_cpu_results_file_is_a_jobs_measured_from_a_commit_with_its_load():
    """Each results file under docs/ (the GPU folders aside: no GPU here) is written by a job of
    regenerate.py, from a committed tree (no ``+dirty``), with the load it was measured under and, for
    a timed job, quiet cores or the ``allowed`` mark (issue 76: every CPU number reproducible)."""
    docs = Path(regenerate.DOCS)
    owner = {f: name for name, job in regenerate.JOBS.items() for f in job.files}
    for path in sorted(docs.glob("*.json")) + sorted(docs.glob("race_cpu/*.json")):
        name = str(path.relative_to(docs))
        assert name in owner, f"docs/{name} is no job's file: add a job to benchmarks/_jobs_*.py"
        machine = json.loads(path.read_text())["machine"]
        assert "+dirty" not in machine["commit"], f"docs/{name} was measured from an uncommitted tree"
        load = machine.get("load")
        assert load is not None, f"docs/{name} has no load record: rerun it through regenerate.py"
        assert not regenerate.JOBS[owner[name]].timed or load["quiet"] or load["allowed"], name
