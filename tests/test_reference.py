"""reference_rollout: against the closed-form symmetric top, invariants, failure reporting."""

import jax.numpy as jnp
import numpy as np
import pytest
from helpers import MOMENTS, full_tensor, principal_state, to_body_frame

import jaxrot
from jaxrot import quaternion as quat


def symmetric_top_exact(q0, omega_body0, i_perp, i3, ts):
    """Closed form of the torque-free symmetric top (Landau & Lifshitz §33).

    With ``λ = (I3 − I⊥) ω3 / I⊥`` and ``L_w`` the world angular momentum,
    ``q(t) = exp(L_w t / I⊥) ⊗ q0 ⊗ exp(−λ t e3)`` (exp of a rotation vector).
    """
    moments = jnp.array([i_perp, i_perp, i3])
    l_world = quat.rotate(q0, moments * omega_body0)
    lam = (i3 - i_perp) * omega_body0[2] / i_perp
    e3 = jnp.array([0.0, 0.0, 1.0])
    precession = quat.exp(ts[:, None] * l_world[None, :] / i_perp)
    spin = quat.exp(-lam * ts[:, None] * e3[None, :])
    q = quat.multiply(quat.multiply(precession, jnp.broadcast_to(q0, precession.shape)), spin)
    omega_body = quat.rotate(quat.conjugate(spin), jnp.broadcast_to(omega_body0, (ts.shape[0], 3)))
    return q, quat.rotate(q, omega_body)


def test_matches_closed_form_symmetric_top():
    q0 = quat.exp(jnp.array([0.3, -0.5, 0.2]))
    omega_body0 = jnp.array([0.7, -0.4, 3.0])
    ts = jnp.linspace(0.0, 20.0, 41)
    ref = jaxrot.reference_rollout(
        jaxrot.RotState(q0, quat.rotate(q0, omega_body0)),
        jnp.array([1.0, 1.0, 1.7]),
        ts,
        rtol=1e-13,
        atol=1e-13,
    )
    q_exact, omega_exact = symmetric_top_exact(q0, omega_body0, 1.0, 1.7, ts)
    assert float(jnp.max(quat.angle_between(ref.q, q_exact))) < 1e-10
    np.testing.assert_allclose(ref.omega, omega_exact, atol=1e-10)
    np.testing.assert_array_equal(ref.t, ts)


def test_conserves_energy_and_world_angular_momentum_of_a_free_asymmetric_body():
    state = principal_state(omega_body=jnp.array([1.0, 2.0, 0.5]))
    ts = jnp.linspace(0.0, 50.0, 11)
    ref = jaxrot.reference_rollout(state, MOMENTS, ts, rtol=1e-13, atol=1e-13)
    omega_body = quat.rotate(quat.conjugate(ref.q), ref.omega)
    energy = 0.5 * jnp.sum(MOMENTS[None] * omega_body**2, axis=-1)
    l_world = quat.rotate(ref.q, MOMENTS[None] * omega_body)
    np.testing.assert_allclose(energy, energy[0], rtol=1e-10)
    np.testing.assert_allclose(l_world, jnp.broadcast_to(l_world[0], l_world.shape), atol=1e-10)
    np.testing.assert_allclose(jnp.linalg.norm(ref.q, axis=-1), 1.0, atol=1e-15)


@pytest.mark.slow
def test_full_tensor_agrees_with_principal_moments():
    state = principal_state(omega_body=jnp.array([1.0, 2.0, 0.5]))
    ts = jnp.linspace(0.0, 5.0, 6)
    diag = jaxrot.reference_rollout(state, MOMENTS, ts, rtol=1e-13, atol=1e-13)
    full = jaxrot.reference_rollout(to_body_frame(state), full_tensor(), ts, rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(full.omega, diag.omega, atol=1e-10)


@pytest.mark.slow
def test_batched_particles_and_single_time():
    rng = np.random.default_rng(3)
    q = quat.normalize(jnp.asarray(rng.normal(size=(2, 3, 4))))
    states = jaxrot.RotState(q, jnp.asarray(rng.normal(size=(2, 3, 3))))
    ref = jaxrot.reference_rollout(states, MOMENTS, jnp.array([0.0, 0.5, 1.0]), rtol=1e-10, atol=1e-10)
    assert ref.q.shape == (3, 2, 3, 4) and ref.omega.shape == (3, 2, 3, 3)
    only_start = jaxrot.reference_rollout(states, MOMENTS, jnp.array([0.0]))
    np.testing.assert_allclose(only_start.q[0], states.q, atol=1e-15)


def test_a_failed_solve_says_so():
    state = principal_state()
    with pytest.raises(RuntimeError, match="max_steps"):
        jaxrot.reference_rollout(state, MOMENTS, jnp.linspace(0.0, 100.0, 3), max_steps=4)


def test_rejects_tolerances_float32_cannot_meet():
    state = jaxrot.RotState(jnp.array([1.0, 0, 0, 0], dtype=jnp.float32), jnp.ones(3, dtype=jnp.float32))
    with pytest.raises(ValueError, match="rtol"):
        jaxrot.reference_rollout(state, MOMENTS, jnp.linspace(0.0, 1.0, 3))
    ref = jaxrot.reference_rollout(state, MOMENTS, jnp.linspace(0.0, 1.0, 3), rtol=1e-6, atol=1e-6)
    assert ref.q.dtype == jnp.float32


@pytest.mark.parametrize(
    "ts, match",
    [
        (jnp.array([0.0, 2.0, 1.0]), "non-decreasing"),
        (jnp.zeros((2, 2)), "1-D"),
        (jnp.array([0.0, jnp.nan]), "NaN"),
    ],
)
def test_rejects_bad_times(ts, match):
    with pytest.raises(ValueError, match=match):
        jaxrot.reference_rollout(principal_state(), MOMENTS, ts)
