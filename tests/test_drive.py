"""Driven bodies (Rockable, seed 004): imposed angular velocity and imposed moment, every scheme."""

import jax.numpy as jnp
import numpy as np
import pytest
from helpers import MOMENTS, contract_params, gravity_args, principal_state

import jaxrot
from jaxrot import quaternion as quat
from jaxrot.scenes import gravity_torque


TUMBLING = principal_state(omega_body=jnp.array([1.0, 2.0, 0.5]))
OMEGA_IMPOSED = jnp.array([0.4, -1.1, 2.0])


@pytest.mark.parametrize("name", contract_params())
def test_imposed_velocity_rotates_at_exactly_that_rate(name):
    drive = jaxrot.Drive.imposed_velocity(OMEGA_IMPOSED)
    dt, n = 0.01, 100
    traj = jaxrot.rollout(
        name, TUMBLING, MOMENTS, dt, n, torque=gravity_torque, args=gravity_args(), drive=drive
    )
    np.testing.assert_array_equal(traj.omega[1:], jnp.broadcast_to(OMEGA_IMPOSED, (n, 3)))
    if name == "euler":
        # Rockable's first-order update, step by step.
        q = TUMBLING.q
        for _ in range(n):
            q = quat.normalize(q + dt * 0.5 * quat.multiply(quat.pure(OMEGA_IMPOSED), q))
        expected = q
    else:
        expected = quat.multiply(quat.exp(n * dt * OMEGA_IMPOSED), TUMBLING.q)
    assert float(quat.angle_between(traj.q[-1], expected)) < 1e-12


@pytest.mark.parametrize("name", contract_params())
def test_uncontrolled_components_of_a_velocity_driven_body_stay_at_rest(name):
    drive = jaxrot.Drive.imposed_velocity(jnp.array([0.0, 0.0, 2.0]), mask=jnp.array([False, False, True]))
    traj = jaxrot.rollout(
        name, TUMBLING, MOMENTS, 0.01, 50, torque=gravity_torque, args=gravity_args(), drive=drive
    )
    np.testing.assert_array_equal(traj.omega[-1], jnp.array([0.0, 0.0, 2.0]))


def model_torque(t, q, omega, args):
    return jnp.array([0.3, -0.2, 0.1]) + gravity_torque(t, q, omega, args)


def model_with_z_set(t, q, omega, args):
    return model_torque(t, q, omega, args).at[2].set(-0.7)


@pytest.mark.parametrize("name", contract_params())
def test_imposed_moment_overrides_the_torque_model_on_that_component_only(name):
    drive = jaxrot.Drive.imposed_moment(jnp.array([0.0, 0.0, -0.7]), mask=jnp.array([False, False, True]))
    driven = jaxrot.rollout(
        name, TUMBLING, MOMENTS, 0.01, 100, torque=model_torque, args=gravity_args(), drive=drive
    )
    by_hand = jaxrot.rollout(name, TUMBLING, MOMENTS, 0.01, 100, torque=model_with_z_set, args=gravity_args())
    np.testing.assert_allclose(driven.q, by_hand.q, atol=1e-14)
    np.testing.assert_allclose(driven.omega, by_hand.omega, atol=1e-14)
    undriven = jaxrot.rollout(name, TUMBLING, MOMENTS, 0.01, 100, torque=model_torque, args=gravity_args())
    assert float(jnp.max(jnp.abs(undriven.omega - driven.omega))) > 1e-3  # the override matters


def test_imposed_moment_without_a_torque_model():
    drive = jaxrot.Drive.imposed_moment(jnp.array([0.0, 0.5, 0.0]), mask=jnp.array([False, True, False]))
    driven = jaxrot.rollout("zhao", TUMBLING, MOMENTS, 0.01, 50, drive=drive)
    by_hand = jaxrot.rollout(
        "zhao", TUMBLING, MOMENTS, 0.01, 50, torque=lambda t, q, w, a: jnp.array([0.0, 0.5, 0.0])
    )
    np.testing.assert_allclose(driven.q, by_hand.q, atol=1e-14)


@pytest.mark.parametrize("name", contract_params())
def test_per_particle_drives_leave_free_particles_untouched(name):
    states = jaxrot.RotState(jnp.stack([TUMBLING.q] * 3), jnp.stack([TUMBLING.omega] * 3))
    drive = jaxrot.Drive(
        omega_mask=jnp.array([[True, True, True], [False, False, False], [False, False, False]]),
        omega=jnp.stack([OMEGA_IMPOSED, jnp.zeros(3), jnp.zeros(3)]),
        moment_mask=jnp.array([[False, False, False], [False, False, True], [False, False, False]]),
        moment=jnp.stack([jnp.zeros(3), jnp.array([0.0, 0.0, -0.7]), jnp.zeros(3)]),
    )
    traj = jaxrot.rollout(
        name, states, MOMENTS, 0.01, 40, torque=model_torque, args=gravity_args(), drive=drive
    )
    free = jaxrot.rollout(name, TUMBLING, MOMENTS, 0.01, 40, torque=model_torque, args=gravity_args())
    moment = jaxrot.rollout(name, TUMBLING, MOMENTS, 0.01, 40, torque=model_with_z_set, args=gravity_args())
    np.testing.assert_array_equal(traj.omega[-1, 0], OMEGA_IMPOSED)
    np.testing.assert_allclose(traj.q[:, 1], moment.q, rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(traj.q[:, 2], free.q, rtol=1e-13, atol=1e-15)


@pytest.mark.parametrize(
    "drive, match",
    [
        (
            jaxrot.Drive(
                omega_mask=jnp.array([True, False, False]),
                omega=jnp.zeros(3),
                moment_mask=jnp.array([False, True, False]),
                moment=jnp.zeros(3),
            ),
            "may not mix",
        ),
        (jaxrot.Drive(omega_mask=jnp.array([1, 0, 0]), omega=jnp.zeros(3)), r"drive\.omega_mask.*boolean"),
        (jaxrot.Drive.imposed_velocity(jnp.zeros(4)), r"drive\.omega.*shape"),
        (jaxrot.Drive(omega_mask=jnp.array([True, False, False])), "given together"),
        (jaxrot.Drive.imposed_moment(jnp.array([jnp.nan, 0, 0]), jnp.array([True, False, False])), "NaN"),
        ("spin", "jaxrot.Drive"),
    ],
)
def test_bad_drives_raise_value_error(drive, match):
    with pytest.raises(ValueError, match=match):
        jaxrot.rollout("zhao", TUMBLING, MOMENTS, 0.01, 3, drive=drive)
