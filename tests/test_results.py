"""The committed results files that the docs' tables are rendered from: provenance and coverage.

A results file is current when its ``machine`` block carries the schema of
`jaxrot.comparison.machine_info` (machine, versions, commit, date) and its rows cover every
scheme in `jaxrot.SCHEMES`. ``python benchmarks/regenerate.py`` rewrites all of them but the GPU
files (made on a lent GPU: docs/performance.md); a new scheme fails here until they are rerun.
"""

import csv
import json
from pathlib import Path

import pytest

import jaxrot
from jaxrot.comparison import RESULTS_SCHEMA


DOCS = Path(__file__).resolve().parents[1] / "docs"

# The GPU races of the order >= 4 schemes only (the rotor ones and their rivals).
_GPU_RACE = "RACE_SCHEMES=splitting,rkmk_dopri8,rkmk_dopri8_cayley,srkn6b,srkn14a"

# file -> (how its rows name the scheme, or None where its rows are not per scheme; what regenerates it)
RESULTS = {
    "compile_cpu.json": ("method", "python benchmarks/regenerate.py --only compile"),
    # First calls of the public entries and their peers (issue 72): entries, not schemes.
    "first_call_cpu.json": (None, "python benchmarks/regenerate.py --only first_call"),
    "throughput_cpu.json": ("method", "python benchmarks/regenerate.py --only throughput"),
    "throughput_cpu_jax010.json": ("method", "python benchmarks/regenerate.py --only throughput_jax010"),
    # Three schemes, the ones XLA:CPU's YNN fusions slowed: not per scheme.
    "throughput_cpu_jax010_xla_defaults.json": (
        None,
        "python benchmarks/regenerate.py --only throughput_jax010_xla_defaults",
    ),
    "cpu_vector_width.json": ("scheme", "python benchmarks/regenerate.py --only cpu_vector_width"),
    "memory_cpu.json": ("scheme", "python benchmarks/regenerate.py --only memory"),
    "stability_cpu.json": ("scheme", "python benchmarks/regenerate.py --only stability"),
    # Energy and momentum against |ω|Δt over 1e5 steps: every scheme and MJX's integrators.
    "energy_growth.json": ("method", "python benchmarks/regenerate.py --only energy_growth"),
    "identify_speed_cpu.json": (None, "python benchmarks/regenerate.py --only identify_speed"),
    # The fourth-order Lie-group methods and MuJoCo's RK4: methods, not schemes.
    "order4.json": (None, "python benchmarks/regenerate.py --only order4"),
    "float32_horizon.json": ("scheme", "python benchmarks/regenerate.py --only float32"),
    "rotor_choice_cpu.json": (None, "python benchmarks/regenerate.py --only rotor_choice"),
    "mujoco_free_body_cpu.json": ("method", "python benchmarks/regenerate.py --only mujoco_free_body"),
    "compare_heavy_top.json": ("method", "python benchmarks/regenerate.py --only compare"),
    # MuJoCo XLA against jaxrot (needs .[mjx]): MJX's integrators and four jaxrot schemes, not every scheme.
    "mjx_cpu.json": (None, "python benchmarks/regenerate.py --only mjx"),
    # Bodies in a fluid: the fluid schemes and the overdamped ones, not jaxrot.SCHEMES.
    "fluid_orders.json": (None, "python benchmarks/regenerate.py --only fluid_orders"),
    "fluid_layer.json": (None, "python benchmarks/regenerate.py --only fluid_layer"),
    # The fluid race: rows are jaxrot's fluid and overdamped schemes and diffrax's solvers.
    "fluid_race_cpu.json": (None, "python benchmarks/regenerate.py --only fluid_race"),
    "overdamped_cost_cpu.json": (None, "python benchmarks/regenerate.py --only overdamped_cost"),
    # One exponential step against rkmk4's with the same physics (issue 66): rows are steps, not schemes.
    "fluid_step_cost_cpu.json": (None, "python benchmarks/regenerate.py --only fluid_step_cost"),
    # Bodies at a temperature: the thermal schemes and the peers, not jaxrot.SCHEMES.
    "thermal_orders.json": (None, "python benchmarks/regenerate.py --only thermal_orders"),
    "thermal_peers.json": (None, "python benchmarks/regenerate.py --only thermal_peers"),
    # jaxrot.jax_md against jax_md's rigid-body simulators (Python 3.12 with .[jax_md]): not per scheme.
    "jax_md_cpu.json": (None, "python benchmarks/regenerate.py --only jax_md_rigid --python <py312>"),
    # jaxrot.jax_md.brownian against closed forms (Python 3.12 with .[jax_md]): accuracy, not per scheme.
    "jax_md_brownian.json": (None, "python benchmarks/regenerate.py --only jax_md_brownian --python <py312>"),
    "race_cpu/race_float64.json": ("method", "python benchmarks/regenerate.py --only race64"),
    "race_cpu/race_float32.json": ("method", "python benchmarks/regenerate.py --only race32"),
    "gpu_h100/race_heavy_top_float64.json": ("method", "python benchmarks/race.py (on the GPU)"),
    "gpu_h100/tp_f32_1000000.json": ("method", "python benchmarks/throughput.py (on the GPU)"),
    "gpu_h200/tp_f32_nobar_jax_md.json": ("method", "OUT=... STEPS=throughput bash benchmarks/gpu.sh"),
    # The GPU races leave out the first- and second-order schemes (benchmarks/gpu.sh): not every scheme.
    "gpu_h200/race_dipole_rotating_field_float64.json": (None, "STEPS=race_dipole bash benchmarks/gpu.sh"),
    # The rotor schemes only, under each setting of the rotor's while loop.
    "gpu_h200/rotor_loop.json": (None, "STEPS=rotor_loop bash benchmarks/gpu.sh"),
    "gpu_h200/rotor_loop_cmdbuf.json": (None, "STEPS=command_buffers bash benchmarks/gpu.sh"),
    # The dipole race again with 8 rotor steps per loop iteration, the order >= 4 schemes that run it.
    "gpu_h200/race_dipole_rotating_field_float64_loop8.json": (
        None,
        f"{_GPU_RACE} STEPS=race_dipole bash benchmarks/gpu.sh, with _rotor._GPU_LOOP_BATCH = 8",
    ),
    "gpu_h200/race_viscous_drag_float64_firstpass.json": (
        None,
        "STEPS=race_viscous bash benchmarks/gpu.sh, or benchmarks/race.py --from-log on its log",
    ),
    # After 66a9078, on an H100: the loop settings and command buffers as a compiler option, the flag.
    "gpu_h100/rotor_loop.json": (None, "STEPS=rotor_loop bash benchmarks/gpu.sh"),
    "gpu_h100/rotor_loop_cmdbuf_flag.json": (None, "STEPS=command_buffers bash benchmarks/gpu.sh"),
    "gpu_h100/race_dipole_rotating_field_float64.json": (
        None,
        f"{_GPU_RACE} STEPS=race_dipole bash benchmarks/gpu.sh",
    ),
    "gpu_h100/race_dipole_rotating_field_float64_cmdbuf.json": (
        None,
        f"{_GPU_RACE} STEPS=race_dipole_cmdbuf bash benchmarks/gpu.sh",
    ),
    # From 0ed6f8e on an H100: throughput as `rollout` compiles it (command buffers on), and the
    # kernels per step of four schemes and jax_md against two floors.
    "gpu_h100/tp_f32_nobar_jax_md.json": ("method", "STEPS=throughput bash benchmarks/gpu.sh"),
    "gpu_h100/passes.json": (None, "STEPS=passes bash benchmarks/gpu.sh"),
    # The weak orders at 2²¹ bodies (issue 60), on an H200: the thermal schemes, not jaxrot.SCHEMES.
    "gpu_h200/thermal_orders.json": (
        None,
        "python benchmarks/thermal_orders.py --bodies 2097152 --out docs/gpu_h200/thermal_orders.json "
        "(on the GPU)",
    ),
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
    if "thresholds" in data:  # float32 horizons: rows per problem
        data = {**data, "rows": [r for rows in data["problems"].values() for r in rows]}
    if "limits" in data:  # stability: every scheme has rows in each of its tables
        data = {**data, "rows": data["limits"] + data["blow_up"] + data["drift"]}
    return data


@pytest.mark.parametrize("name", list(RESULTS))
def test_results_file_has_provenance_and_covers_every_scheme(name):
    key, command = RESULTS[name]
    data = _load(name)
    machine = data.get("machine", {})
    assert machine.get("schema") == RESULTS_SCHEMA, (
        f"{name}: schema {machine.get('schema')}; rerun `{command}`"
    )
    for field in ("date", "commit", "python", "jax", "cpus", "device"):
        assert machine.get(field), f"{name}: no {field!r} in its machine block; rerun `{command}`"
    if key is None:
        return
    missing = set(jaxrot.SCHEMES) - {row[key] for row in data["rows"]}
    assert not missing, f"{name}: no rows for {sorted(missing)}; rerun `{command}`"


def test_every_results_file_the_docs_render_is_checked():
    """A new results file under docs/ gets an entry in `RESULTS` (or this fails)."""
    rendered = {
        str(p.relative_to(DOCS)) for p in [*DOCS.glob("*.json"), *DOCS.glob("*.csv"), *DOCS.glob("*/*.json")]
    }
    unchecked = rendered - set(RESULTS)
    # The GPU throughput files besides the one checked are the same run at other settings.
    unchecked = {n for n in unchecked if not n.startswith("gpu_h100/tp_")}
    assert not unchecked, f"results files without a provenance check: {sorted(unchecked)}"


def _tables():
    """The docs' table hook (docs/_hooks/tables.py), loaded by its path."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("_docs_tables", DOCS / "_hooks" / "tables.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_readme_quotes_the_results_files():
    """README's speed paragraph is the one the home page renders from the results files
    (``{{ front_door_speed }}``, docs/_hooks/tables.py): a rerun that moves a number fails here
    until README follows, and the message gives the text to paste."""
    expected = _tables().front_door_speed(DOCS)
    readme = (DOCS.parent / "README.md").read_text()
    assert expected in readme, f"README.md's speed paragraph should read:\n\n{expected}\n"
    assert "{{ front_door_speed }}" in (DOCS / "index.md").read_text()


def test_scheme_guide_table_is_the_registry():
    """The scheme guide opens with the table of models (``{{ scheme_models_table }}``), rendered from
    `jaxrot.schemes_for`: one row per model, every registered scheme linked to its page."""
    from jaxrot._integrate._bind import DEFAULT_BROWNIAN, DEFAULT_OVERDAMPED
    from jaxrot.schemes import MODELS, REGISTRY

    table = _tables().TABLES["scheme_models_table"](DOCS)
    assert "{{ scheme_models_table }}" in (DOCS / "schemes" / "index.md").read_text()
    assert len(table.splitlines()) == 2 + len(MODELS)
    for name in REGISTRY:
        assert f"[`{name}`]({name}.md)" in table
    overdamped, brownian = table.splitlines()[-2:]
    assert overdamped.endswith(f"[`{DEFAULT_OVERDAMPED}`]({DEFAULT_OVERDAMPED}.md) |")
    assert brownian.endswith(f"[`{DEFAULT_BROWNIAN}`]({DEFAULT_BROWNIAN}.md) |")
