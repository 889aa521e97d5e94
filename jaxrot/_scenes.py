"""Built-in scenes: a body, its initial state, its torque and a horizon.

Every scene is a plain description; the compare job and the tests run schemes
on them. Torques are module-level functions so compiled code is reused.
"""

from collections.abc import Callable
from typing import Any, NamedTuple

import jax.numpy as jnp

from . import quaternion as quat
from ._state import RotState


class Scene(NamedTuple):
    """A rotation problem: initial state, body-frame inertia, torque, horizon."""

    name: str
    description: str
    state: RotState
    inertia: Any
    torque: Callable | None
    args: Any
    t_end: float


def gravity_torque(t, q, omega, args):
    """Torque of a weight ``m g`` (world frame) at the body-frame offset ``r_b`` from the pivot."""
    r_world = quat.rotate(q, args["offset_body"])
    return jnp.cross(r_world, args["weight"])


def heavy_top(dtype=jnp.float64) -> Scene:
    """Asymmetric heavy top: gravity on a centre of mass offset from a fixed pivot.

    Inertia ``(1, 2, 3)`` kg m² about the pivot (principal axes = body axes),
    centre of mass at ``(0.1, 0.05, 0.3)`` m in the body, weight ``(0, 0, −9.81)``
    N (1 kg), spun mostly about the body z axis and tilted by about 0.37 rad.
    The orientation-dependent torque makes the motion nutate and precess.
    """
    q0 = quat.exp(jnp.array([0.1, 0.2, 0.3], dtype=dtype))
    omega_body = jnp.array([0.3, 1.0, 6.0], dtype=dtype)
    return Scene(
        name="heavy_top",
        description="asymmetric heavy top, I=(1,2,3), gravity on an offset centre of mass",
        state=RotState(q0, quat.rotate(q0, omega_body)),
        inertia=jnp.array([1.0, 2.0, 3.0], dtype=dtype),
        torque=gravity_torque,
        args={
            "offset_body": jnp.array([0.1, 0.05, 0.3], dtype=dtype),
            "weight": jnp.array([0.0, 0.0, -9.81], dtype=dtype),
        },
        t_end=5.0,
    )


SCENES = {"heavy_top": heavy_top}
