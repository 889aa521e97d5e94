"""The `Scene` record of `jaxrot.scenes`, and the dtype helper its factories share."""

from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .._state import RotState
from ..diagnostics import kinetic_energy


class Scene(NamedTuple):
    """A rotation problem.

    Attributes:
        name: key in `SCENES`.
        description: one line of physics.
        state: initial `RotState`; leading axes are bodies (none for one body).
        inertia: body-frame principal moments ``(3,)`` / tensor ``(3, 3)``, shared
            or one per body, kg m².
        torque: a `jaxrot.torques` model (or any torque callable), or None.
        args: the torque's parameters.
        dt: a suggested time step (s): second-order schemes reach about 1e-3 rad
            over the horizon at this step.
        t_end: the horizon (s).
        drive: a `jaxrot.Drive`, or None.
        fluid: a `jaxrot.Fluid` the bodies turn in (`FLUID_SCENES`), or None. With a fluid and
            ``inertia=None`` the scene is overdamped: `jaxrot.overdamped_rollout` integrates it.
    """

    name: str
    description: str
    state: RotState
    inertia: Any
    torque: Callable | None
    args: Any
    dt: float
    t_end: float
    drive: Any = None
    fluid: Any = None

    @property
    def n_bodies(self) -> int:
        return int(np.prod(self.state.q.shape[:-1]))

    def energy(self, t, q, omega):
        """Total energy (J) of all bodies: kinetic plus the torque model's potential.

        ``q`` ``(..., 4)`` and ``omega`` ``(..., 3)`` with the scene's body axes
        last (any leading time axes); None when the torque is not conservative or a fluid drags.
        """
        if self.fluid is not None or (
            self.torque is not None and not getattr(self.torque, "conservative", False)
        ):
            return None
        body_ndim = self.state.q.ndim - 1
        kinetic = kinetic_energy(q, omega, self.inertia)
        kinetic = jnp.sum(kinetic, axis=tuple(range(kinetic.ndim - body_ndim, kinetic.ndim)))
        if self.torque is None:
            return kinetic
        bodies = q.reshape(-1, self.n_bodies, 4)  # one row of all bodies per leading index
        potential = jax.vmap(lambda qi: self.torque.energy(t, qi, self.args))(bodies)
        return kinetic + potential.reshape(kinetic.shape)


def _f(x, dtype):
    return jnp.asarray(x, dtype=dtype)
