"""Principal moments and axes of one body's inertia: the frame the free-motion schemes work in."""

import jax.numpy as jnp

from .. import quaternion as quat


def principal_axes(inertia):
    """Ascending principal moments ``(3,)`` and the quaternion ``r`` (principal → body) of one body.

    ``inertia`` is ``(3,)`` principal moments (``r`` is then a signed axis
    permutation, the identity when the moments are already ascending) or a
    symmetric ``(3, 3)`` tensor (``jnp.linalg.eigh``). ``r`` is a proper rotation:
    ``I_body = R diag(moments) Rᵀ`` with ``R = to_matrix(r)``.
    """
    inertia = jnp.asarray(inertia)
    if inertia.ndim == 1:
        order = jnp.argsort(inertia)
        moments = inertia[order]
        rot = (jnp.arange(3)[:, None] == order[None, :]).astype(inertia.dtype)
    else:
        moments, rot = jnp.linalg.eigh(0.5 * (inertia + inertia.T))
    det = jnp.dot(rot[:, 0], jnp.cross(rot[:, 1], rot[:, 2]))
    sign = jnp.where(det < 0, -1, 1).astype(rot.dtype)
    rot = jnp.concatenate([sign * rot[:, :1], rot[:, 1:]], axis=1)
    return moments, quat._from_orthogonal_matrix(rot)
