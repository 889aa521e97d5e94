"""Synthetic telemetry for the identification tests, made by the package's reference solver (Dopri8)."""

import functools

import jax
import jax.numpy as jnp
import numpy as np

import jaxrot
from jaxrot import quaternion as quat


# A small satellite (kg m², body frame): moments ~0.03-0.05 with products of inertia.
SATELLITE_INERTIA = np.array([[0.040, 0.002, -0.001], [0.002, 0.050, 0.0015], [-0.001, 0.0015, 0.060]])
SATELLITE_DIPOLE = np.array([0.03, -0.02, 0.015])  # residual magnetic dipole, A m², body frame
FIELD = 3e-5  # T


def field(t):
    """The geomagnetic field along the orbit, world frame (T): a slow rotation of period 5400 s."""
    a = 2 * jnp.pi * t / 5400.0
    return FIELD * jnp.stack([jnp.cos(a), 0.3 * jnp.ones_like(a), jnp.sin(a)])


def dipole_torque(t, q, omega, args):
    """The residual dipole's torque ``R m × B`` (world frame)."""
    return jnp.cross(quat.rotate(q, args["dipole"]), field(t))


def _interp(t, t_c, tau_c):
    return jax.vmap(lambda column: jnp.interp(t, t_c, column), in_axes=1)(tau_c)


def _controlled_torque(t, q, omega, args):
    """The dipole's torque plus the sampled control ``args["tau_c"]`` at ``args["t_c"]``: one torque
    function for the three manoeuvres, so that their reference solves share one compiled program."""
    return dipole_torque(t, q, omega, args) + _interp(t, args["t_c"], args["tau_c"])


@functools.lru_cache(maxsize=4)
def satellite_records(n=121, duration=600.0):
    """The three manoeuvres without noise: ``(t, q, omega_body, t_c, tau_c, q0, omega0)`` each.

    Every noise seed shares them (the reference solve is the slow part of a seed).
    """
    records = []
    starts = [(0.02, -0.01, 0.03), (-0.03, 0.02, 0.01), (0.01, 0.035, -0.02)]
    for i, w in enumerate(starts):
        q0 = quat.normalize(jnp.asarray(np.random.default_rng(100 + i).normal(size=4)))
        omega0 = jnp.asarray(w)
        t = np.linspace(0.0, duration, n)
        t_c = np.linspace(0.0, duration, 13)
        commanded = np.random.default_rng(200 + i).normal(size=(13, 3)) * 0.2  # A m², world frame
        # A world-frame control torque: the commanded dipole crossed with the field, sampled.
        tau_c = np.cross(commanded, np.asarray(jax.vmap(field)(jnp.asarray(t_c))))

        ref = jaxrot.reference_rollout(
            jaxrot.RotState(q0, omega0),
            jnp.asarray(SATELLITE_INERTIA),
            jnp.asarray(t),
            torque=_controlled_torque,
            args={
                "dipole": jnp.asarray(SATELLITE_DIPOLE),
                "t_c": jnp.asarray(t_c),
                "tau_c": jnp.asarray(tau_c),
            },
        )
        omega_body = np.asarray(quat.rotate(quat.conjugate(ref.q), ref.omega))
        records.append((t, np.asarray(ref.q), omega_body, t_c, tau_c, np.asarray(q0), np.asarray(omega0)))
    return tuple(records)


def satellite_experiments(seed, *, n=121, duration=600.0, sigma_q=1e-4, sigma_omega=2e-5, noise=True):
    """Three manoeuvres of the satellite: star tracker + gyro, known magnetorquer torques.

    Star-tracker noise is a body-frame rotation vector with ``sigma_q`` rad per axis; gyro noise
    ``sigma_omega`` rad/s per axis. Returns ``(experiments, truth)``; ``truth`` holds the inertia,
    the dipole and each start state.
    """
    rng = np.random.default_rng(seed)
    truth = {"inertia": SATELLITE_INERTIA, "dipole": SATELLITE_DIPOLE, "q0": [], "omega0": []}
    experiments = []
    for t, q, omega_body, t_c, tau_c, q0, omega0 in satellite_records(n, duration):
        if noise:
            q = np.asarray(
                quat.multiply(jnp.asarray(q), quat.exp(jnp.asarray(rng.normal(size=(n, 3)) * sigma_q)))
            )
            omega_body = omega_body + rng.normal(size=(n, 3)) * sigma_omega
        experiments.append(
            jaxrot.Experiment(
                t, q=q, omega_body=omega_body, sigma_q=sigma_q, sigma_omega=sigma_omega, control=(t_c, tau_c)
            )
        )
        truth["q0"].append(q0)
        truth["omega0"].append(omega0)
    return experiments, truth


# The real-sensor satellite: the same body and field, sensors with the flaws of flight hardware.
TRUE_SENSORS = {
    "gyro_bias": np.array([[2.0e-4, -1.0e-4, 1.5e-4], [-3.0e-4, 2.0e-4, 0.5e-4], [1.0e-4, 1.0e-4, -2.5e-4]]),
    "gyro_scale": np.array([1.002, 0.999, 1.0015]),
    "gyro_delay": np.array(0.4),
    "tracker_mount": np.array([0.01, -0.02, 0.005]),
    "tracker_delay": np.array(0.25),
}
# (frame, hold) of each manoeuvre's control: the four options, a body-frame one twice (held, and
# interpolated), and the world frame's two.
CONTROLS = (("world", "linear"), ("body", "previous"), ("world", "previous"), ("body", "linear"))
PRE_ROLL = 2.0  # s of motion before the first sample: a delayed sensor's first reading sees it


def _control_value(t, t_c, tau_c, held):
    """``tau_c`` at ``t``: linear between the samples (held outside), or each sample held until the next
    (zero before the first)."""
    linear = _interp(t, t_c, tau_c)
    index = jnp.searchsorted(t_c, t, side="right") - 1
    previous = jnp.where(index >= 0, tau_c[jnp.maximum(index, 0)], 0.0)
    return jnp.where(held, previous, linear)


def _sensor_torque(t, q, omega, args):
    """Dipole, a constant world torque ``thruster``, a drag ``−drag ω``, and the control (world or body
    frame, linear or held): one function for every manoeuvre, so their solves share one program."""
    control = _control_value(t, args["t_c"], args["tau_c"], args["held"])
    control = jnp.where(args["body"], quat.rotate(q, control), control)
    return dipole_torque(t, q, omega, args) + args["thruster"] - args["drag"] * omega + control


def sensor_torque(t, q, omega, args):
    """The torque model identify fits: dipole, thruster and drag (the control is the Experiment's)."""
    return dipole_torque(t, q, omega, args) + args["thruster"] - args["drag"] * omega


@functools.lru_cache(maxsize=8)
def sensor_records(
    controls=CONTROLS[:3], n=121, duration=600.0, thrusters=None, drags=None, delays=(0.25, 0.4)
):
    """Noise-free manoeuvres for `sensor_experiments`: per manoeuvre the true motion at the sample times
    and at the delayed sensors' times, its control, and its start state at ``t = 0``.

    ``thrusters``/``drags``: per manoeuvre, a tuple of (3,) tuples / floats (default zero). Held
    controls switch every 37 s from 3.1 s (between samples); interpolated ones are sampled every
    50 s. The reference solver lands its steps on the control times (`jump_ts`).
    """
    k = len(controls)
    thrusters = thrusters or ((0.0, 0.0, 0.0),) * k
    drags = drags or (0.0,) * k
    tracker_delay, gyro_delay = delays
    records = []
    for i, (frame, hold) in enumerate(controls):
        rng = np.random.default_rng(300 + i)
        q_pre = quat.normalize(jnp.asarray(rng.normal(size=4)))
        omega_pre = jnp.asarray(rng.uniform(-0.04, 0.04, 3))
        t = np.linspace(0.0, duration, n)
        t_c = 3.1 + 37.0 * np.arange(13) if hold == "previous" else np.linspace(0.0, duration, 13)
        tau_c = rng.normal(size=(13, 3)) * 6e-6  # N m, the size of a magnetorquer's torque
        times = np.unique(np.concatenate([[-PRE_ROLL], t, t - tracker_delay, t - gyro_delay]))
        ref = jaxrot.reference_rollout(
            jaxrot.RotState(q_pre, omega_pre),
            jnp.asarray(SATELLITE_INERTIA),
            jnp.asarray(times),
            torque=_sensor_torque,
            args={
                "dipole": jnp.asarray(SATELLITE_DIPOLE),
                "thruster": jnp.asarray(thrusters[i]),
                "drag": jnp.asarray(drags[i]),
                "t_c": jnp.asarray(t_c),
                "tau_c": jnp.asarray(tau_c),
                "held": jnp.asarray(hold == "previous"),
                "body": jnp.asarray(frame == "body"),
            },
            jump_ts=jnp.asarray(t_c),
            rtol=1e-13,
            atol=1e-13,
        )
        q_all, omega_all = np.asarray(ref.q), np.asarray(ref.omega)
        start = np.searchsorted(times, 0.0)
        records.append(
            {"t": t, "t_c": t_c, "tau_c": tau_c, "frame": frame, "hold": hold, "times": times, "q": q_all,
             "omega": omega_all, "q0": q_all[start], "omega0": omega_all[start]}
        )  # fmt: skip
    return tuple(records)


def _true_at(record, s):
    """The true ``(q, ω)`` of a `sensor_records` manoeuvre at times ``s`` (among its solved times)."""
    rows = np.searchsorted(record["times"], s)
    return record["q"][rows], record["omega"][rows]


def sensor_experiments(
    seed, *, controls=CONTROLS[:3], sensors=None, noise=True, sigma_q=1e-4, sigma_omega=2e-5, n=121,
    thrusters=None, drags=None, known_thrusters=(),
):  # fmt: skip
    """Manoeuvres of the satellite seen through flawed sensors: ``(experiments, truth)``.

    ``sensors``: the true sensor parameters (a dict of `TRUE_SENSORS`' keys; None: ideal sensors):
    tracker reading ``q(t − tracker_delay) ⊗ exp(tracker_mount)``, gyro reading
    ``gyro_scale ⊙ ω_b(t − gyro_delay) + gyro_bias[i]``, then white noise (σ per axis).
    ``known_thrusters``: manoeuvres whose ``thruster`` goes into their ``Experiment.args``.
    """
    sensors = {} if sensors is None else sensors
    delays = (float(sensors.get("tracker_delay", 0.0)), float(sensors.get("gyro_delay", 0.0)))
    records = sensor_records(controls, n, 600.0, thrusters, drags, delays)
    rng = np.random.default_rng(seed)
    mount = jnp.asarray(sensors.get("tracker_mount", np.zeros(3)))
    experiments, truth = [], {"q0": [], "omega0": []}
    for i, rec in enumerate(records):
        t = rec["t"]
        q_seen, _ = _true_at(rec, t - delays[0])
        q_seen = np.asarray(quat.multiply(jnp.asarray(q_seen), quat.exp(mount)))
        q_gyro, omega_gyro = _true_at(rec, t - delays[1])
        gyro = np.asarray(quat.rotate(quat.conjugate(jnp.asarray(q_gyro)), jnp.asarray(omega_gyro)))
        gyro = (
            gyro * sensors.get("gyro_scale", 1.0) + sensors.get("gyro_bias", np.zeros((len(records), 3)))[i]
        )
        if noise:
            q_seen = np.asarray(
                quat.multiply(jnp.asarray(q_seen), quat.exp(jnp.asarray(rng.normal(size=(n, 3)) * sigma_q)))
            )
            gyro = gyro + rng.normal(size=(n, 3)) * sigma_omega
        known = {"thruster": np.asarray(thrusters[i])} if i in known_thrusters else None
        experiments.append(
            jaxrot.Experiment(
                t, q=q_seen, omega_body=gyro, sigma_q=sigma_q, sigma_omega=sigma_omega,
                control=(rec["t_c"], rec["tau_c"]), control_frame=rec["frame"], control_hold=rec["hold"],
                args=known,
            )
        )  # fmt: skip
        truth["q0"].append(rec["q0"])
        truth["omega0"].append(rec["omega0"])
    return experiments, truth
