"""Closed forms of bodies at a temperature, and exact samples of their equilibrium, for the checks.

- Equipartition: each principal axis carries ``⟨I_k ω_k²⟩ = kT`` (the Maxwell law of the spin).
- A dipole ``μ`` (along body z) in a field ``B`` (world z): the orientation's Boltzmann law gives
  ``cos θ`` (the dipole's angle to the field) the density ``∝ e^{x cos θ}`` on ``[−1, 1]``,
  ``x = μB/kT``, and the mean ``L(x) = coth x − 1/x`` (the Langevin function).
- Free rotational diffusion with ``D_k = kT/ζ_k`` about the principal axes: a body axis ``e_i``
  keeps ``⟨e_i(t)·e_i(0)⟩ = exp(−(D_j + D_k) t)`` (Favro, Phys. Rev. 119, 53 (1960): the generator
  ``Σ D_k L_k²`` maps ``R e_i`` to ``−(D_j + D_k) R e_i``), ``e^{−2Dt}`` for a sphere.
"""

import jax
import jax.numpy as jnp
import numpy as np

from .. import quaternion as quat


def langevin_function(x):
    """``L(x) = coth x − 1/x`` (``x/3 − x³/45`` near 0): the mean ``cos θ`` of a dipole, ``x = μB/kT``."""
    x = np.asarray(x, dtype=np.float64)
    small = np.abs(x) < 1e-3
    safe = np.where(small, 1.0, x)
    return np.where(small, x / 3 - x**3 / 45, 1 / np.tanh(safe) - 1 / safe)


def axis_correlation(diffusion, t):
    """``⟨e_i(t)·e_i(0)⟩ = exp(−(D_j + D_k) t)`` ``(..., 3)`` of free diffusion ``diffusion`` ``(3,)``."""
    d = np.asarray(diffusion, dtype=np.float64)
    return np.exp(-(d.sum() - d) * np.asarray(t, dtype=np.float64)[..., None])


def dipole_orientations(key, n: int, x, dtype=jnp.float64):
    """``(n, 4)`` orientations from the Boltzmann law of a body-z dipole in a world-z field at
    ``x = μB/kT > 0``: ``cos θ = 1 + log(U + (1 − U) e^{−2x}) / x``, uniform azimuth and spin."""
    u_cos, u_azimuth, u_spin = jax.random.uniform(key, (3, n), dtype)
    cos_theta = 1 + jnp.log(u_cos + (1 - u_cos) * jnp.exp(-2 * x)) / x
    theta = jnp.arccos(jnp.clip(cos_theta, -1, 1))
    z = jnp.array([0.0, 0.0, 1.0], dtype)
    y = jnp.array([0.0, 1.0, 0.0], dtype)
    spin = quat.from_axis_angle(z, 2 * jnp.pi * u_spin)
    tilt = quat.from_axis_angle(y, theta)
    azimuth = quat.from_axis_angle(z, 2 * jnp.pi * u_azimuth)
    return quat.multiply(azimuth, quat.multiply(tilt, spin))


def maxwell_spins(key, q, inertia, kT):
    """World angular velocities ``(n, 3)`` of bodies at ``q`` ``(n, 4)`` from the Maxwell law:
    ``ω_b,k ~ N(0, kT/I_k)``."""
    scale = jnp.sqrt(kT / jnp.asarray(inertia, q.dtype))
    normals = jax.random.normal(key, q.shape[:-1] + (3,), q.dtype)
    body = normals * scale.reshape((1,) * (normals.ndim - scale.ndim) + scale.shape)
    return quat.rotate(q, body)
