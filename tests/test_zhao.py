"""Zhao & van Wachem (2013): measured order, zero angular velocity, float32, torque calls."""

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
from jaxrot._scenes import gravity_torque, heavy_top


ZHAO = jaxrot.SCHEMES["zhao"]
TUMBLING = principal_state(omega_body=jnp.array([1.0, 2.0, 0.5]))


def time_dependent_torque(t, q, omega, amplitude):
    return amplitude * jnp.stack([jnp.sin(3 * t), jnp.cos(2 * t), jnp.ones_like(t) * 0.5])


def damping_torque(t, q, omega, c):
    return -c * omega


def test_metadata():
    assert ZHAO.name == "zhao"
    assert ZHAO.order == 2
    assert ZHAO.torque_evals_per_step == 2


@pytest.mark.parametrize("inertia_form", ["diagonal", "full"])
@pytest.mark.parametrize("torque_name", ["free", "gravity"])
def test_measured_order_is_two(inertia_form, torque_name):
    """Log-log slope of max orientation error against dt, reference at rtol=atol=1e-13."""
    torque = None if torque_name == "free" else gravity_torque
    if inertia_form == "diagonal":
        state, inertia = TUMBLING, MOMENTS
        args = None if torque is None else gravity_args()
    else:
        state, inertia = to_body_frame(TUMBLING), full_tensor()
        args = None if torque is None else gravity_args(r=PRINCIPAL_TO_BODY)
    dts, errors = order_errors(ZHAO, state, inertia, 4.0, 40, 5, torque, args)
    assert errors[-1] > 1e-9  # still far above the reference's own error
    assert fitted_order(dts, errors) == pytest.approx(2.0, abs=0.15)


@pytest.mark.parametrize(
    "torque, args",
    [(time_dependent_torque, jnp.asarray(2.0)), (damping_torque, jnp.asarray(0.5))],
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


def test_zero_angular_velocity_without_torque_is_at_rest_with_finite_gradients():
    q0 = quat.exp(jnp.array([0.2, -0.1, 0.4]))
    state = jaxrot.RotState(q0, jnp.zeros(3))
    traj = jaxrot.rollout(ZHAO, state, MOMENTS, 0.05, 50)
    np.testing.assert_array_equal(traj.omega, jnp.zeros_like(traj.omega))
    np.testing.assert_allclose(traj.q, jnp.broadcast_to(q0, traj.q.shape), atol=1e-15)

    weights = jnp.array([0.3, -0.7, 0.2, 0.5])

    def loss(omega0, inertia):
        out = jaxrot.rollout(ZHAO, jaxrot.RotState(q0, omega0), inertia, 0.05, 50)
        return jnp.sum(out.q[-1] * weights) + jnp.sum(out.omega[-1])

    for inertia in (MOMENTS, full_tensor()):
        g_omega, g_inertia = jax.grad(loss, argnums=(0, 1))(jnp.zeros(3), inertia)
        assert bool(jnp.all(jnp.isfinite(g_omega))) and bool(jnp.all(jnp.isfinite(g_inertia)))
        # At rest the inertia cannot matter: its gradient is exactly zero.
        np.testing.assert_array_equal(g_inertia, jnp.zeros_like(g_inertia))
        # d q_end / d omega0 at rest is nonzero: a small spin does move the body.
        assert float(jnp.linalg.norm(g_omega)) > 0


def test_batch_equals_each_particle_alone():
    """Particles do not interact: a batch agrees with each particle alone to 1e-13 (relative).

    Not bitwise: batched and single runs compile to different SIMD code, measured to differ
    by 1-2 ulp per step (|Δω| = 1.8e-15 after one step, 1.3e-13 after 20 at |ω| ≈ 5)."""
    rng = np.random.default_rng(1)
    n = 5
    q = quat.normalize(jnp.asarray(rng.normal(size=(n, 4))))
    omega = jnp.asarray(rng.normal(size=(n, 3)) * 2)
    inertia = jnp.asarray(rng.uniform(1.0, 2.0, size=(n, 3)))
    batch = jaxrot.rollout(
        ZHAO,
        jaxrot.RotState(q, omega),
        inertia,
        0.01,
        20,
        torque=gravity_torque,
        args=gravity_args(),
        save_every=10,
    )
    for i in range(n):
        alone = jaxrot.rollout(
            ZHAO,
            jaxrot.RotState(q[i], omega[i]),
            inertia[i],
            0.01,
            20,
            torque=gravity_torque,
            args=gravity_args(),
            save_every=10,
        )
        np.testing.assert_allclose(batch.q[:, i], alone.q, rtol=1e-13, atol=1e-15)
        np.testing.assert_allclose(batch.omega[:, i], alone.omega, rtol=1e-13, atol=1e-15)


def test_float32_in_float32_out_and_unit_norm_after_1000_steps():
    s32, s64 = heavy_top(dtype=jnp.float32), heavy_top()
    traj = jaxrot.rollout(ZHAO, s32.state, s32.inertia, 0.005, 1000, torque=s32.torque, args=s32.args)
    assert traj.q.dtype == traj.omega.dtype == traj.t.dtype == jnp.float32
    assert float(jnp.max(jnp.abs(jnp.linalg.norm(traj.q, axis=-1) - 1))) < 1e-5

    traj64 = jaxrot.rollout(ZHAO, s64.state, s64.inertia, 0.005, 1000, torque=s64.torque, args=s64.args)
    ref = jaxrot.reference_rollout(
        s64.state, s64.inertia, traj64.t[::100], torque=s64.torque, args=s64.args, rtol=1e-13, atol=1e-13
    )
    err32 = float(jnp.max(quat.angle_between(traj.q[::100].astype(jnp.float64), ref.q)))
    err64 = float(jnp.max(quat.angle_between(traj64.q[::100], ref.q)))
    # At this dt float32 round-off stays below the scheme's own truncation error
    # (measured 3.8e-4 against 3.1e-4 rad at t = 5).
    assert err32 < 1.5 * err64


def test_torque_is_called_twice_per_step_and_none_never():
    calls = []

    def counting_torque(t, q, omega, args):
        jax.debug.callback(lambda t: calls.append(float(t)), t)
        return jnp.zeros(3)

    jax.block_until_ready(jaxrot.rollout(ZHAO, TUMBLING, MOMENTS, 0.1, 7, torque=counting_torque, t0=1.0))
    assert len(calls) == ZHAO.torque_evals_per_step * 7
    # Start-of-step and midpoint times: t, t + dt/2 for each step.
    expected = sorted([1.0 + 0.1 * k for k in range(7)] + [1.05 + 0.1 * k for k in range(7)])
    np.testing.assert_allclose(sorted(calls), expected, atol=1e-12)


def test_step_is_usable_alone_and_matches_rollout():
    state = TUMBLING
    for _ in range(3):
        state = ZHAO.step(state, 0.0, 0.02, MOMENTS, None, None)
    traj = jaxrot.rollout(ZHAO, TUMBLING, MOMENTS, 0.02, 3)
    np.testing.assert_allclose(state.q, traj.q[-1], atol=1e-15)
    np.testing.assert_allclose(state.omega, traj.omega[-1], atol=1e-15)
