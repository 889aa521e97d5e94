"""The identification page's comparison with `mujoco.sysid` (docs/identification.md): its tables render
from docs/identify_speed_cpu.json, with and without the real-sensor rows, its prose says what the file
says, and each cell of the table of what each tool can express is code that exists and runs.

The real-sensor rows (``"mujoco_sensors"``) came after the file's last quiet run: until it is rerun
(``python benchmarks/regenerate.py --only identify_speed``) the page says so, and the checks of those
rows run on a copy of the file given rows of the same shape (`_with_sensor_rows`).
"""

import copy
import importlib.util
import inspect
import json
import re
from pathlib import Path

import pytest

import jaxrot
from jaxrot._fit._identify._sensors import SENSORS


ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
PAGE = DOCS / "identification.md"
RESULTS = "identify_speed_cpu.json"


def _tables():
    spec = importlib.util.spec_from_file_location("_docs_tables", DOCS / "_hooks" / "tables.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


TABLES = _tables().TABLES
CAPS = importlib.util.module_from_spec(
    spec := importlib.util.spec_from_file_location("_caps", ROOT / "benchmarks" / "_identify_capabilities.py")
)
spec.loader.exec_module(CAPS)


def _with_sensor_rows(tmp_path, data):
    """A docs folder whose results file is ``data`` with real-sensor rows shaped as the benchmark writes
    them (`benchmarks/identify_mujoco.py`), where it has none: numbers made up, structure real."""
    data = copy.deepcopy(data)
    if "mujoco_sensors" not in data:
        row = {
            "median_s": 1.5,
            "first_call_s": 14.0,
            "relative_error": 3.1e-5,
            "coverage95": 0.92,
            "seeds": 4,
        }
        data["mujoco_sensors"] = [
            {**row, "fit": "jaxrot.identify, fitting …", "fitted": sorted(SENSORS), "left_out": []},
            {**row, "fit": "mujoco.sysid, fitting …", "median_s": 40.0, "first_call_s": None,
             "fitted": sorted(SENSORS), "left_out": []},
        ]  # fmt: skip
        data["capabilities"] = [list(map(copy.deepcopy, row)) for row in CAPS.CAPABILITIES]
    (tmp_path / RESULTS).write_text(json.dumps(data))
    return tmp_path


def _files():
    """The committed results file, and a quick run's where one was made (regenerate.py --quick)."""
    files = [DOCS / RESULTS]
    files += sorted(ROOT.glob(f"quick/**/{RESULTS}"))
    return files


@pytest.mark.parametrize("path", _files(), ids=lambda p: str(p.relative_to(ROOT)))
def test_sysid_tables_render_the_results_file(path, tmp_path):
    data = json.loads(path.read_text())
    docs = path.parent
    ideal = TABLES["identify_sysid_table"](docs)
    if data.get("mujoco"):
        assert len(ideal.split("\n\n")[0].splitlines()) == 2 + len(data["mujoco"])
    sensors = TABLES["identify_sysid_sensors_table"](docs)
    if not data.get("mujoco_sensors"):
        # The file predates the rows: the page says so and names the rerun; the rows' checks below run
        # on a copy given rows of the benchmark's shape.
        assert "regenerate.py --only identify_speed" in sensors and "|" not in sensors
        docs = _with_sensor_rows(tmp_path, data)
        data = json.loads((docs / RESULTS).read_text())
        sensors = TABLES["identify_sysid_sensors_table"](docs)
    rows = data["mujoco_sensors"]
    table, summary = sensors.split("\n\n")[:2]
    assert len(table.splitlines()) == 2 + len(rows)
    for row, line in zip(rows, table.splitlines()[2:], strict=True):
        assert line.startswith(f"| {row['fit']} | {row['median_s']:.2f} |")
        assert line.endswith(" | none |") == (not row["left_out"])
    ratio = rows[1]["median_s"] / rows[0]["median_s"]
    assert f"`jaxrot.identify` {ratio:.0f}× as fast" in summary
    if data.get("mujoco"):
        assert f"{rows[0]['median_s'] / data['mujoco'][0]['median_s']:.2f}× its time" in summary


def test_prose_about_the_real_sensor_rows_matches_the_file(tmp_path):
    """docs/identification.md says both tools fit the same five flaws and sysid leaves none out; the
    file's rows must say the same (the committed file, or rows of its shape until the rerun)."""
    page = PAGE.read_text()
    for name in ("identify_sysid_table", "identify_sysid_sensors_table", "identify_capabilities_table"):
        assert f"{{{{ {name} }}}}" in page
    from types import SimpleNamespace

    page_ref = SimpleNamespace(file=SimpleNamespace(src_path="identification.md"))
    rendered = _tables().on_page_markdown(page, page_ref, {"docs_dir": str(DOCS)}, None)
    assert "{{ identify" not in rendered and "| `jaxrot.identify` | `mujoco.sysid` |" in rendered
    prose = " ".join(page.split())
    assert "both tools fit the inertia, every initial state and all five flaws" in prose
    data = json.loads((DOCS / RESULTS).read_text())
    if not data.get("mujoco_sensors"):
        data = json.loads((_with_sensor_rows(tmp_path, data) / RESULTS).read_text())
    ours, theirs = data["mujoco_sensors"]
    assert sorted(ours["fitted"]) == sorted(theirs["fitted"]) == sorted(SENSORS)
    assert ours["left_out"] == theirs["left_out"] == []
    if "capabilities" in data:  # the file's copy is the module's (written by the same run)
        assert data["capabilities"] == [list(row) for row in CAPS.CAPABILITIES]
    # Every sensor's sysid cell names an API (none is a "no"), as the prose's "every flaw" says.
    flaws = {row[0]: row[2] for row in CAPS.CAPABILITIES}
    for what in ("gyro bias, one per manoeuvre", "gyro scale factor", "sensor delay",
                 "tracker mounted at a rotation of the body"):  # fmt: skip
        assert flaws[what]["api"], what


def _resolve_jaxrot(api):
    kind, _, name = api.partition(":")
    if kind == "sensors":
        return name in SENSORS
    if kind in ("identify", "Experiment"):
        return name in inspect.signature(getattr(jaxrot, kind)).parameters
    owner, _, field = api.partition(".")
    return field in getattr(jaxrot, owner)._fields


def _resolve_sysid(api, sysid):
    if api.startswith("residual:"):
        return api.split(":")[1] in inspect.signature(sysid.residual).parameters
    obj = sysid
    for part in api.split("."):
        obj = getattr(obj, part, None)
    return obj is not None


@pytest.mark.parametrize("row", CAPS.CAPABILITIES, ids=lambda row: row[0])
def test_each_capability_cell_is_code_that_exists_and_runs(row):
    """A cell's ``api`` exists in the tool and its ``usage`` is in the code that drives that tool in the
    benchmark; a cell without an ``api`` is a "no" and says so."""
    _, ours, theirs = row
    for tool, cell in (("jaxrot", ours), ("sysid", theirs)):
        if cell["api"] is None:
            assert cell["text"].startswith("no"), cell
            continue
        source = "\n".join((ROOT / f).read_text() for f in CAPS.DRIVERS[tool])
        assert cell["usage"] and cell["usage"] in source, (tool, cell["usage"])
        if tool == "jaxrot":
            assert _resolve_jaxrot(cell["api"]), cell["api"]
        else:
            sysid = pytest.importorskip("mujoco.sysid")
            if not hasattr(sysid, "optimize"):
                pytest.skip("mujoco.sysid without its extra: pip install 'mujoco[sysid]'")
            assert _resolve_sysid(cell["api"], sysid), cell["api"]
        # The cell's text quotes its API's last name, so the table a person reads names the code.
        assert re.sub(r"^\w+:", "", cell["api"]).split(".")[-1] in cell["text"], cell
