"""Test configuration, in the style of diffrax/equinox: float64 on, strict promotion."""

import os


# Four fake CPU devices (tests/test_sharding.py); must be set before the backend starts.
os.environ.setdefault("XLA_FLAGS", "--xla_force_host_platform_device_count=4")

import jax  # noqa: E402
import pytest  # noqa: E402
from hypothesis import settings  # noqa: E402


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
