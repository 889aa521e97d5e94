"""Telemetry made by MuJoCo: a free body with a full inertia tensor under body-frame torques held per step.

The identification comparison with `mujoco.sysid` (issue 53) fits data that MuJoCo itself made, so
that neither side is fitted to its own integrator. The model (`model_xml`):

- one body on a free joint, gravity and contacts off, mass 1, centre of mass at the body origin, the
  inertia tensor `INERTIA` given as ``fullinertia`` in the body frame;
- three ``motor`` actuators on the free joint with gears ``e₃``, ``e₄``, ``e₅``: a free joint's
  rotational dofs ``qvel[3:6]`` are the **body-frame** angular velocity, so ``ctrl`` is the
  body-frame torque (checked in tests/test_mujoco_telemetry.py against ``I⁻¹ τ``);
- sensors ``framequat`` with ``objtype="xbody"`` (the body frame: ``"body"`` would report the
  principal frame, MuJoCo's ``iquat``) and ``gyro`` at a site at the body origin with no rotation;
- RK4 at `TIMESTEP`, the sensors read every `SAMPLE_EVERY` steps (100 Hz).

Time stamps, MuJoCo's trap: ``mj_step`` computes the sensors in its ``mj_forward`` *before* it
integrates, so the row ``mujoco.rollout`` records after step ``k`` (whose ``state`` time is
``(k + 1)·dt``) holds the state at ``k·dt``. Every sample here carries the time of the state it
measures: sensor row ``k`` → ``t = k·dt``. The control ``ctrl[k]`` acts, constant in the body frame
through all four RK4 stages, over ``[k·dt, (k + 1)·dt)``: ``control=(t_c, tau_c)`` with ``t_c = k·dt``
and ``control_hold="previous"``, ``control_frame="body"`` in jaxrot's terms.

Inertia, MuJoCo's other trap: a compiled model stores principal moments ``body_inertia`` and the
principal frame's orientation ``body_iquat``; the tensor in the body frame is ``R diag(m) Rᵀ``
(`body_frame_inertia`), which equals the ``fullinertia`` given to round-off.

Needs ``mujoco`` (``pip install -e ".[mujoco]"``); the module imports without it, and its
functions then raise an ImportError that says so.
"""

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

import jaxrot
from jaxrot import quaternion as quat


try:
    import mujoco
    from mujoco import rollout as mj_rollout
except ImportError:  # the tests that need it skip; jaxrot itself does not
    mujoco = mj_rollout = None


# Body frame, kg m²: a small satellite's moments with products of inertia of 5-8 % of them.
INERTIA = np.array([[0.040, 0.003, -0.002], [0.003, 0.050, 0.0025], [-0.002, 0.0025, 0.060]])
TIMESTEP = 1e-3  # s
SAMPLE_EVERY = 10  # steps between sensor readings: 100 Hz
DURATION = 10.0  # s per manoeuvre
SEEDS = (0, 1, 2)  # one manoeuvre per seed
SIGMA_Q = 1e-4  # rad per axis, a star tracker
SIGMA_OMEGA = 1e-4  # rad/s per axis, a gyro
TORQUE_AMPLITUDE = 2e-3  # N m, per sinusoid of the excitation
SPIN = 0.2  # rad/s, standard deviation of each initial body-frame rate


class Manoeuvre(NamedTuple):
    """One manoeuvre's record, every time the time of the state it belongs to.

    Fields: ``t`` ``(n,)`` sample times (s); ``q`` ``(n, 4)`` orientations (scalar first, body →
    world; the sign MuJoCo's integration carries, continuous in time); ``omega_body`` ``(n, 3)``
    gyro readings (rad/s, body frame); ``t_c`` ``(m,)`` the start of each MuJoCo step and
    ``tau_c`` ``(m, 3)`` the body-frame torque (N m) held over it; ``q0`` ``(4,)`` and
    ``omega_body0`` ``(3,)`` the true initial state; ``sigma_q``, ``sigma_omega`` the noise
    levels added (0.0 for noise-free data).
    """

    t: np.ndarray
    q: np.ndarray
    omega_body: np.ndarray
    t_c: np.ndarray
    tau_c: np.ndarray
    q0: np.ndarray
    omega_body0: np.ndarray
    sigma_q: float = 0.0
    sigma_omega: float = 0.0

    def experiment_kwargs(self):
        """Keyword arguments of ``jaxrot.Experiment`` for this record (noise-free: σ left to the fit).

        ``jaxrot.Experiment(**m.experiment_kwargs())`` once `Experiment` takes ``control_frame``
        and ``control_hold`` (issue 53).
        """
        sigmas = {}
        if self.sigma_q > 0:
            sigmas = {"sigma_q": self.sigma_q, "sigma_omega": self.sigma_omega}
        return {
            "t": self.t,
            "q": self.q,
            "omega_body": self.omega_body,
            "control": (self.t_c, self.tau_c),
            "control_frame": "body",
            "control_hold": "previous",
            **sigmas,
        }


def _require_mujoco():
    if mujoco is None:
        raise ImportError('MuJoCo is not installed: pip install -e ".[mujoco]" (mujoco[sysid] >= 4.0)')


def model_xml(inertia=INERTIA, timestep=TIMESTEP):
    """The MJCF of the free body (module docstring); ``inertia`` ``(3, 3)`` body frame, kg m²."""
    i = np.asarray(inertia, dtype=float)
    full = " ".join(repr(float(x)) for x in (i[0, 0], i[1, 1], i[2, 2], i[0, 1], i[0, 2], i[1, 2]))
    return f"""<mujoco model="free_body">
  <option timestep="{timestep!r}" integrator="RK4" gravity="0 0 0">
    <flag contact="disable"/>
  </option>
  <worldbody>
    <body name="body">
      <freejoint name="free"/>
      <inertial pos="0 0 0" mass="1" fullinertia="{full}"/>
      <site name="imu"/>
    </body>
  </worldbody>
  <actuator>
    <motor name="torque_x" joint="free" gear="0 0 0 1 0 0"/>
    <motor name="torque_y" joint="free" gear="0 0 0 0 1 0"/>
    <motor name="torque_z" joint="free" gear="0 0 0 0 0 1"/>
  </actuator>
  <sensor>
    <framequat name="orientation" objtype="xbody" objname="body"/>
    <gyro name="gyro" site="imu"/>
  </sensor>
</mujoco>
"""


def body_frame_inertia(model, body="body"):
    """The inertia tensor ``(3, 3)`` of a compiled model's body in its body (xbody) frame.

    MuJoCo keeps principal moments ``m = body_inertia`` and the principal frame's orientation
    ``body_iquat``: the tensor is ``R diag(m) Rᵀ`` with ``R`` the rotation of ``body_iquat``.
    """
    _require_mujoco()
    b = model.body(body)
    rotation = np.empty(9)
    mujoco.mju_quat2Mat(rotation, b.iquat)
    rotation = rotation.reshape(3, 3)
    return rotation @ np.diag(b.inertia) @ rotation.T


def true_inertia(inertia=INERTIA):
    """The tensor MuJoCo integrates when given ``inertia`` (`body_frame_inertia` of `model_xml`'s model):
    ``inertia`` to MuJoCo's eigendecomposition (5e-16 for `INERTIA`; its stopping test is 1e-12)."""
    _require_mujoco()
    return body_frame_inertia(mujoco.MjModel.from_xml_string(model_xml(inertia)))


def initial_state(seed):
    """``(q0, omega_body0)`` of manoeuvre ``seed``: a random orientation and body rates of ~`SPIN`."""
    rng = np.random.default_rng(1000 + seed)
    q0 = rng.normal(size=4)
    return q0 / np.linalg.norm(q0), SPIN * rng.normal(size=3)


def torque_profile(seed, n_steps, dt=TIMESTEP):
    """Body-frame torques ``(n_steps, 3)`` (N m) held over each step: per axis three sinusoids of
    0.05-0.5 Hz with random phases, sampled at the start of each step."""
    rng = np.random.default_rng(2000 + seed)
    t = np.arange(n_steps) * dt
    freq = rng.uniform(0.05, 0.5, size=(3, 3))  # (sinusoid, axis), Hz
    phase = rng.uniform(0.0, 2 * np.pi, size=(3, 3))
    return TORQUE_AMPLITUDE * np.sin(2 * np.pi * freq[None] * t[:, None, None] + phase[None]).sum(axis=1)


def simulate(model, q0, omega_body0, tau_c):
    """MuJoCo's rollout from ``(q0, omega_body0)`` under the held torques ``tau_c`` ``(m, 3)``.

    Returns the sensor rows ``(m, 7)`` (orientation, gyro) with their true times ``k·dt``
    (row ``k`` holds the state at the start of step ``k``: the module docstring), and the state
    rows ``(m, 14)`` (time after the step, qpos, qvel).
    """
    _require_mujoco()
    data = mujoco.MjData(model)
    data.qpos[3:7] = q0
    data.qvel[3:6] = omega_body0
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    state0 = np.empty(mujoco.mj_stateSize(model, spec))
    mujoco.mj_getState(model, data, state0, spec)
    state, sensors = mj_rollout.rollout(model, data, state0, np.asarray(tau_c, dtype=float))
    return np.arange(len(tau_c)) * model.opt.timestep, sensors[0], state[0]


@functools.lru_cache(maxsize=8)
def _records(seeds, duration, inertia_key):
    inertia = np.asarray(inertia_key).reshape(3, 3)
    model = mujoco.MjModel.from_xml_string(model_xml(inertia))
    n_steps = int(round(duration / TIMESTEP))
    records = []
    for seed in seeds:
        q0, omega_body0 = initial_state(seed)
        # One step more than the duration: its sensor row is the state at `duration`.
        tau_c = torque_profile(seed, n_steps + 1)
        t, sensors, _ = simulate(model, q0, omega_body0, tau_c)
        rows = slice(0, n_steps + 1, SAMPLE_EVERY)
        records.append(
            Manoeuvre(
                t=t[rows],
                q=sensors[rows, :4],
                omega_body=sensors[rows, 4:7],
                t_c=t[:n_steps],
                tau_c=tau_c[:n_steps],
                q0=q0,
                omega_body0=omega_body0,
            )
        )
    return tuple(records)


def manoeuvres(seeds=SEEDS, *, duration=DURATION, inertia=INERTIA, noise_seed=None, sigma_q=SIGMA_Q,
               sigma_omega=SIGMA_OMEGA):  # fmt: skip
    """One `Manoeuvre` per seed, made by MuJoCo (RK4, 1 ms) with the true `INERTIA`.

    ``noise_seed=None``: noise-free. Otherwise every orientation is turned by a body-frame
    rotation vector with ``sigma_q`` rad per axis, ``q ⊗ exp(n)``, and every gyro reading gets
    ``sigma_omega`` rad/s per axis, drawn from ``numpy.random.default_rng(noise_seed)``. The
    controls are known exactly. The noise-free records are cached per (seeds, duration, inertia).
    """
    _require_mujoco()
    clean = _records(tuple(seeds), float(duration), tuple(np.asarray(inertia, dtype=float).ravel()))
    if noise_seed is None:
        return list(clean)
    rng = np.random.default_rng(noise_seed)
    noisy = []
    for m in clean:
        turn = quat.exp(jnp.asarray(rng.normal(size=(len(m.t), 3)) * sigma_q))
        noisy.append(
            m._replace(
                q=np.asarray(quat.multiply(jnp.asarray(m.q), turn)),
                omega_body=m.omega_body + rng.normal(size=m.omega_body.shape) * sigma_omega,
                sigma_q=sigma_q,
                sigma_omega=sigma_omega,
            )
        )
    return noisy


def replay(manoeuvre, inertia=INERTIA, substeps=2):
    """jaxrot's trajectory ``(q (n, 4), omega_body (n, 3))`` at the sample times under the same held torques.

    Each MuJoCo step is integrated by ``substeps`` steps of ``rkmk_dopri8`` whose torque is that
    step's body-frame torque turned into the world, ``rotate(q, τ_k)``, in every stage: the held
    control with no stage straddling a switch. The scheme's carry (state and angular momentum)
    holds no torque, so it passes from one control step to the next unchanged (re-initialising it
    every step instead costs ~1e-16 rad of round-off per step: 2e-13 rad after 2 s, measured).
    Two sub-steps of 0.5 ms err by ~1e-15 rad over 10 s (order 8), so the difference from MuJoCo's
    record is MuJoCo's own error. (`jaxrot.reference_rollout` with a torque callable that holds the
    sample at or before ``t`` is no such check: its adaptive steps straddle the switches, and it
    erred by 3e-10 rad after 1 s at rtol = atol = 1e-12, 7e-8 at 1e-10, measured.)
    """
    m = manoeuvre
    scheme = jaxrot.SCHEMES["rkmk_dopri8"]
    inertia = jaxrot.body_inertia(jnp.asarray(inertia))
    dt = float(m.t_c[1] - m.t_c[0]) / substeps

    def torque(t, q, omega, tau_b):
        return quat.rotate(q, tau_b)

    def one_control_step(carry, control):
        t0, tau_b = control
        for i in range(substeps):
            carry = scheme.step(carry, t0 + i * dt, dt, inertia, torque, tau_b)
        state = scheme.state(carry)
        return carry, state

    q0 = jnp.asarray(m.q0)
    state0 = jaxrot.RotState(q0, quat.rotate(q0, jnp.asarray(m.omega_body0)))
    carry0 = scheme.init(state0, m.t_c[0], inertia, torque, jnp.asarray(m.tau_c[0]))
    _, states = jax.jit(lambda c, u: jax.lax.scan(one_control_step, c, u))(
        carry0, (jnp.asarray(m.t_c), jnp.asarray(m.tau_c))
    )
    # Row k of `states` is the state at t_c[k] + substeps·dt; the initial state goes first.
    q = jnp.concatenate([q0[None], states.q])
    omega = jnp.concatenate([state0.omega[None], states.omega])
    every = int(round((m.t[1] - m.t[0]) / (m.t_c[1] - m.t_c[0])))
    q, omega = q[::every], omega[::every]
    return np.asarray(q), np.asarray(quat.rotate(quat.conjugate(q), omega))


# Real sensors on MuJoCo's data (issue 74's profile): a gyro bias per manoeuvre, a gyro scale factor and
# delay, a tracker mounted at a small rotation of the body frame and with a delay of its own. Delays
# are whole MuJoCo steps, so a delayed reading is an exact MuJoCo row.
TRUE_SENSORS = {
    "gyro_bias": np.array([[2.0e-3, -1.0e-3, 1.5e-3], [-3.0e-3, 2.0e-3, 0.5e-3], [1.0e-3, 1.0e-3, -2.5e-3]]),
    "gyro_scale": np.array([1.002, 0.999, 1.0015]),
    "gyro_delay": np.array(0.004),
    "tracker_mount": np.array([0.01, -0.02, 0.005]),
    "tracker_delay": np.array(0.007),
}


def sensor_manoeuvres(seeds=SEEDS, *, duration=DURATION, noise_seed=None, sensors=None):
    """`manoeuvres` seen through the flawed sensors ``sensors`` (default `TRUE_SENSORS`).

    Tracker reading ``q(t − tracker_delay) ⊗ exp(tracker_mount)``, gyro reading
    ``gyro_scale ⊙ ω_b(t − gyro_delay) + gyro_bias[i]`` (`jaxrot.identify`'s sensor models), then the
    noise of `manoeuvres` (σ = `SIGMA_Q`, `SIGMA_OMEGA`). The samples are at 100 Hz from the first
    whose delayed readings fall inside the record; ``q0``, ``omega_body0`` are the state there.
    """
    _require_mujoco()
    s = TRUE_SENSORS if sensors is None else sensors
    model = mujoco.MjModel.from_xml_string(model_xml(INERTIA))
    n_steps = int(round(duration / TIMESTEP))
    lag = [int(round(float(s[name]) / TIMESTEP)) for name in ("tracker_delay", "gyro_delay")]
    rng = None if noise_seed is None else np.random.default_rng(noise_seed)
    mount = quat.exp(jnp.asarray(s["tracker_mount"]))
    out = []
    for i, seed in enumerate(seeds):
        q0, omega_body0 = initial_state(seed)
        tau_c = torque_profile(seed, n_steps + 1)
        t, rows, _ = simulate(model, q0, omega_body0, tau_c)
        k = np.arange(SAMPLE_EVERY, n_steps + 1, SAMPLE_EVERY)  # every reading's delayed row exists
        q = np.asarray(quat.multiply(jnp.asarray(rows[k - lag[0], :4]), mount))
        gyro = s["gyro_scale"] * rows[k - lag[1], 4:7] + s["gyro_bias"][i]
        if rng is not None:
            turn = quat.exp(jnp.asarray(rng.normal(size=(k.size, 3)) * SIGMA_Q))
            q = np.asarray(quat.multiply(jnp.asarray(q), turn))
            gyro = gyro + rng.normal(size=gyro.shape) * SIGMA_OMEGA
        noisy = rng is not None
        out.append(
            Manoeuvre(
                t=t[k], q=q, omega_body=gyro, t_c=t[:n_steps], tau_c=tau_c[:n_steps], q0=rows[k[0], :4],
                omega_body0=rows[k[0], 4:7], sigma_q=SIGMA_Q if noisy else 0.0,
                sigma_omega=SIGMA_OMEGA if noisy else 0.0,
            )
        )  # fmt: skip
    return out
