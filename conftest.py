"""Test configuration, in the style of diffrax/equinox: float64 on, strict promotion."""

import importlib.metadata
import importlib.util
import os


# Four fake CPU devices (tests/test_sharding.py); must be set before the backend starts. And LLVM at
# -O0 for XLA:CPU's generated code: compiling dominates this suite (a test's programs compile in
# seconds and run in milliseconds), and -O0 cut the compile-bound tests' time by 10-30 % (measured on
# tests/test_rotor.py, tests/test_zhao.py and a fit); the programs' semantics, hence every tolerance,
# are the same at any optimisation level.
_XLA_FLAGS = "--xla_force_host_platform_device_count=4 --xla_backend_optimization_level=0"
# And XLA:CPU's older loop emitters instead of its fusion emitters, where jaxlib still has them
# (0.10; 0.12 has only the fusion emitters and rejects the flag): they compile faster (measured on
# jaxlib 0.10.2, 2 cores: the default set 4:51 -> 2:38; tests/test_identify.py's per-experiment
# Jacobian test 10.4 -> 6.9 s) and evaluate the same operations, but fuse them differently, so two
# programs that round alike under the default emitters may not here: tests of a bit-for-bit promise
# take the `default_emitters` fixture.
_LOOP_EMITTERS = "--xla_cpu_use_fusion_emitters=false"
if tuple(int(p) for p in importlib.metadata.version("jaxlib").split(".")[:2]) < (0, 11):
    _XLA_FLAGS += " " + _LOOP_EMITTERS
os.environ.setdefault("XLA_FLAGS", _XLA_FLAGS)

import jax  # noqa: E402
import pytest  # noqa: E402
from hypothesis import settings  # noqa: E402


# JAX's persistent compilation cache: compiling dominates this suite's time (a test's rollouts,
# references and gradients compile in seconds and run in milliseconds), and the slow set, a second
# run, or the other xdist worker reuse what one run compiled. JAXROT_TEST_CACHE="" turns it off.
_cache = os.environ.get("JAXROT_TEST_CACHE", os.path.join(os.path.dirname(__file__), ".jax_cache"))
if _cache:
    jax.config.update("jax_compilation_cache_dir", _cache)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_dtype_promotion", "strict")
jax.config.update("jax_numpy_rank_promotion", "raise")

# Compilation makes first examples slow; hypothesis deadlines would be noise.
settings.register_profile("jaxrot", deadline=None, max_examples=60, derandomize=True)
settings.load_profile("jaxrot")


def _memory_maps():
    """(memory mappings of this process, the kernel's limit), or None off Linux."""
    try:
        with open("/proc/sys/vm/max_map_count") as f:
            limit = int(f.read())
        with open("/proc/self/maps") as f:
            return sum(1 for _ in f), limit
    except (OSError, ValueError):
        return None


@pytest.fixture(autouse=True)
def _release_compiled_code():
    """Drop JAX's compiled programs once they hold half of the process's memory mappings.

    XLA:CPU maps a few pages per kernel of every compiled program (a rollout: 50-400 mappings)
    and keeps them while the program is cached. A test worker compiles thousands of programs;
    past Linux's vm.max_map_count (65530 by default) LLVM fails with "Cannot allocate memory"
    and the worker aborts. Measured: tests/test_stability.py alone leaves 15 500 mappings.
    """
    yield
    counts = _memory_maps()
    if counts is not None and counts[0] > counts[1] // 2:
        jax.clear_caches()


# Long items that cannot carry a decorator: the notebooks (also executed by the documentation build,
# `mkdocs build`, in .ci/run) and the longest docstring examples. Run them with `pytest -m slow`.
SLOW_ITEMS = (
    "notebooks/",
    "jaxrot/stability.py::",
    "jaxrot/comparison/__init__.py::",
    "jaxrot/jax_md/_simulate.py::",
)


# The jax_md adapter and its notebook import jax_md, an optional extra (`pip install -e ".[jax_md]"`,
# Python 3.12: jax_md excludes jax 0.10.2): without it their doctests and cells are not collected
# (tests/test_jax_md.py skips itself with a message).
collect_ignore_glob = (
    [] if importlib.util.find_spec("jax_md") else ["jaxrot/jax_md/*", "notebooks/jax_md*.ipynb"]
)


def pytest_collection_modifyitems(config, items):
    # A module that moves (jaxrot/comparison.py became a package) would silently put its long
    # examples back into the default set: every named file must exist.
    root = os.path.dirname(__file__)
    missing = [p for p in SLOW_ITEMS if p.endswith("::") and not os.path.exists(os.path.join(root, p[:-2]))]
    if missing:
        raise pytest.UsageError(f"conftest.SLOW_ITEMS names files that do not exist: {missing}")
    for item in items:
        if item.nodeid.startswith(SLOW_ITEMS):
            item.add_marker(pytest.mark.slow)


@pytest.fixture(autouse=True)
def _jax_md_promotion(request):
    """jax_md's own code (the shapes and energies a test builds) needs JAX's default promotion rules, not
    this suite's strict ones: in the adapter's tests and doctests they are the default ones."""
    if "jax_md" not in request.node.nodeid:
        yield
        return
    with jax.numpy_dtype_promotion("standard"), jax.numpy_rank_promotion("allow"):
        yield


@pytest.fixture
def default_emitters(monkeypatch):
    """jaxrot's own programs compile with XLA's default (fusion) emitters in this test.

    A bit-for-bit promise (a blocked run equals the unblocked one; a user's ``jax.jit`` with
    `jaxrot.compiler_options` equals jaxrot's top-level call) is about the programs users compile.
    The suite's flag for faster compiles (above) turns those emitters off; a compiler option, which
    jaxrot adds to every program it compiles at top level, turns them back on for one test. A user's
    own ``jax.jit`` in such a test passes `jaxrot.compiler_options()`, which then carries it too.
    """
    if _LOOP_EMITTERS in os.environ.get("XLA_FLAGS", "").split():
        import jaxrot._core._compile

        monkeypatch.setitem(jaxrot._core._compile._CPU_OPTIONS, "xla_cpu_use_fusion_emitters", True)
