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
