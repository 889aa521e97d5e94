"""Scenes in a fluid (`FLUID_SCENES`): a spheroid in simple shear, with and without inertia."""

from types import MappingProxyType

import jax.numpy as jnp
import numpy as np

from .. import quaternion as quat
from .._fluid._fluid import Fluid
from .._state import RotState
from ._scene import Scene, _f


def _spheroid_in_shear(dtype, stokes):
    aspect = 4.0
    shear = jnp.zeros((3, 3), dtype).at[0, 1].set(1.0)
    fluid = Fluid.spheroid(_f(aspect, dtype), _f(1.0, dtype), _f(1.0, dtype), velocity_gradient=shear)
    q0 = quat.exp(_f([0.3, -0.5, 0.7], dtype))
    state = RotState(q0, fluid.angular_velocity(q0))
    inertia = None
    if stokes:
        shape = _f([aspect**2 + 1, aspect**2 + 1, 2.0], dtype) / 5  # a uniform spheroid's moments / mass
        inertia = stokes * fluid.friction[0] / shape[0] * shape
    return fluid, state, inertia, 2 * np.pi * (aspect + 1 / aspect)


def spheroid_shear(dtype=jnp.float64, stokes=1e-2) -> Scene:
    """A prolate spheroid (aspect ratio 4) with inertia in a simple shear: Jeffery's orbit, drifting.

    Reduced units: semi-axes 4 and 1, viscosity 1, the shear ``u = (y, 0, 0)`` of rate 1 (Perrin's
    frictions, `jaxrot.Fluid.spheroid`); the moments of a uniform spheroid, scaled to the Stokes
    number ``St = I_⊥ γ̇ / ζ_⊥`` (default 1e-2: the friction relaxes the tumbling in 0.01 and the spin
    in 0.0056 time units, so ``ζΔt/I`` is 5–9 at the suggested step). Started off the shear plane,
    turning at the overdamped angular velocity. The horizon is one Jeffery period,
    ``2π(λ + 1/λ)/γ̇``. Needs a fluid scheme (`jaxrot.FLUID_SCHEMES`): ``rollout(..., fluid=scene.fluid)``.
    """
    fluid, state, inertia, period = _spheroid_in_shear(dtype, stokes)
    return Scene(
        "spheroid_shear",
        f"spheroid (aspect 4) in simple shear at Stokes number {stokes:g}, reduced units",
        state, inertia, None, None, dt=0.05, t_end=float(period), fluid=fluid,
    )  # fmt: skip


def spheroid_shear_overdamped(dtype=jnp.float64) -> Scene:
    """`spheroid_shear` without inertia (Stokes number 0): Jeffery's orbit, `jaxrot.overdamped_rollout`.

    The orientation alone: ``inertia=None``; ``state.omega`` is the overdamped angular velocity.
    """
    fluid, state, _, period = _spheroid_in_shear(dtype, 0.0)
    return Scene(
        "spheroid_shear_overdamped",
        "spheroid (aspect 4) in simple shear without inertia: Jeffery's orbit, reduced units",
        state, None, None, None, dt=0.1, t_end=float(period), fluid=fluid,
    )  # fmt: skip


# Scenes in a fluid: run by `jaxrot.rollout(..., fluid=scene.fluid)` with a fluid scheme, or by
# `jaxrot.overdamped_rollout` (inertia None); ``python -m jaxrot compare`` knows them. Kept apart
# from `SCENES`, which every scheme of `jaxrot.SCHEMES` runs.
FLUID_SCENES = MappingProxyType({f.__name__: f for f in (spheroid_shear, spheroid_shear_overdamped)})
