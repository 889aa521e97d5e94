"""The compiled step does each expensive thing once (`jaxrot._core._fusion`, `jaxrot._core._trig`)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrot
import jaxrot._core._fusion
from jaxrot._core._fusion import stage, stage_stacked
from jaxrot.scenes import heavy_top


def compiled_rollout_text(scheme, dtype):
    scene = heavy_top(dtype)
    state = jaxrot.RotState(
        jnp.broadcast_to(scene.state.q, (64, 4)), jnp.broadcast_to(scene.state.omega, (64, 3))
    )

    def run(s):
        return jaxrot.rollout(scheme, s, scene.inertia, 1e-3, 10, torque=scene.torque, args=scene.args)

    return jax.jit(run).lower(state).compile().as_text()


def test_float32_zhao_evaluates_each_trig_function_once_per_exp():
    # Two quaternion exponentials per step. Without the stage boundaries XLA re-derived the
    # cosine inside every consumer: 5 cosines (15 in a component-wise step).
    text = compiled_rollout_text("zhao", jnp.float32)
    assert text.count(" sine(") == 2
    assert text.count(" cosine(") == 2


@pytest.mark.parametrize("scheme", ["zhao", "no_squish"])
def test_float64_steps_use_the_vectorised_kernel(scheme):
    # XLA:CPU's float64 sine is scalar (7 ns per element); `sincos` is plain arithmetic.
    text = compiled_rollout_text(scheme, jnp.float64)
    assert text.count(" sine(") == 0
    assert text.count(" cosine(") == 0


@pytest.mark.parametrize("barrier", [stage, stage_stacked], ids=["stage", "stage_stacked"])
def test_stage_is_the_identity_for_values_gradients_and_batching(barrier):
    def f(x):
        y, z = barrier(jnp.sin(x), x**2)
        return jnp.sum(y * z)

    x = jnp.linspace(0.0, 1.0, 5)
    np.testing.assert_array_equal(jax.jit(f)(x), f(x))
    np.testing.assert_allclose(jax.grad(f)(x), jnp.cos(x) * x**2 + 2 * x * jnp.sin(x), rtol=1e-15)
    batched = jax.vmap(f)(jnp.stack([x, 2 * x]))
    np.testing.assert_allclose(batched, jnp.array([f(x), f(2 * x)]), rtol=1e-15)
    np.testing.assert_array_equal(stage(x), x)


@pytest.mark.parametrize("setting, placed", [(None, True), (True, True), (False, False)])
def test_barriers_are_placed_when_tracing_for_cpu_or_when_forced(setting, placed, monkeypatch):
    # On a GPU fusion wins (docs/performance.md, "On a GPU"): `None` places them for CPU only.
    monkeypatch.setattr(jaxrot._core._fusion, "BARRIERS", setting)
    text = str(jax.make_jaxpr(lambda x: stage(jnp.sin(x)))(jnp.ones(3)))
    assert ("optimization_barrier" in text) == placed
    if setting is None:
        monkeypatch.setattr(jax, "default_backend", lambda: "gpu")
        assert "optimization_barrier" not in str(jax.make_jaxpr(lambda x: stage(jnp.sin(x)))(jnp.ones(3)))
