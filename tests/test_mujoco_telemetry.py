"""MuJoCo's free-body telemetry (`_mujoco_telemetry`) and the `mujoco.sysid` fit of it (`_mujoco_sysid`).

What is checked: the frames and time stamps the data module relies on (numerically, on MuJoCo
itself), that jaxrot reproduces MuJoCo's record under the same held body-frame torques, the noise
model, and that sysid as written recovers the inertia. Skipped where ``mujoco`` is not installed
(``pip install -e ".[mujoco]"``).
"""

import inspect

import numpy as np
import pytest


# All in the slow set: .ci/run installs MuJoCo for it (README's quick start does not), so these would
# be skipped in CI's default run.
pytestmark = pytest.mark.slow
mujoco = pytest.importorskip("mujoco")

import _mujoco_telemetry as mt  # noqa: E402
import jax.numpy as jnp  # noqa: E402

import jaxrot  # noqa: E402
from jaxrot import quaternion as quat  # noqa: E402


EPS = np.finfo(np.float64).eps


@pytest.fixture(scope="module")
def model():
    return mujoco.MjModel.from_xml_string(mt.model_xml())


def _rotation(q):
    out = np.empty(9)
    mujoco.mju_quat2Mat(out, np.asarray(q, dtype=float))
    return out.reshape(3, 3)


def _angles(a, b):
    return np.asarray(quat.angle_between(jnp.asarray(a), jnp.asarray(b)))


def test_body_frame_inertia_rebuilds_the_given_tensor(model):
    """MuJoCo stores principal moments and ``iquat``; ``R diag(m) Rᵀ`` is the ``fullinertia`` given."""
    inertia = mt.body_frame_inertia(model)
    # MuJoCo's eigendecomposition (mju_eig3) stops once the off-diagonal is below 1000·mjMINVAL = 1e-12.
    np.testing.assert_allclose(inertia, mt.INERTIA, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(mt.true_inertia(), inertia)
    assert np.abs(np.diag(model.body("body").inertia) - mt.INERTIA).max() > 1e-3  # not the tensor


def test_frames_of_the_actuators_and_sensors(model):
    """ctrl is the body-frame torque, ``framequat`` of the xbody is qpos's quaternion (of the
    principal frame for objtype "body"), and the gyro reads ``qvel[3:6]``, the body-frame rate."""
    data = mujoco.MjData(model)
    rng = np.random.default_rng(0)
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    omega_body, tau_body = rng.normal(size=3) * 0.3, rng.normal(size=3) * 5e-3
    data.qpos[3:7], data.qvel[3:6], data.ctrl[:] = q, omega_body, tau_body
    mujoco.mj_forward(model, data)
    inertia = mt.INERTIA
    expected = np.linalg.solve(inertia, tau_body - np.cross(omega_body, inertia @ omega_body))
    # MuJoCo factorises the mass matrix in the principal frame: ~100 ulps of the acceleration.
    np.testing.assert_allclose(data.qacc[3:6], expected, rtol=0, atol=1e3 * EPS * np.abs(expected).max())
    as_world = np.linalg.solve(
        inertia, _rotation(q).T @ tau_body - np.cross(omega_body, inertia @ omega_body)
    )
    assert np.abs(data.qacc[3:6] - as_world).max() > 1e-2  # the world-frame reading is far off
    np.testing.assert_array_equal(data.sensor("orientation").data, data.xquat[1])
    np.testing.assert_allclose(data.sensor("orientation").data, q, rtol=0, atol=4 * EPS)
    np.testing.assert_allclose(data.sensor("gyro").data, omega_body, rtol=0, atol=4 * EPS)
    # objtype="body" reports the principal frame, q ⊗ iquat: not the body's orientation.
    with_body = mujoco.MjModel.from_xml_string(mt.model_xml().replace('objtype="xbody"', 'objtype="body"'))
    data_body = mujoco.MjData(with_body)
    data_body.qpos[3:7] = q
    mujoco.mj_forward(with_body, data_body)
    principal = np.empty(4)
    mujoco.mju_mulQuat(principal, q, with_body.body("body").iquat)
    np.testing.assert_allclose(data_body.sensor("orientation").data, principal, rtol=0, atol=8 * EPS)
    assert _angles(data_body.sensor("orientation").data, q) > 0.1


def test_a_sensor_row_holds_the_state_before_its_step(model):
    """``mujoco.rollout``'s sensor row k (state time (k + 1)·dt) holds the state at k·dt."""
    q0, omega_body0 = mt.initial_state(0)
    tau = mt.torque_profile(0, 5)
    t, sensors, state = mt.simulate(model, q0, omega_body0, tau)
    np.testing.assert_allclose(state[:, 0], (np.arange(5) + 1) * mt.TIMESTEP, rtol=1e-14)
    np.testing.assert_array_equal(t, np.arange(5) * mt.TIMESTEP)
    np.testing.assert_allclose(sensors[0, :4], q0, rtol=0, atol=4 * EPS)
    np.testing.assert_allclose(sensors[0, 4:], omega_body0, rtol=0, atol=4 * EPS)
    np.testing.assert_allclose(sensors[1:, :4], state[:-1, 4:8], rtol=0, atol=4 * EPS)
    np.testing.assert_allclose(sensors[1:, 4:], state[:-1, 11:14], rtol=0, atol=4 * EPS)
    assert np.abs(sensors[1:, :4] - state[1:, 4:8]).max() > 1e-5  # not the state after the step


def test_manoeuvre_layout_and_noise():
    """Sample and control times, the true initial state in the first row, and the noise levels."""
    clean = mt.manoeuvres(duration=1.0)
    noisy = mt.manoeuvres(duration=1.0, noise_seed=3)
    for m, n in zip(clean, noisy, strict=True):
        np.testing.assert_allclose(m.t, np.arange(101) * 0.01, rtol=0, atol=1e-15)
        np.testing.assert_allclose(m.t_c, np.arange(1000) * 1e-3, rtol=0, atol=1e-15)
        assert m.tau_c.shape == (1000, 3) and m.q.shape == (101, 4) and m.omega_body.shape == (101, 3)
        np.testing.assert_allclose(m.q[0], m.q0, rtol=0, atol=4 * EPS)
        np.testing.assert_allclose(m.omega_body[0], m.omega_body0, rtol=0, atol=4 * EPS)
        np.testing.assert_array_equal(n.tau_c, m.tau_c)
    turn = np.concatenate(
        [
            np.asarray(quat.log(quat.multiply(quat.conjugate(jnp.asarray(m.q)), jnp.asarray(n.q))))
            for m, n in zip(clean, noisy, strict=True)
        ]  # fmt: skip
    )
    gyro = np.concatenate([n.omega_body - m.omega_body for m, n in zip(clean, noisy, strict=True)])
    # 909 samples per axis: a sample standard deviation is within 5 % of σ with probability > 0.99.
    np.testing.assert_allclose(turn.std(axis=0), mt.SIGMA_Q, rtol=0.05)
    np.testing.assert_allclose(gyro.std(axis=0), mt.SIGMA_OMEGA, rtol=0.05)
    assert noisy[0].sigma_q == mt.SIGMA_Q and clean[0].sigma_q == 0.0


def test_experiment_kwargs_build_a_jaxrot_experiment():
    if "control_frame" not in inspect.signature(jaxrot.Experiment).parameters:
        pytest.skip("jaxrot.Experiment has no control_frame / control_hold yet (issue 53)")
    m = mt.manoeuvres(duration=1.0, noise_seed=0)[0]
    jaxrot.Experiment(**m.experiment_kwargs())


def test_jaxrot_reproduces_mujocos_record():
    """jaxrot under the same held body-frame torques (`replay`) follows MuJoCo's RK4 record (1 ms,
    2 s) to round-off: ~1e-16 rad per step on each side, 2000 steps, bound 10 ulps a step. RK4's
    own error at 1 ms is below that on this body (|ω| dt ~ 3e-4): 1.1e-13 rad after 10 s, measured."""
    m = mt.manoeuvres(seeds=(0,), duration=2.0)[0]
    q, omega_body = mt.replay(m)
    steps = len(m.t_c)
    assert _angles(q, m.q).max() < 10 * steps * EPS
    np.testing.assert_allclose(omega_body, m.omega_body, rtol=0, atol=10 * steps * EPS)
