"""Leading particle axes: flattened to one vmapped axis inside, restored on output."""

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp

from ._state import RotState, Trajectory


def flatten_particles(state: RotState, inertia, per_particle: bool):
    """``state`` as ``(N, 4)``/``(N, 3)`` and a per-particle ``inertia`` as ``(N, 3[, 3])``."""
    batch_shape = state.q.shape[:-1]
    n = math.prod(batch_shape)
    flat = RotState(state.q.reshape(n, 4), state.omega.reshape(n, 3))
    if per_particle:
        inertia = inertia.reshape(n, *inertia.shape[len(batch_shape) :])
    return flat, inertia


def unflatten_trajectory(traj: Trajectory, batch_shape) -> Trajectory:
    """``(n_saved, N, ...)`` arrays back to ``(n_saved, *batch_shape, ...)``."""
    n_saved = traj.q.shape[0]
    return Trajectory(
        traj.t, traj.q.reshape(n_saved, *batch_shape, 4), traj.omega.reshape(n_saved, *batch_shape, 3)
    )


# The vmap axis name of the particle axis in `rollout` and `reference_rollout`: coupled torques
# gather the other bodies over it (see `jaxrot.torques`).
PARTICLES = "particles"


class PerBody(NamedTuple):
    """Marks an ``args`` leaf whose leading axes are the particle axes (see `per_body`)."""

    value: jax.Array


def per_body(value) -> PerBody:
    """Mark a torque parameter as one value per body: its leading axes are the particle axes.

    `jaxrot.rollout` and `jaxrot.reference_rollout` then give each body's torque
    call its own row (unmarked leaves are shared by all bodies).

    Example:
        >>> import jax.numpy as jnp, jaxrot
        >>> drag = lambda t, q, omega, args: -args["c"] * omega
        >>> s = jaxrot.RotState(jnp.array([[1.0, 0, 0, 0]] * 2), jnp.array([[0.0, 0, 1]] * 2))
        >>> traj = jaxrot.rollout("zhao", s, jnp.array([1.0, 1, 1]), 0.01, 100, torque=drag,
        ...                       args={"c": jaxrot.per_body(jnp.array([0.0, 1.0]))})
        >>> [round(float(w), 3) for w in traj.omega[-1, :, 2]]  # e^(-c t) at t = 1
        [1.0, 0.368]
    """
    return PerBody(jnp.asarray(value))


def is_per_body(x) -> bool:
    return isinstance(x, PerBody)


def unwrap_per_body(args):
    """``args`` with every `per_body` marker replaced by its array."""
    return jax.tree_util.tree_map(lambda x: x.value if is_per_body(x) else x, args, is_leaf=is_per_body)


def split_per_body(args, batch_shape):
    """``(values, in_axes)`` for vmapping ``args`` over the flattened particle axis.

    Per-body leaves are checked against ``batch_shape`` and flattened to ``(N, ...)``.
    """
    n = math.prod(batch_shape)
    nb = len(batch_shape)

    def value(x):
        if not is_per_body(x):
            return x
        v = x.value
        if tuple(v.shape[:nb]) != tuple(batch_shape):
            raise ValueError(
                f"a `per_body` torque parameter must have the particle axes {tuple(batch_shape)} in front; "
                f"got shape {v.shape}. Give one row per body, or pass the value unmarked to share it."
            )
        return v.reshape(n, *v.shape[nb:])

    values = jax.tree_util.tree_map(value, args, is_leaf=is_per_body)
    axes = jax.tree_util.tree_map(lambda x: 0 if is_per_body(x) else None, args, is_leaf=is_per_body)
    return values, axes
