"""Driven bodies (Rockable DEM, seed 004): imposed angular velocity or moment, per body and component."""

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .._core._concrete import is_concrete
from .._state import RotState


class Drive(NamedTuple):
    """Per-body, per-component driving of rotation, in the **world** frame.

    Attributes:
        omega_mask: bool ``(..., 3)``, or None for no imposed velocity. A body with
            any True component is *velocity-driven*: its world angular velocity is
            ``omega`` on the masked components and 0 on the others (Rockable: a
            component without a control line does not move), whatever the torque.
        omega: imposed world angular velocity ``(..., 3)`` (rad / time).
        moment_mask: bool ``(..., 3)``, or None for no imposed moment. Masked
            components of the world torque are *set* to ``moment``, overriding
            the torque model on that component only; the body stays free
            otherwise and is integrated by the scheme.
        moment: imposed world torque ``(..., 3)``.

    Leading axes are absent (one drive for every particle) or the particle axes.
    A body may not mix imposed velocity and imposed moment. With the ``"euler"``
    scheme a velocity-driven body moves by the seed's first-order update
    ``normalize(q + Δt · ½ ω ⊗ q)``; every other scheme rotates it exactly,
    ``exp(ω Δt) ⊗ q``. Without a drive (``drive=None``) no drive code runs.

    Example:
        >>> import jax.numpy as jnp, jaxrot
        >>> spin_z = jaxrot.Drive.imposed_velocity(jnp.array([0.0, 0.0, 2.0]))
        >>> s = jaxrot.RotState(jnp.array([1.0, 0, 0, 0]), jnp.zeros(3))
        >>> traj = jaxrot.rollout("zhao", s, jnp.array([1.0, 2.0, 2.5]), 0.1, 10, drive=spin_z)
        >>> print(traj.omega[-1].tolist())
        [0.0, 0.0, 2.0]
    """

    omega_mask: jax.Array | None = None
    omega: jax.Array | None = None
    moment_mask: jax.Array | None = None
    moment: jax.Array | None = None

    @classmethod
    def imposed_velocity(cls, omega, mask=None) -> "Drive":
        """Impose world angular velocity ``omega`` on the components in ``mask`` (default: all)."""
        omega = jnp.asarray(omega)
        mask = jnp.ones(omega.shape, dtype=bool) if mask is None else jnp.asarray(mask, dtype=bool)
        return cls(omega_mask=mask, omega=omega)

    @classmethod
    def imposed_moment(cls, moment, mask) -> "Drive":
        """Set the world torque to ``moment`` on the components in ``mask``."""
        return cls(moment_mask=jnp.asarray(mask, dtype=bool), moment=jnp.asarray(moment))


def check_drive(drive, batch_shape, dtype):
    """Validate a `Drive`; returns ``(drive, per_particle)`` with values cast to ``dtype``."""
    if drive is None:
        return None, False
    if not isinstance(drive, Drive):
        raise ValueError(f"`drive` must be None or a jaxrot.Drive; got {type(drive).__name__}.")
    fields = {}
    shapes = set()
    for mask_name, value_name in (("omega_mask", "omega"), ("moment_mask", "moment")):
        mask, value = getattr(drive, mask_name), getattr(drive, value_name)
        if (mask is None) != (value is None):
            raise ValueError(f"`drive.{mask_name}` and `drive.{value_name}` must be given together.")
        if mask is None:
            fields[mask_name] = fields[value_name] = None
            continue
        mask, value = jnp.asarray(mask), jnp.asarray(value)
        if mask.dtype != jnp.bool_:
            raise ValueError(f"`drive.{mask_name}` must be a boolean array; got dtype {mask.dtype}.")
        for name, x in ((mask_name, mask), (value_name, value)):
            if x.shape not in ((3,), (*batch_shape, 3)):
                raise ValueError(
                    f"`drive.{name}` must have shape (3,) or the particle axes then 3, {(*batch_shape, 3)}; "
                    f"got {x.shape}."
                )
        value = value.astype(dtype)
        if is_concrete(value) and not np.all(np.isfinite(np.asarray(value))):
            raise ValueError(f"`drive.{value_name}` contains NaN or infinite values.")
        fields[mask_name], fields[value_name] = mask, value
        shapes.update({mask.shape, value.shape})
    if fields["omega_mask"] is None and fields["moment_mask"] is None:
        return None, False
    if fields["omega_mask"] is not None and fields["moment_mask"] is not None:
        both = jnp.broadcast_arrays(jnp.any(fields["omega_mask"], -1), jnp.any(fields["moment_mask"], -1))
        if is_concrete(*both) and np.any(np.asarray(both[0]) & np.asarray(both[1])):
            raise ValueError(
                "`drive`: a body may not mix an imposed velocity and an imposed moment; drive it by velocity "
                "on the components you control (the others are held at rest) or by moment only."
            )
    per_particle = any(len(shape) > 1 for shape in shapes)
    if per_particle:
        fields = {k: None if v is None else jnp.broadcast_to(v, (*batch_shape, 3)) for k, v in fields.items()}
    return Drive(**fields), per_particle


def driven_torque(torque, drive: Drive):
    """The torque callable seen by a scheme: the model's, with imposed moment components set."""
    if drive.moment_mask is None:
        return torque

    def torque_with_moments(t, q, omega, args):
        model = jnp.zeros_like(omega) if torque is None else jnp.asarray(torque(t, q, omega, args))
        return jnp.where(drive.moment_mask, drive.moment.astype(model.dtype), model)

    return torque_with_moments


def driven_step(scheme, carry, t, dt, inertia, torque, args, drive: Drive):
    """One step of one body under ``drive`` (not None)."""
    new_carry = scheme.step(carry, t, dt, inertia, driven_torque(torque, drive), args)
    if drive.omega_mask is None:
        return new_carry
    q0 = scheme.state(carry).q
    omega = jnp.where(drive.omega_mask, drive.omega, jnp.zeros_like(drive.omega))
    forced = scheme.with_state(new_carry, RotState(scheme.driven_rotation(q0, omega, dt), omega), inertia)
    is_driven = jnp.any(drive.omega_mask)
    return jax.tree_util.tree_map(lambda a, b: jnp.where(is_driven, a, b), forced, new_carry)
