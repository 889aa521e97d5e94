"""`RotState.from_body` and `RotState.omega_body`: body-frame rates at the door, the pytree kept to
(q, omega), and MuJoCo's free joint (``qpos[3:7]`` scalar-first body → world, ``qvel[3:6]`` body
frame) read correctly."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import jaxrot
from jaxrot import quaternion as quat


EPS = float(np.finfo(np.float64).eps)
RNG = np.random.default_rng(7)
Q = quat.normalize(jnp.asarray(RNG.normal(size=(2, 5, 4))))
W_BODY = jnp.asarray(RNG.normal(size=(2, 5, 3)))


def assert_close(actual, expected, ulps=16):
    """Equal to ``ulps`` round-offs of the largest magnitude compared (a rotation mixes components)."""
    scale = max(1.0, float(np.max(np.abs(np.asarray(expected)))))
    np.testing.assert_allclose(actual, expected, rtol=0, atol=ulps * EPS * scale)


def test_from_body_rotates_to_the_world_frame_and_omega_body_back():
    """``omega = rotate(q, ω_b)`` (scipy's ``apply`` agrees), and ``omega_body`` inverts it to a few eps."""
    state = jaxrot.RotState.from_body(Q, W_BODY)
    assert (
        isinstance(state, jaxrot.RotState) and state.q.shape == (2, 5, 4) and state.omega.shape == (2, 5, 3)
    )
    np.testing.assert_array_equal(state.q, Q)
    expected = Rotation.from_quat(np.array(quat.to_xyzw(Q)).reshape(-1, 4)).apply(
        np.array(W_BODY).reshape(-1, 3)
    )
    assert_close(state.omega, expected.reshape(2, 5, 3), 16)
    assert_close(state.omega_body, W_BODY, 16)
    assert_close(jaxrot.RotState(Q, state.omega).omega_body, W_BODY, 16)


def test_leading_axes_broadcast():
    one_q, many_w = Q[0, 0], W_BODY[0]
    state = jaxrot.RotState.from_body(one_q, many_w)
    assert state.q.shape == (5, 4) and state.omega.shape == (5, 3)
    assert_close(state.omega[3], quat.rotate(one_q, many_w[3]), 4)
    state = jaxrot.RotState.from_body(Q[0], W_BODY[0, 0])
    assert state.q.shape == (5, 4) and state.omega.shape == (5, 3)


def test_non_unit_q_rotates_as_the_rotation_it_stands_for():
    """``q`` is kept as given (rollout checks or normalises it); ``omega`` is that of ``q / |q|``."""
    state = jaxrot.RotState.from_body(3 * Q, W_BODY)
    np.testing.assert_array_equal(state.q, 3 * Q)
    assert_close(state.omega, jaxrot.RotState.from_body(Q, W_BODY).omega, 16)
    assert_close(state.omega_body, W_BODY, 16)


@pytest.mark.parametrize(
    "q, w, match",
    [
        (jnp.ones(3), jnp.ones(3), r"`q` must have shape \(\.\.\., 4\)"),
        (jnp.ones(4), jnp.ones(4), r"`omega_body` must have shape \(\.\.\., 3\)"),
        (jnp.ones((2, 4)), jnp.ones((3, 3)), "broadcast"),
    ],
)
def test_bad_shapes_are_refused(q, w, match):
    with pytest.raises(ValueError, match=match):
        jaxrot.RotState.from_body(q, w)


def test_still_a_two_leaf_pytree_under_jit_vmap_scan_and_grad():
    """A classmethod and a property add no leaves: tree_util, vmap and scan see (q, omega) only."""
    state = jaxrot.RotState.from_body(Q, W_BODY)
    leaves, treedef = jax.tree_util.tree_flatten(state)
    assert len(leaves) == 2 and treedef == jax.tree_util.tree_structure(jaxrot.RotState(Q, W_BODY))
    assert state._fields == ("q", "omega") and len(state) == 2
    assert isinstance(jax.tree_util.tree_unflatten(treedef, leaves), jaxrot.RotState)

    vmapped = jax.vmap(jaxrot.RotState.from_body)(Q[0], W_BODY[0])
    assert_close(vmapped.omega, state.omega[0], 4)
    assert_close(jax.jit(lambda s: s.omega_body)(state), state.omega_body, 4)

    def spin(s, _):  # a body-frame rate held fixed while the body turns: omega follows it in the world
        q = quat.multiply(s.q, quat.exp(0.01 * s.omega_body))
        return jaxrot.RotState.from_body(q, s.omega_body), None

    final, _ = jax.lax.scan(spin, state, length=3)
    assert jax.tree_util.tree_structure(final) == treedef
    assert_close(final.omega_body, W_BODY, 64)

    # Gradients finite at the identity and at zero rate.
    grad_w = jax.grad(lambda w: jnp.sum(jaxrot.RotState.from_body(quat.identity(), w).omega ** 2))(
        jnp.zeros(3)
    )
    grad_q = jax.grad(lambda q: jnp.sum(jaxrot.RotState(q, jnp.zeros(3)).omega_body))(quat.identity())
    assert np.all(np.isfinite(grad_w)) and np.all(np.isfinite(grad_q))


def test_rollout_of_a_sphere_spins_about_the_body_rate():
    """An isotropic body keeps its world-frame rate: ``q(t) = q₀ ⊗ exp(ω_b t) = exp(ω t) ⊗ q₀``."""
    q0, w_body = Q[0, 0], W_BODY[0, 0]
    traj = jaxrot.rollout("zhao", jaxrot.RotState.from_body(q0, w_body), jnp.ones(3), 0.01, 20)
    expected = quat.multiply(q0, quat.exp(0.2 * w_body))
    assert float(quat.angle_between(traj.q[-1], expected)) < 1e-13
    np.testing.assert_allclose(jaxrot.RotState(traj.q[-1], traj.omega[-1]).omega_body, w_body, atol=1e-13)


def test_mujoco_free_joint_is_scalar_first_body_to_world_with_body_frame_rates():
    """MuJoCo (`doc/overview.rst`, "Floating objects": a free joint's rotational velocities are in the
    local body frame; `mj_integratePos` calls `mju_quatIntegrate`, ``q ← q ⊗ exp(ω dt)``). Checked on
    MuJoCo itself: its world-frame rate, one position update, and a symmetric top (moments 1, 1, 2)
    stepped 1000 times with RK4 against the closed form ``q(t) = exp(L t / I⊥) ⊗ q₀ ⊗ exp(−λ t e_z)``,
    ``λ = (I₃ − I⊥) ω_b,z / I⊥`` (Landau & Lifshitz §33), read with `from_body` / `omega_body`; and
    the frames of its two applied torques."""
    mujoco = pytest.importorskip("mujoco")
    xml = """<mujoco><option gravity="0 0 0" timestep="0.001" integrator="RK4"/><worldbody>
      <body><freejoint/><inertial pos="0 0 0" mass="1" diaginertia="1 1 2"/></body></worldbody></mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    q0, w_body = np.asarray(Q[1, 2]), np.array([0.4, 1.1, -0.7])
    data.qpos[3:7], data.qvel[3:6] = q0, w_body
    mujoco.mj_forward(model, data)
    state = jaxrot.RotState.from_body(jnp.asarray(data.qpos[3:7]), jnp.asarray(data.qvel[3:6]))

    world = np.zeros(6)  # [angular, linear], world frame (flg_local=0)
    mujoco.mj_objectVelocity(model, data, mujoco.mjtObj.mjOBJ_BODY, 1, world, 0)
    assert_close(state.omega, world[:3], 8)
    xmat = jnp.asarray(data.xmat[1].reshape(3, 3))  # body → world
    assert float(quat.angle_between(quat.from_matrix(xmat), state.q)) < 8 * EPS

    qpos = data.qpos.copy()
    mujoco.mj_integratePos(model, qpos, data.qvel, 1e-3)
    assert (
        float(quat.angle_between(jnp.asarray(qpos[3:7]), quat.multiply(state.q, quat.exp(1e-3 * w_body))))
        < 8 * EPS
    )

    for _ in range(1000):
        mujoco.mj_step(model, data)
    lam = (2.0 - 1.0) * w_body[2] / 1.0
    momentum = quat.rotate(state.q, jnp.array([1.0, 1.0, 2.0]) * w_body)
    spin = quat.exp(jnp.array([0.0, 0.0, -lam * data.time]))
    q_t = quat.multiply(quat.multiply(quat.exp(momentum * data.time), state.q), spin)
    after = jaxrot.RotState.from_body(jnp.asarray(data.qpos[3:7]), jnp.asarray(data.qvel[3:6]))
    # RK4 at dt = 1e-3 over 1 s: O(dt⁴) ~ 1e-12 (measured 6e-15); qvel read as world-frame: 0.96 rad off.
    assert float(quat.angle_between(after.q, q_t)) < 1e-10
    omega_body_t = quat.rotate(quat.conjugate(spin), jnp.asarray(w_body))
    np.testing.assert_allclose(after.omega_body, omega_body_t, atol=1e-10)
    np.testing.assert_allclose(after.omega, quat.rotate(q_t, omega_body_t), atol=1e-10)
    # qvel taken for a world-frame rate: the same closed form from that state ends far from MuJoCo's run.
    wrong = jaxrot.RotState(jnp.asarray(q0), jnp.asarray(w_body))
    w_wrong = wrong.omega_body
    spin_wrong = quat.exp(jnp.array([0.0, 0.0, -w_wrong[2] * data.time]))
    momentum_wrong = quat.rotate(wrong.q, jnp.array([1.0, 1.0, 2.0]) * w_wrong)
    q_wrong = quat.multiply(quat.multiply(quat.exp(momentum_wrong * data.time), wrong.q), spin_wrong)
    assert float(quat.angle_between(after.q, q_wrong)) > 0.5  # measured 0.96 rad

    # Torques: xfrc_applied[b, 3:6] is world frame, qfrc_applied[3:6] body frame (at rest: I ω̇_b = τ_b).
    torque = jnp.array([0.2, -0.5, 0.7])
    torque_body = np.asarray(quat.rotate(quat.conjugate(after.q), torque))
    data.qvel[:] = 0
    data.xfrc_applied[1, 3:6] = torque
    mujoco.mj_forward(model, data)
    np.testing.assert_allclose(data.qacc[3:6], torque_body / np.array([1.0, 1.0, 2.0]), rtol=0, atol=1e-12)
    data.xfrc_applied[:] = 0
    data.qfrc_applied[3:6] = torque_body
    mujoco.mj_forward(model, data)
    np.testing.assert_allclose(data.qacc[3:6], torque_body / np.array([1.0, 1.0, 2.0]), rtol=0, atol=1e-12)
