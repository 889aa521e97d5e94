"""A rollout's compiled memory depends on the saved states, not on the number of steps."""

import sys

import jax
import jax.numpy as jnp
import pytest

import jaxrot
from jaxrot import _blocking


def compiled_memory(scheme, n_bodies, n_steps, save_every):
    q = jaxrot.quaternion.exp(jnp.linspace(0.1, 1.0, 3 * n_bodies).reshape(n_bodies, 3))
    state = jaxrot.RotState(q, jnp.ones((n_bodies, 3)))

    top = jaxrot.SCENES["heavy_top"]()

    def run(state):
        return jaxrot.rollout(
            scheme, state, top.inertia, 1e-3, n_steps, torque=top.torque, args=top.args, save_every=save_every
        )

    return jax.jit(run).lower(state).compile().memory_analysis()


@pytest.mark.parametrize(
    ("scheme", "blocked"), [(name, False) for name in sorted(jaxrot.SCHEMES)] + [("zhao", True)]
)
def test_memory_is_independent_of_the_number_of_steps(scheme, blocked, monkeypatch):
    if blocked:
        monkeypatch.setattr(_blocking, "BLOCK_BODIES", 16)  # 64 bodies in 4 blocks
    sizes = {}
    for n_steps, save_every in [(100, 100), (10_000, 10_000), (1000, 100), (100_000, 10_000)]:
        stats = compiled_memory(scheme, 64, n_steps, save_every)
        sizes[n_steps] = (stats.temp_size_in_bytes, stats.output_size_in_bytes)
    assert sizes[100] == sizes[10_000]  # 2 saved states
    assert sizes[1000] == sizes[100_000]  # 11 saved states
    # The output holds the saved states: t, and q and omega of 64 bodies, float64.
    assert sizes[1000][1] - sizes[100][1] == 9 * (1 + 64 * 7) * 8


def memory_maps():
    with open("/proc/self/maps") as f:
        return sum(1 for _ in f)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="counts /proc/self/maps")
def test_clear_caches_releases_the_mappings_of_compiled_rollouts():
    """README "Many compiles in one process": each compiled rollout holds memory mappings
    until `jax.clear_caches()` (conftest.py relies on it to stay under vm.max_map_count)."""
    state = jaxrot.RotState(jnp.array([1.0, 0.0, 0.0, 0.0]), jnp.array([0.1, 0.2, 0.3]))
    inertia = jnp.array([1.0, 2.0, 3.0])
    before = memory_maps()
    for n_steps in range(10, 15):
        jaxrot.rollout("no_squish", state, inertia, 0.01, n_steps)
    added = memory_maps() - before
    assert added > 5 * 20  # per program measured: 162 (jax 0.10.2), 38 (jax 0.12)
    jax.clear_caches()
    assert memory_maps() < before + 0.1 * added
