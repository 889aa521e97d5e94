"""Energy and momentum against the step over 10⁵ steps (docs/energy_growth.json, written by
``python benchmarks/regenerate.py --only energy_growth``): the pages render it, README quotes it, and
what docs/stability.md, docs/schemes/zhao.md and README say about it holds in it. Nothing here
integrates: the file is the measurement (accuracy only, float64), these tests read it."""

import importlib.util
import json
import re
import sys
from pathlib import Path
from types import SimpleNamespace

import pytest

import jaxrot


ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
DATA = json.loads((DOCS / "energy_growth.json").read_text())
ROWS = {(r["method"], r["body"]): r for r in DATA["rows"]}
GRID = DATA["settings"]["grid"]
BODIES = ("tumbling", "dzhanibekov", "heavy_top")
FREE = ("tumbling", "dzhanibekov")
MJX = DATA["settings"]["mjx"] == "measured"
needs_mjx = pytest.mark.skipif(not MJX, reason="docs/energy_growth.json was measured without MJX")
# Pages and the tables they render from the file.
PAGES = {
    "stability.md": [
        "{{ energy_limits_table }}",
        *(f"{{{{ energy_drift_table {b} }}}}" for b in BODIES),
    ],
    "schemes/zhao.md": [
        "{{ energy_limits_table zhao,no_squish,splitting,rozmanov,mjx_rk4 }}",
        "{{ energy_drift_table tumbling zhao,no_squish,splitting,rozmanov,mjx_rk4 }}",
    ],
}


def _module(name, path):
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def tables():
    return _module("_docs_tables", DOCS / "_hooks" / "tables.py")


def test_the_file_covers_every_scheme_and_body_on_the_grid():
    assert DATA["settings"]["steps"] == 100_000 and DATA["settings"]["save_every"] == 1
    assert DATA["settings"]["tolerance"] == 0.01
    # 10 rungs per decade from 0.005 to 1 (the docs say so through the rendered note).
    assert GRID[0] == pytest.approx(10**-2.3) and GRID[-1] == 1.0 and len(GRID) == 24
    assert all(b / a == pytest.approx(10**0.1) for a, b in zip(GRID, GRID[1:], strict=False))
    methods = [*jaxrot.SCHEMES, *(["mjx_euler", "mjx_rk4", "mjx_implicitfast"] if MJX else [])]
    assert set(ROWS) == {(m, b) for m in methods for b in BODIES}
    for r in DATA["rows"]:
        assert all(len(r[k]) == len(GRID) for k in ("energy_max", "energy_end", "first_nonfinite_step"))


def test_each_1_percent_step_is_the_rule_applied_to_the_files_rungs():
    """The largest rung at which it and every smaller rung are finite and within 1 %; lucky rungs above
    it are listed, not counted (recomputed here from the per-rung maxima)."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    import energy_growth

    assert energy_growth.limit([True, True, False, True]) == 1
    assert energy_growth.limit([False, True]) is None
    for r in DATA["rows"]:
        for key in ("energy", "momentum"):
            passing = [x is not None and x <= 0.01 for x in r[f"{key}_max"]]
            i = energy_growth.limit(passing)
            assert r[f"{key}_limit"] == (None if i is None else GRID[i]), (r["method"], r["body"], key)
            if i is not None:
                assert all(passing[: i + 1])
        # A non-finite run has no figures.
        for j, step in enumerate(r["first_nonfinite_step"]):
            assert (step is None) == (r["energy_max"][j] is not None)


@pytest.mark.parametrize("page", list(PAGES))
def test_the_pages_render_the_file(tables, page):
    """Each page names its tables, and the hook renders the whole page from the file: every limit
    the limits table prints is the file's, in the file's order of methods."""
    text = (DOCS / page).read_text()
    for placeholder in PAGES[page]:
        assert placeholder in text, f"docs/{page} lost {placeholder}"
    config = {"docs_dir": str(DOCS)}
    rendered = tables.on_page_markdown(
        text, SimpleNamespace(file=SimpleNamespace(src_path=page)), config, None
    )
    assert "{{ energy" not in rendered
    header = " | ".join(
        ["| method", *(f"{b}: energy / momentum" for b in ("tumbling", "Dzhanibekov", "heavy top"))]
    )
    header += " |"
    block = rendered.split(header)[1].split("\n\n")[0].strip().splitlines()[1:]
    assert block, "no limits table rendered"
    for line in block:
        method = re.search(r"`(\w+)`", line).group(1)
        method = method if (method, "tumbling") in ROWS else f"mjx_{method}"
        cells = [c.strip() for c in line.strip("|").split("|")[1:]]
        for body, cell in zip(BODIES, cells, strict=True):
            r = ROWS[method, body]
            for part, key in zip(cell.split(" (")[0].split(" / "), ("energy", "momentum"), strict=True):
                x = r[f"{key}_limit"]
                expected = "< 0.005" if x is None else ("≥ 1" if x >= GRID[-1] else f"{x:.3g}")
                assert part == expected, (page, method, body, key)
    assert "from `docs/energy_growth.json`" in rendered.lower()


def test_the_energy_section_has_no_hand_typed_numbers():
    """The section's figures come from the file; the hand-quoted table it had is gone."""
    text = (DOCS / "stability.md").read_text()
    section = text.split("### Energy against the step")[1].split("\n## ")[0]
    assert not re.search(r"\d\.\d+e[+-]?\d", section)
    assert not re.search(r"\d\.\d+e[+-]?\d", (DOCS / "schemes" / "zhao.md").read_text())


def test_zhao_gains_energy_and_the_gain_grows_with_the_run():
    """docs/stability.md: a gain at every finite rung, at its 1 % step at least 5× larger over 10⁵ steps
    than over the first 10⁴, and non-finite runs past it."""
    for body in BODIES:
        r = ROWS["zhao", body]
        ends = [e for e in r["energy_end"] if e is not None]
        assert ends and all(e > 0 for e in ends), body
        i = GRID.index(r["energy_limit"])
        assert r["energy_max"][i] >= 5 * r["energy_max_1e4"][i], body
        assert any(s is not None for s in r["first_nonfinite_step"][i + 1 :]), body


def test_zhaos_1_percent_step_is_below_the_symplectic_schemes_and_mjx_rk4():
    """docs/stability.md, zhao.md and schemes/index.md: the smallest of the second-order schemes on
    every body, several (≥ 3) times below no_squish's and splitting's."""
    for body in BODIES:
        zhao = ROWS["zhao", body]["energy_limit"]
        assert zhao is not None
        rivals = ["no_squish", "rozmanov", "splitting"] + (["mjx_rk4"] if MJX else [])
        for method in rivals:
            assert ROWS[method, body]["energy_limit"] > zhao, (method, body)
        for method in ("no_squish", "splitting"):
            assert ROWS[method, body]["energy_limit"] >= 3 * zhao, (method, body)


def test_the_symplectic_schemes_errors_are_bounded_or_round_off():
    for body in BODIES:
        r = ROWS["no_squish", body]
        for whole, early in zip(r["energy_max"], r["energy_max_1e4"], strict=True):
            assert whole is not None and whole <= 1.1 * early, body
    for method in ("splitting", "srkn6b", "srkn14a"):
        for body in FREE:
            assert max(ROWS[method, body]["energy_max"]) <= 1e-10, (method, body)
    for body in BODIES:
        assert ROWS["euler", body]["energy_limit"] is None, body


@needs_mjx
def test_what_the_docs_say_of_mjx():
    for body in FREE:  # energy of the body rates alone: RK4 on Euler's equations on both sides
        assert ROWS["mjx_rk4", body]["energy_limit"] == ROWS["rkmk4", body]["energy_limit"], body
    for body in BODIES:
        euler, implicit = ROWS["mjx_euler", body], ROWS["mjx_implicitfast", body]
        for key in ("energy_max", "energy_end", "momentum_max", "first_nonfinite_step"):
            assert euler[key] == implicit[key], (body, key)
        assert euler["energy_limit"] is None
        first = next(g for g, s in zip(GRID, euler["first_nonfinite_step"], strict=True) if s is not None)
        assert first <= 0.02, body


def test_readme_quotes_the_file_on_its_examples_scheme(tables):
    """README's sentence is rendered from the file (a rerun that moves a number fails here until README
    follows), its example runs the scheme, step and steps the sentence is about on the heavy top, and
    what the sentence says holds: within 1 % at every rung for the example's scheme, not for zhao,
    and zhao cheaper per step in every row of the throughput file."""
    hook = _module("_tables_energy", DOCS / "_hooks" / "_tables_energy.py")
    sentence = tables.readme_energy_sentence(DOCS)
    readme = (ROOT / "README.md").read_text()
    assert sentence in readme, f"README.md's sentence should read:\n\n{sentence}\n"
    scheme, dt, steps = hook.README_EXAMPLE
    call = re.search(r'jaxrot\.rollout\("(\w+)", state, inertia, ([\d.]+), (\d+), torque=gravity', readme)
    assert call and (call.group(1), float(call.group(2)), int(call.group(3))) == (scheme, dt, steps)
    omega = re.search(r"jaxrot\.RotState\(q0, jnp\.array\(\[([\d., ]+)\]\)\)", readme).group(1)
    norm = sum(float(x) ** 2 for x in omega.split(",")) ** 0.5
    assert norm == pytest.approx(DATA["settings"]["bodies"]["heavy_top"]["omega0"], rel=1e-12)
    assert ROWS[scheme, "heavy_top"]["energy_limit"] == GRID[-1]
    assert ROWS[hook.README_RIVAL, "heavy_top"]["energy_limit"] < GRID[-1]
    throughput = json.loads((DOCS / "throughput_cpu.json").read_text())["rows"]
    speed = {(r["dtype"], r["n"], r["method"]): r["particle_steps_per_s"] for r in throughput}
    for dtype, n, method in speed:
        if method == scheme:
            assert speed[dtype, n, hook.README_RIVAL] > speed[dtype, n, scheme], (dtype, n)
