"""Invariants to monitor a trajectory: kinetic energy, world angular momentum, quaternion norm.

The functions take the arrays of any `jaxrot.Trajectory` (or single states):
``q`` ``(..., 4)`` (scalar first, body → world), world-frame ``omega``
``(..., 3)``, with any leading time and particle axes, and a body-frame inertia
in either form: principal moments ``(3,)`` or a symmetric tensor ``(3, 3)``,
shared by all particles, or one per particle with the particle axes in front
(``(P..., 3)`` / ``(P..., 3, 3)``, where ``P...`` are the trailing leading axes of
``q``, as in `jaxrot.rollout`). As in `jaxrot.rollout`, a trailing ``(3, 3)`` is
always read as a tensor. Results keep the dtype of ``q`` and ``omega``.

For a torque-free body the energy and the world angular momentum are constant,
so their drift measures an integrator's error.

Example:
    >>> import jax.numpy as jnp, jaxrot
    >>> from jaxrot import diagnostics
    >>> state = jaxrot.RotState(jnp.array([1.0, 0, 0, 0]), jnp.array([0.0, 0.0, 2.0]))
    >>> print(float(diagnostics.kinetic_energy(state.q, state.omega, jnp.array([1.0, 2.0, 3.0]))))
    6.0
    >>> print(diagnostics.angular_momentum(state.q, state.omega, jnp.array([1.0, 2.0, 3.0])).tolist())
    [0.0, 0.0, 6.0]
"""

import jax.numpy as jnp

from . import quaternion as quat
from ._core._checks import float_dtype


__all__ = ["angular_momentum", "kinetic_energy", "norm_drift"]


def _prepare(q, omega, inertia):
    q = jnp.asarray(q)
    omega = jnp.asarray(omega)
    inertia = jnp.asarray(inertia)
    if q.ndim < 1 or q.shape[-1] != 4:
        raise ValueError(f"`q` must have shape (..., 4) (scalar-first [w, x, y, z]); got {q.shape}.")
    if omega.ndim < 1 or omega.shape[-1] != 3:
        raise ValueError(f"`omega` must have shape (..., 3) (world frame); got {omega.shape}.")
    lead = q.shape[:-1]
    if omega.shape[:-1] != lead:
        raise ValueError(
            f"`q` and `omega` must share their leading (time/particle) axes; "
            f"got {lead} and {omega.shape[:-1]}."
        )
    tensor = inertia.ndim >= 2 and inertia.shape[-2:] == (3, 3)
    trailing = 2 if tensor else 1
    inertia_batch = inertia.shape[: inertia.ndim - trailing]
    ok = inertia.ndim >= 1 and inertia.shape[-1] == 3
    ok = ok and len(inertia_batch) <= len(lead) and lead[len(lead) - len(inertia_batch) :] == inertia_batch
    if not ok:
        raise ValueError(
            "`inertia` must be principal moments (3,) or a body-frame tensor (3, 3), shared, or one per "
            f"particle with the particle axes (the last leading axes of `q`, here {lead}) in front; "
            f"got shape {inertia.shape}."
        )
    dtype = float_dtype(q, omega)
    inertia = inertia.astype(dtype).reshape((1,) * (len(lead) - len(inertia_batch)) + inertia.shape)
    return q.astype(dtype), omega.astype(dtype), inertia, tensor


def _body_momentum(q, omega, inertia, tensor):
    omega_body = quat.rotate(quat.conjugate(q), omega)
    if tensor:
        return omega_body, (inertia @ omega_body[..., None])[..., 0]
    return omega_body, inertia * omega_body


def kinetic_energy(q, omega, inertia):
    """Rotational kinetic energy ``½ ω_b · I ω_b``, shape ``q.shape[:-1]``.

    ``ω_b`` is ``omega`` taken to the body frame with ``q``.
    """
    q, omega, inertia, tensor = _prepare(q, omega, inertia)
    omega_body, l_body = _body_momentum(q, omega, inertia, tensor)
    return 0.5 * jnp.sum(omega_body * l_body, axis=-1)


def angular_momentum(q, omega, inertia):
    """World-frame angular momentum ``q ⊗ (I ω_b) ⊗ q*``, shape ``(..., 3)``."""
    q, omega, inertia, tensor = _prepare(q, omega, inertia)
    _, l_body = _body_momentum(q, omega, inertia, tensor)
    return quat.rotate(q, l_body)


def norm_drift(q):
    """Largest ``| |q| − 1 |`` over all leading axes (a scalar in the dtype of ``q``).

    Example:
        >>> import jax.numpy as jnp
        >>> from jaxrot import diagnostics
        >>> print(float(diagnostics.norm_drift(jnp.array([[1.0, 0, 0, 0], [0.0, 0, 0, 2.0]]))))
        1.0
    """
    q = jnp.asarray(q)
    if q.ndim < 1 or q.shape[-1] != 4:
        raise ValueError(f"`q` must have shape (..., 4) (scalar-first [w, x, y, z]); got {q.shape}.")
    if not jnp.issubdtype(q.dtype, jnp.floating):
        q = q.astype(float_dtype(q))
    if q.size == 0:
        return jnp.zeros((), q.dtype)
    return jnp.max(jnp.abs(jnp.linalg.norm(q, axis=-1) - 1))
