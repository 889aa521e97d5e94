"""Zhao & van Wachem (2013) specifics; what every scheme must do is in test_schemes.py."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import (
    MOMENTS,
    PRINCIPAL_TO_BODY,
    fitted_order,
    full_tensor,
    gravity_args,
    order_errors,
    principal_state,
    to_body_frame,
)

import jaxrot
from jaxrot import quaternion as quat
from jaxrot.scenes import gravity_torque


ZHAO = jaxrot.SCHEMES["zhao"]
TUMBLING = principal_state(omega_body=jnp.array([1.0, 2.0, 0.5]))


def time_dependent_torque(t, q, omega, amplitude):
    return amplitude * jnp.stack([jnp.sin(3 * t), jnp.cos(2 * t), jnp.ones_like(t) * 0.5])


def damping_torque(t, q, omega, c):
    return -c * omega


@pytest.mark.parametrize(
    "torque, args",
    [
        pytest.param(time_dependent_torque, jnp.asarray(2.0), marks=pytest.mark.slow),
        (damping_torque, jnp.asarray(0.5)),
    ],
    ids=["time-dependent", "velocity-dependent"],
)
def test_measured_order_is_two_for_time_and_velocity_dependent_torque(torque, args):
    """The midpoint torque is called at (t + dt/2, q_half, omega_half); at t it would be first order."""
    dts, errors = order_errors(ZHAO, TUMBLING, MOMENTS, 4.0, 40, 5, torque, args)
    assert fitted_order(dts, errors) == pytest.approx(2.0, abs=0.15)


def test_full_tensor_is_the_same_physics_as_principal_moments():
    """A rotated full tensor and the matching orientation give the same world motion to round-off."""
    diag = jaxrot.rollout(ZHAO, TUMBLING, MOMENTS, 0.01, 300, torque=gravity_torque, args=gravity_args())
    full = jaxrot.rollout(
        ZHAO,
        to_body_frame(TUMBLING),
        full_tensor(),
        0.01,
        300,
        torque=gravity_torque,
        args=gravity_args(r=PRINCIPAL_TO_BODY),
    )
    np.testing.assert_allclose(full.omega, diag.omega, atol=1e-12)
    q_principal = quat.multiply(full.q, PRINCIPAL_TO_BODY)
    assert float(jnp.max(quat.angle_between(q_principal, diag.q))) < 1e-12


def test_torque_is_called_at_step_start_and_midpoint():
    calls = []

    def counting_torque(t, q, omega, args):
        jax.debug.callback(lambda t: calls.append(float(t)), t)
        return jnp.zeros(3)

    jax.block_until_ready(jaxrot.rollout(ZHAO, TUMBLING, MOMENTS, 0.1, 7, torque=counting_torque, t0=1.0))
    assert len(calls) == ZHAO.torque_evals_per_step * 7
    # Start-of-step and midpoint times: t, t + dt/2 for each step.
    expected = sorted([1.0 + 0.1 * k for k in range(7)] + [1.05 + 0.1 * k for k in range(7)])
    np.testing.assert_allclose(sorted(calls), expected, atol=1e-12)
