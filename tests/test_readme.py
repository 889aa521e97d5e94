"""The README's Python example, and the longer ones it used to print that now live on the diffrax,
scenes and performance pages of the documentation, run as printed (each in a fresh process, in a
scratch folder)."""

import importlib.util
import os
import pathlib
import re
import subprocess
import sys

import jax
import pytest


ROOT = pathlib.Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
PAGES = [README] + [
    ROOT / "docs" / page for page in ("scenes.md", "performance.md", "diffrax.md", "conventions.md")
]
README_BLOCKS = re.findall(r"```python\n(.*?)```", README.read_text(), flags=re.DOTALL)
BLOCKS = [b for page in PAGES for b in re.findall(r"```python\n(.*?)```", page.read_text(), flags=re.DOTALL)]
# The multi-host example (docs/performance.md) needs a cluster (jax.distributed); every other block runs.
RUNNABLE = [b for b in BLOCKS if "jax.distributed.initialize" not in b]
# A block without imports continues the README's first ("Use") example, which is also the first
# rollout of docs/getting-started.md (the drive example of docs/scenes.md continues it).
RUNNABLE = [b if "import jaxrot" in b else BLOCKS[0] + b for b in RUNNABLE]


def test_the_readme_has_its_examples():
    assert README_BLOCKS and "import jaxrot" in README_BLOCKS[0]
    assert len(BLOCKS) == len(RUNNABLE) + 1 >= 4


def _marks(block):
    """The diffrax example compiles adaptive order-8 solves (~30 s); tests/test_solver.py checks the same
    API by default, and the example itself runs in the slow set. A block that imports a peer that is not
    installed (the conventions page's MuJoCo example) is skipped, naming it."""
    marks = [pytest.mark.slow] if "diffeqsolve" in block else []
    imported = re.findall(r"^(?:import|from) (\w+)", block, flags=re.MULTILINE)
    missing = sorted({name for name in imported if importlib.util.find_spec(name) is None})
    if missing:
        marks.append(pytest.mark.skip(reason=f"needs {', '.join(missing)} (not installed)"))
    return marks


def _example_env():
    """The suite's compile settings (conftest.py) without its four fake devices, which a block that sets
    its own device count would contradict: the examples' programs mean the same at any optimisation
    level. And the suite's persistent compilation cache: most blocks repeat the README's first example
    (its rollout and its diffrax reference), and load those programs instead of compiling them again."""
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    flags = [f for f in os.environ.get("XLA_FLAGS", "").split() if "device_count" not in f]
    if flags:
        env["XLA_FLAGS"] = " ".join(flags)
    cache = jax.config.jax_compilation_cache_dir
    if cache:
        env["JAX_COMPILATION_CACHE_DIR"] = str(cache)
        env["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"] = "0"
        env["JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES"] = "0"
    return env


@pytest.mark.parametrize(
    "code",
    [pytest.param(b, marks=_marks(b)) for b in RUNNABLE],
    ids=[b.splitlines()[-1][:40] for b in RUNNABLE],
)
def test_readme_example_runs(code, tmp_path):
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=tmp_path, env=_example_env(), capture_output=True, text=True
    )
    assert out.returncode == 0, out.stderr[-3000:]
    if "sharding.spec" in code:
        assert "(None, 'p')" in out.stdout


def test_readme_race_range_is_the_results_file():
    """README's race sentence quotes the range of speed-ups that the committed results file gives
    (`docs/race_cpu/race_float64.json`, rendered on the docs site by the same hook), so a rerun of
    the race cannot leave a stale number on the front door."""
    spec = importlib.util.spec_from_file_location("docs_tables_hook", ROOT / "docs" / "_hooks" / "tables.py")
    tables = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(tables)
    low, high, slower = tables.race_ratios(ROOT / "docs")
    quoted = re.search(r"by (\d+\.\d+)× to (\d+\.\d+)×", README.read_text())
    assert quoted, "README lost its race sentence"
    assert (quoted.group(1), quoted.group(2)) == (f"{low:.2f}", f"{high:.2f}")
    assert not slower  # the sentence says faster "at every error budget"
