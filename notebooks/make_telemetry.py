"""Make the seeded synthetic telemetry that notebooks/identify.ipynb fits (shipped in jaxrot/data/).

    python notebooks/make_telemetry.py   # jaxrot/data/satellite_telemetry.npz, heavy_top_axis.npz

Both records come from `jaxrot.reference_rollout` (diffrax Dopri8 at 1e-12), with seeded noise:
- a small satellite, three 10-minute manoeuvres under known reaction-wheel torques (body frame,
  each command held for 20 s) and the torque of an unknown residual magnetic dipole in the
  geomagnetic field, seen through flight-like sensors: a star tracker mounted 1.4° off the body
  axes (1e-4 rad per axis of noise), a gyro with a bias per manoeuvre and a scale factor off by
  0.1-0.3 % (2e-5 rad/s per axis of noise), 121 samples each; the tracker drops 5 % of its
  samples (NaN rows);
- a heavy asymmetric top seen through one body axis (a camera tracking a marker): 1e-3 rad noise
  across the direction, 241 samples over 6 s; its centre-of-mass offset is the unknown.
"""

from pathlib import Path

import jax


jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np

import jaxrot
from jaxrot import quaternion as quat


OUT = Path(__file__).resolve().parent.parent / "jaxrot" / "data"
FIELD_TESLA, ORBIT_S = 3e-5, 5400.0


def geomagnetic_field(t):
    """World-frame field along the orbit (T): a slow rotation with the orbital period."""
    a = 2 * jnp.pi * t / ORBIT_S
    return FIELD_TESLA * jnp.stack([jnp.cos(a), 0.3 * jnp.ones_like(a), jnp.sin(a)])


def satellite(rng):
    inertia = np.array([[0.040, 0.002, -0.001], [0.002, 0.050, 0.0015], [-0.001, 0.0015, 0.060]])
    dipole = np.array([0.03, -0.02, 0.015])
    sigma_q, sigma_omega, n = 1e-4, 2e-5, 121
    mount = np.array([0.02, -0.015, 0.01])  # rad: the tracker's frame in the body frame
    scale = np.array([1.003, 0.998, 1.001])
    bias = rng.normal(size=(3, 3)) * 2e-4  # rad/s, one per manoeuvre
    record = {"inertia": inertia, "dipole": dipole, "sigma_q": sigma_q, "sigma_omega": sigma_omega}
    record |= {"field_tesla": FIELD_TESLA, "orbit_s": ORBIT_S}
    record |= {"tracker_mount": mount, "gyro_scale": scale, "gyro_bias": bias}
    for k in range(3):
        q0 = quat.normalize(jnp.asarray(rng.normal(size=4)))
        omega0 = jnp.asarray(rng.normal(size=3) * 0.02)
        t = np.linspace(0.0, 600.0, n)
        t_c = np.arange(0.0, 600.0, 20.0) + 7.0  # a wheel command every 20 s, between samples
        tau_c = rng.normal(size=(t_c.size, 3)) * 5e-6  # N m, body frame

        def torque(tt, q, omega, args, t_c=t_c, tau_c=tau_c):
            index = jnp.searchsorted(jnp.asarray(t_c), tt, side="right") - 1
            held = jnp.where(index >= 0, jnp.asarray(tau_c)[jnp.maximum(index, 0)], 0.0)
            return jnp.cross(quat.rotate(q, args["dipole"]), geomagnetic_field(tt)) + quat.rotate(q, held)

        ref = jaxrot.reference_rollout(
            jaxrot.RotState(q0, omega0), jnp.asarray(inertia), jnp.asarray(t), torque=torque,
            args={"dipole": jnp.asarray(dipole)}, jump_ts=jnp.asarray(t_c),
        )  # fmt: skip
        seen = quat.multiply(ref.q, quat.exp(jnp.asarray(mount))[None, :])
        q = np.array(quat.multiply(seen, quat.exp(jnp.asarray(rng.normal(size=(n, 3)) * sigma_q))))
        q[rng.random(n) < 0.05] = np.nan
        omega_body = np.asarray(quat.rotate(quat.conjugate(ref.q), ref.omega))
        omega_body = scale * omega_body + bias[k] + rng.normal(size=(n, 3)) * sigma_omega
        record |= {f"t{k}": t, f"q{k}": q, f"omega_body{k}": omega_body, f"control_t{k}": t_c}
        record |= {
            f"control_tau{k}": tau_c,
            f"true_q0_{k}": np.asarray(q0),
            f"true_omega0_{k}": np.asarray(omega0),
        }
    return record


def heavy_top(rng):
    inertia, gravity = np.diag([1.0, 1.4, 0.7]), np.array([0.0, 0.0, -1.0])  # kg m², N (weight m g)
    offset = np.array([0.02, -0.01, 0.1])  # centre of mass from the pivot, body frame, m
    q0, omega0 = quat.exp(jnp.array([0.3, -0.2, 0.1])), jnp.array([0.2, -0.1, 3.0])
    t, axis, sigma = np.linspace(0.0, 6.0, 241), np.array([0.0, 0.0, 1.0]), 1e-3

    def torque(tt, q, omega, args):
        return jnp.cross(quat.rotate(q, args["offset"]), jnp.asarray(gravity))

    ref = jaxrot.reference_rollout(
        jaxrot.RotState(q0, omega0), jnp.asarray(inertia), jnp.asarray(t), torque=torque,
        args={"offset": jnp.asarray(offset)},
    )  # fmt: skip
    seen = np.asarray(quat.rotate(ref.q, jnp.asarray(axis)))
    noisy = seen + np.cross(rng.normal(size=seen.shape) * sigma, seen)
    noisy /= np.linalg.norm(noisy, axis=-1, keepdims=True)
    return {
        "t": t, "direction": noisy, "body_vector": axis, "sigma_direction": sigma, "inertia": inertia,
        "gravity": gravity, "offset": offset, "true_q0": np.asarray(q0), "true_omega0": np.asarray(omega0),
    }  # fmt: skip


def main():
    OUT.mkdir(exist_ok=True)
    np.savez_compressed(OUT / "satellite_telemetry.npz", **satellite(np.random.default_rng(2026)))
    np.savez_compressed(OUT / "heavy_top_axis.npz", **heavy_top(np.random.default_rng(1903)))
    for path in sorted(OUT.glob("*.npz")):
        print(path, path.stat().st_size, "bytes")


if __name__ == "__main__":
    main()
