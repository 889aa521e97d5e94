"""The `Scene` record of `jaxrot.scenes`, and the dtype helper its factories share."""

from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .._inertia import check_inertia_values
from .._particles import is_per_body
from .._pivot import central_inertia
from .._state import RotState
from ..diagnostics import kinetic_energy
from ..torques import Gravity


class Scene(NamedTuple):
    """A rotation problem.

    Attributes:
        name: key in `SCENES`.
        description: one line of physics.
        state: initial `RotState`; leading axes are bodies (none for one body).
        inertia: body-frame principal moments ``(3,)`` / tensor ``(3, 3)``, shared
            or one per body, kg m²: about the centre of mass, or about the pivot of a top (a
            `jaxrot.torques.Gravity` term), where it is what Euler's equations about that fixed point use.
        torque: a `jaxrot.torques` model (or any torque callable), or None.
        args: the torque's parameters.
        dt: a suggested time step (s): second-order schemes reach about 1e-3 rad
            over the horizon at this step.
        t_end: the horizon (s).
        drive: a `jaxrot.Drive`, or None.
        fluid: a `jaxrot.Fluid` the bodies turn in (`FLUID_SCENES`), or None. With a fluid and
            ``inertia=None`` the scene is overdamped: `jaxrot.overdamped_rollout` integrates it.
        mass: the body's mass (kg) where a weight acts on an offset centre of mass (a
            `jaxrot.torques.Gravity` term), else None. With the offset it fixes the central inertia
            (`central_inertia`), which must be a body that can exist.
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
    mass: Any = None

    @property
    def n_bodies(self) -> int:
        return int(np.prod(self.state.q.shape[:-1]))

    def central_inertia(self):
        """The bodies' inertia about their centres of mass (kg m², body frame), checked to be a real body.

        For a top (a `jaxrot.torques.Gravity` term in ``torque``) ``inertia`` is about the pivot and
        this is `jaxrot.central_inertia` of it, ``mass`` and each term's ``offset_body`` (``(3, 3)``,
        per body where those are); otherwise ``inertia`` itself. Raises ``ValueError`` for a central
        inertia that is not positive definite or breaks the triangle inequality, and for a top without
        ``mass``. None for an overdamped scene (no inertia). The built-in tops call it when built, so an
        impossible one cannot be built; ``tests/test_scenes.py`` checks every built-in scene independently.
        """
        if self.inertia is None:
            return None
        terms = getattr(self.torque, "terms", (self.torque,))
        offsets = [self.args[t.key]["offset_body"] for t in terms if isinstance(t, Gravity)]
        if not offsets:
            check_inertia_values(np.asarray(self.inertia, np.float64), f"{self.name}.inertia")
            return self.inertia
        if self.mass is None:
            raise ValueError(
                f"Scene `{self.name}` has a weight on an offset centre of mass (torques.Gravity) but no "
                "`mass`: pass mass= (kg), so that its central inertia can be checked."
            )
        names = (f"{self.name}.inertia", f"{self.name}.mass", f"{self.name}.args[...]['offset_body']")
        central = None
        for offset in offsets:
            offset = offset.value if is_per_body(offset) else offset
            central = central_inertia(self.inertia, self.mass, offset, names=names)
        return central

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
