"""The committed results files that the docs' tables are rendered from: provenance and coverage.

A results file is current when its ``machine`` block carries the schema of
`jaxrot.comparison.machine_info` (machine, versions, commit, date) and its rows cover every
scheme in `jaxrot.SCHEMES`. Files that predate this are listed in `STALE` with what they lack
and are expected to fail (strict): regenerating one makes its test pass, and the strict mark
then fails until the entry is removed, so the list cannot go stale silently.
"""

import csv
import json
from pathlib import Path

import pytest

import jaxrot
from jaxrot.comparison import RESULTS_SCHEMA


DOCS = Path(__file__).resolve().parents[1] / "docs"

# file -> (how its rows name the method, what regenerates it)
RESULTS = {
    "compile_cpu.json": ("method", "python benchmarks/compile.py"),
    "throughput_cpu.json": ("method", "python benchmarks/throughput.py"),
    "memory_cpu.json": ("scheme", "python benchmarks/memory.py"),
    "compare_heavy_top.json": (
        "method",
        "python -m jaxrot compare --out DIR "
        "(then DIR/compare.json and compare.png to docs/compare_heavy_top.*)",
    ),
    "gpu_h100/race_heavy_top_float64.json": ("method", "python benchmarks/race.py (on the GPU)"),
    "gpu_h100/tp_f32_1000000.json": ("method", "python benchmarks/throughput.py (on the GPU)"),
}
# Measured before the provenance schema and before the high-order schemes (CPU) existed.
STALE = {
    "throughput_cpu.json": "no commit/date; no rkmk*, srkn*, splitting rows",
    "memory_cpu.json": "a bare list: no machine block; zhao and no_squish only",
    "gpu_h100/race_heavy_top_float64.json": "schema 1: no commit/date (GPU lent once; every scheme covered)",
    "gpu_h100/tp_f32_1000000.json": "schema 1: no commit/date (GPU lent once; every scheme covered)",
}


def _load(name):
    path = DOCS / name
    if path.suffix == ".csv":
        with open(path, newline="") as f:
            return {"rows": list(csv.DictReader(f))}
    data = json.loads(path.read_text())
    if isinstance(data, list):
        return {"rows": data}
    if "scenes" in data:  # the race: rows per scene
        data = {**data, "rows": [r for scene in data["scenes"].values() for r in scene["rows"]]}
    return data


@pytest.mark.parametrize(
    "name",
    [
        pytest.param(n, marks=pytest.mark.xfail(strict=True, reason=STALE[n])) if n in STALE else n
        for n in RESULTS
    ],
)
def test_results_file_has_provenance_and_covers_every_scheme(name):
    key, command = RESULTS[name]
    data = _load(name)
    machine = data.get("machine", {})
    assert machine.get("schema") == RESULTS_SCHEMA, (
        f"{name}: schema {machine.get('schema')}; rerun `{command}`"
    )
    for field in ("date", "commit", "python", "jax", "cpus", "device"):
        assert machine.get(field), f"{name}: no {field!r} in its machine block; rerun `{command}`"
    missing = set(jaxrot.SCHEMES) - {row[key] for row in data["rows"]}
    assert not missing, f"{name}: no rows for {sorted(missing)}; rerun `{command}`"


def test_every_results_file_the_docs_render_is_checked():
    """A new results file under docs/ gets an entry in `RESULTS` (or this fails)."""
    rendered = {
        str(p.relative_to(DOCS))
        for p in [*DOCS.glob("*.json"), *DOCS.glob("*.csv"), *DOCS.glob("gpu_h100/*.json")]
    }
    unchecked = rendered - set(RESULTS)
    # The GPU throughput files besides the one checked are the same run at other settings.
    unchecked = {n for n in unchecked if not n.startswith("gpu_h100/tp_")}
    assert not unchecked, f"results files without a provenance check: {sorted(unchecked)}"
