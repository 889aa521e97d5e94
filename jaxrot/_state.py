"""The state a scheme advances and the trajectory a rollout returns."""

from typing import NamedTuple

import jax


class RotState(NamedTuple):
    """Orientation and angular velocity of one or many rigid bodies.

    Attributes:
        q: unit quaternion ``(..., 4)``, scalar first ``[w, x, y, z]``, mapping
            body-frame vectors to the world frame.
        omega: angular velocity ``(..., 3)`` in the **world** frame, rad per
            unit time.

    Leading axes ``...`` are particle axes; ``q`` and ``omega`` share them.

    Example:
        >>> import jax.numpy as jnp, jaxrot
        >>> state = jaxrot.RotState(q=jnp.array([1.0, 0, 0, 0]), omega=jnp.array([0.0, 0, 1]))
        >>> state.q.shape, state.omega.shape
        ((4,), (3,))
    """

    q: jax.Array
    omega: jax.Array


class Trajectory(NamedTuple):
    """Saved states of a rollout.

    Attributes:
        t: times ``(n_saved,)``.
        q: orientations ``(n_saved, ..., 4)``, scalar first, body → world.
        omega: world-frame angular velocities ``(n_saved, ..., 3)``.

    Index 0 along the first axis is the initial state.
    """

    t: jax.Array
    q: jax.Array
    omega: jax.Array
