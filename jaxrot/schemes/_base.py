"""The small interface every scheme implements.

A scheme advances **one body**; `jaxrot.rollout` vmaps it over particles and
scans it over time. A scheme may carry more than `RotState` between steps (a
momentum, a reused torque): `init` builds that carry, `step` advances it and
`state` reads the `RotState` back out.
"""

from collections.abc import Callable
from typing import Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp

from .. import quaternion as quat
from .._fusion import stage
from .._inertia import BodyInertia
from .._state import RotState


Torque = Callable[[jax.Array, jax.Array, jax.Array, Any], jax.Array]


class AbstractScheme(eqx.Module):
    """Base class of the integrators in `jaxrot.SCHEMES`.

    Class attributes:
        name: the key in `jaxrot.SCHEMES`.
        order: nominal global order of accuracy in ``dt``.
        torque_evals_per_step: calls of the torque callable per step (0 when
            ``torque=None``, which is never called).
        torque_evals_at_init: extra calls made once by `init` (schemes that
            reuse the end-of-step torque evaluate the first one there).
    """

    name: ClassVar[str]
    order: ClassVar[int]
    torque_evals_per_step: ClassVar[int]
    torque_evals_at_init: ClassVar[int] = 0

    def init(self, state: RotState, t0, inertia: BodyInertia, torque: Torque | None, args) -> Any:
        """Carry for the first step; the plain state unless the scheme needs more."""
        return state

    def step(self, carry, t, dt, inertia: BodyInertia, torque: Torque | None, args) -> Any:
        """Advance one body from time ``t`` to ``t + dt``."""
        raise NotImplementedError

    def state(self, carry) -> RotState:
        """The `RotState` held in a carry."""
        return carry

    def with_state(self, carry, state: RotState, inertia: BodyInertia) -> Any:
        """``carry`` with its orientation and angular velocity replaced by ``state``.

        Used for velocity-driven bodies; schemes that carry derived quantities
        (a momentum) recompute them here without calling the torque.
        """
        if isinstance(carry, RotState):
            return state
        raise NotImplementedError(
            f"{type(self).__name__} carries {type(carry).__name__}: override with_state to support drives."
        )

    def driven_rotation(self, q, omega, dt):
        """Orientation after ``dt`` at imposed world angular velocity ``omega``: exactly ``exp(ω Δt) ⊗ q``."""
        return quat.multiply(quat.exp(dt * omega), q)

    def summarize(self, carry):
        """What `report` needs of a final carry, reduced over the particles (traceable), or None.

        Small, so that a rollout that does not return its carry need not keep it."""
        return None

    def report(self, summary) -> str | None:
        """A warning about a finished rollout, from its concrete `summarize` output, or None."""
        return None


def world_torque(torque: Torque, t, q, omega, args):
    """The torque callable's world-frame torque ``(3,)``, in the dtype of ``q``, shape-checked."""
    tau = jnp.asarray(torque(t, q, omega, args)).astype(q.dtype)
    if tau.shape != (3,):
        raise ValueError(
            f"`torque` must return a world-frame torque of shape (3,) for one body; got {tau.shape}."
        )
    return tau


def body_torque(torque: Torque | None, t, q, omega, args):
    """Torque in the body frame of ``q``; None when the scene is torque-free."""
    if torque is None:
        return None
    return stage(quat.rotate(quat.conjugate(q), world_torque(torque, t, q, omega, args)))
