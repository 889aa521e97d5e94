"""The state a scheme advances and the trajectory a rollout returns."""

from typing import NamedTuple

import jax
import jax.numpy as jnp

from . import quaternion as quat


class RotState(NamedTuple):
    """Orientation and angular velocity of one or many rigid bodies.

    Attributes:
        q: unit quaternion ``(..., 4)``, scalar first ``[w, x, y, z]``, mapping
            body-frame vectors to the world frame.
        omega: angular velocity ``(..., 3)`` in the **world** frame, rad per
            unit time.

    Leading axes ``...`` are particle axes; ``q`` and ``omega`` share them.

    Gyros, MuJoCo's free-joint ``qvel[3:6]`` and most spacecraft codes give the
    angular velocity in the **body** frame: build the state with
    `RotState.from_body` and read it back with `RotState.omega_body`. Only
    ``q`` and ``omega`` are stored (``jax.tree_util``, ``vmap`` and ``scan``
    see those two leaves).

    Example:
        >>> import jax.numpy as jnp, jaxrot
        >>> state = jaxrot.RotState(q=jnp.array([1.0, 0, 0, 0]), omega=jnp.array([0.0, 0, 1]))
        >>> state.q.shape, state.omega.shape
        ((4,), (3,))
    """

    q: jax.Array
    omega: jax.Array

    @classmethod
    def from_body(cls, q, omega_body):
        """The state of orientation ``q`` ``(..., 4)`` spinning at ``omega_body`` ``(..., 3)``, body frame.

        ``omega = rotate(q / |q|, omega_body)``: the world-frame angular velocity
        jaxrot stores. ``q`` (scalar first, body → world) is kept as given, so
        `jaxrot.rollout` still checks its norm; the rotation uses it normalised,
        so ``omega`` is right for the orientation ``q`` stands for. Leading axes
        broadcast against each other (one orientation, many rates, or the
        reverse). Works under ``jit``, ``vmap`` and ``grad``.

        Example:
            >>> import jax.numpy as jnp, jaxrot
            >>> from jaxrot import quaternion as quat
            >>> q = quat.from_axis_angle(jnp.array([0.0, 0, 1]), jnp.pi / 2)  # body x is world y
            >>> state = jaxrot.RotState.from_body(q, jnp.array([2.0, 0, 0]))  # a gyro reads 2 rad/s about x
            >>> print(state.omega.round(6).tolist())
            [0.0, 2.0, 0.0]
            >>> print(state.omega_body.round(6).tolist())
            [2.0, 0.0, 0.0]
        """
        q, omega_body = jnp.asarray(q), jnp.asarray(omega_body)
        if q.ndim < 1 or q.shape[-1] != 4:
            raise ValueError(f"`q` must have shape (..., 4) (scalar-first [w, x, y, z]); got {q.shape}.")
        if omega_body.ndim < 1 or omega_body.shape[-1] != 3:
            raise ValueError(f"`omega_body` must have shape (..., 3) (body frame); got {omega_body.shape}.")
        try:
            batch = jnp.broadcast_shapes(q.shape[:-1], omega_body.shape[:-1])
        except ValueError:
            raise ValueError(
                f"`q` {q.shape} and `omega_body` {omega_body.shape} must have leading (particle) axes that "
                "broadcast against each other."
            ) from None
        q = jnp.broadcast_to(q, (*batch, 4))
        return cls(q, quat.rotate(quat.normalize(q), omega_body))

    @property
    def omega_body(self):
        """The angular velocity ``(..., 3)`` in the **body** frame: ``rotate(conjugate(q / |q|), omega)``."""
        return quat.rotate(quat.conjugate(quat.normalize(self.q)), self.omega)


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
