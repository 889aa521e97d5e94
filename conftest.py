"""Test configuration, in the style of diffrax/equinox: float64 on, strict promotion."""

import os


# Two fake CPU devices; must be set before the backend starts. tests/test_sharding.py needs 4:
# XLA_FLAGS=--xla_force_host_platform_device_count=4 python -m pytest tests/test_sharding.py
os.environ.setdefault("XLA_FLAGS", "--xla_force_host_platform_device_count=2")

import jax  # noqa: E402
from hypothesis import settings  # noqa: E402


jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_dtype_promotion", "strict")
jax.config.update("jax_numpy_rank_promotion", "raise")

# Compilation makes first examples slow; hypothesis deadlines would be noise.
settings.register_profile("jaxrot", deadline=None, max_examples=60, derandomize=True)
settings.load_profile("jaxrot")
