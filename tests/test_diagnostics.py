"""diagnostics: kinetic energy, world angular momentum and quaternion norm drift on trajectory arrays."""

import jax.numpy as jnp
import numpy as np
import pytest
from helpers import MOMENTS, PRINCIPAL_TO_BODY, full_tensor

from jaxrot import diagnostics, quaternion as quat


def _random_states(shape, seed=0):
    rng = np.random.default_rng(seed)
    q = quat.normalize(jnp.asarray(rng.normal(size=(*shape, 4))))
    omega = jnp.asarray(rng.normal(size=(*shape, 3)))
    return q, omega


def _numpy_energy_and_momentum(q, omega, tensor):
    """Independent evaluation with rotation matrices: R = to_matrix(q), ω_b = Rᵀω, L = R I ω_b."""
    rot = np.asarray(quat.to_matrix(q))
    omega_body = np.einsum("...ji,...j->...i", rot, np.asarray(omega))
    l_body = np.einsum("...ij,...j->...i", np.asarray(tensor), omega_body)
    return 0.5 * np.sum(omega_body * l_body, axis=-1), np.einsum("...ij,...j->...i", rot, l_body)


def test_shared_inertia_both_forms_with_time_and_particle_axes():
    q, omega = _random_states((5, 2, 3))  # (time, particles...)
    for inertia, tensor in ((MOMENTS, jnp.diag(MOMENTS)), (full_tensor(), full_tensor())):
        energy = diagnostics.kinetic_energy(q, omega, inertia)
        momentum = diagnostics.angular_momentum(q, omega, inertia)
        assert energy.shape == (5, 2, 3) and momentum.shape == (5, 2, 3, 3)
        expected_energy, expected_momentum = _numpy_energy_and_momentum(
            q, omega, np.broadcast_to(tensor, (5, 2, 3, 3, 3))
        )
        np.testing.assert_allclose(energy, expected_energy, rtol=1e-13)
        np.testing.assert_allclose(momentum, expected_momentum, rtol=1e-13, atol=1e-14)


def test_per_particle_inertia_goes_after_the_time_axis():
    q, omega = _random_states((4, 2, 5))  # (time, particles...)
    rng = np.random.default_rng(1)
    moments = jnp.asarray(rng.uniform(1.0, 1.5, size=(2, 5, 3)))  # one (3,) per particle
    tensors = jnp.eye(3)[None, None] * moments[..., None, :]  # (2, 5, 3, 3): the same bodies as tensors
    expected_energy, expected_momentum = _numpy_energy_and_momentum(
        q, omega, jnp.broadcast_to(tensors, (4, 2, 5, 3, 3))
    )
    for inertia in (moments, tensors):
        np.testing.assert_allclose(diagnostics.kinetic_energy(q, omega, inertia), expected_energy, rtol=1e-13)
        np.testing.assert_allclose(
            diagnostics.angular_momentum(q, omega, inertia), expected_momentum, rtol=1e-13, atol=1e-14
        )


def test_a_rotated_tensor_is_the_same_body_as_its_principal_moments():
    """Expressing the same body in a non-principal body frame changes q, not the physics."""
    q, omega = _random_states((6,), seed=2)
    q_body = quat.multiply(q, quat.conjugate(jnp.broadcast_to(PRINCIPAL_TO_BODY, q.shape)))
    np.testing.assert_allclose(
        diagnostics.kinetic_energy(q_body, omega, full_tensor()),
        diagnostics.kinetic_energy(q, omega, MOMENTS),
        rtol=1e-13,
    )
    np.testing.assert_allclose(
        diagnostics.angular_momentum(q_body, omega, full_tensor()),
        diagnostics.angular_momentum(q, omega, MOMENTS),
        rtol=1e-13,
        atol=1e-14,
    )


def test_single_state_float32_and_norm_drift():
    q = jnp.array([1.0, 0.0, 0.0, 0.0], dtype=jnp.float32)
    omega = jnp.array([0.0, 0.0, 2.0], dtype=jnp.float32)
    energy = diagnostics.kinetic_energy(q, omega, jnp.array([1.0, 2.0, 3.0], dtype=jnp.float32))
    assert energy.shape == () and energy.dtype == jnp.float32 and float(energy) == 6.0
    drift = diagnostics.norm_drift(jnp.array([[1.0, 0, 0, 0], [0.6, 0.8, 0, 0], [0.0, 0, 0, 1.001]]))
    assert float(drift) == pytest.approx(1e-3, rel=1e-9)
    assert diagnostics.norm_drift(q).dtype == jnp.float32


@pytest.mark.parametrize(
    "q_shape, omega_shape, inertia_shape, match",
    [
        ((5, 3), (5, 3), (3,), "`q`"),
        ((5, 4), (5, 2), (3,), "`omega`"),
        ((5, 4), (4, 3), (3,), "leading"),
        ((5, 2, 4), (5, 2, 3), (3, 3, 3), "inertia"),
        ((5, 2, 4), (5, 2, 3), (4,), "inertia"),
    ],
)
def test_bad_shapes_raise_value_error(q_shape, omega_shape, inertia_shape, match):
    with pytest.raises(ValueError, match=match):
        diagnostics.kinetic_energy(jnp.ones(q_shape), jnp.ones(omega_shape), jnp.ones(inertia_shape))
    with pytest.raises(ValueError, match="`q`"):
        diagnostics.norm_drift(jnp.ones((3, 3)))
