"""The orientation misfit both fits measure: the rotation between a modelled and an observed orientation.

`orientation_misfit` is its squared size ``4 sin²(θ/2) ≈ θ²`` (fit_inertia's objective),
`signed_vector` the rotation vector whose squared norm it is (both stacks' residuals).
"""

import jax.numpy as jnp

from .. import quaternion as quat


def orientation_misfit(q, q_obs):
    """``4 |v|²`` of ``q_obs* ⊗ q = (w, v)``: ``4 sin²(θ/2) ≈ θ²``, sign invariant, smooth, finite gradient.

    For unit quaternions this is ``4 (1 − (q·q_obs)²)``, but computed without that
    cancellation: ``1 − c²`` is a difference of O(1) numbers, so it is known only to
    ~eps absolute (it came out −5e-16 at a perfect fit, and could not resolve misfits
    below ~√eps rad: 3e-4 rad in float32). Each component of ``v`` is a short sum of
    products, correct to ~eps absolute, so ``4 |v|²`` is never negative and resolves
    angles down to ~eps; a ``|q|`` off 1 by round-off scales it instead of shifting it.
    """
    v = quat.multiply(quat.conjugate(q_obs), q)[..., 1:]
    return 4 * jnp.sum(v * v, axis=-1)


def signed_vector(q, q_ref):
    """``2 v sign(w)`` of ``q_ref* ⊗ q = (w, v)``: its squared norm is `orientation_misfit`."""
    d = quat.multiply(quat.conjugate(q_ref), q)
    return 2 * jnp.where(d[..., :1] < 0, -d[..., 1:], d[..., 1:])
