"""Scenes of magnetic needles: in a uniform or a rotating field, and a grid coupled by their dipoles."""

import jax
import jax.numpy as jnp
import numpy as np

from .. import quaternion as quat
from .._state import RotState
from ..torques import DipoleInteraction, RotatingField, UniformField
from ._scene import Scene, _f


def _needle(dtype, tilt):
    q0 = quat.from_axis_angle(_f([0.0, 1.0, 0.0], dtype), _f(tilt, dtype))
    return q0, _f([1.0, 1.0, 0.2], dtype), _f([0.0, 0.0, 1.0], dtype)


def dipole_field(dtype=jnp.float64) -> Scene:
    """A magnetised needle (compass) in a uniform field: it swings about the field and spins.

    Inertia ``(1, 1, 0.2)`` kg m², moment 1 A m² along the body z (needle) axis,
    field ``(1, 0, 0)`` T, needle tilted 0.5 rad from the world z towards x
    (1.07 rad from the field), spin 2 rad/s about the needle. Energy is conserved,
    and so is the angular momentum component along the field.
    """
    q0, inertia, moment = _needle(dtype, 0.5)
    return Scene(
        "dipole_field",
        "magnetic needle in a uniform 1 T field",
        RotState(q0, quat.rotate(q0, _f([0.3, 0.0, 2.0], dtype))),
        inertia,
        UniformField(),
        {"field": {"moment_body": moment, "field": _f([1.0, 0.0, 0.0], dtype)}},
        dt=0.005,
        t_end=10.0,
    )


def dipole_rotating_field(dtype=jnp.float64) -> Scene:
    """A magnetised needle dragged by a field rotating in the xy plane at 0.5 rad/s.

    The needle of `dipole_field` lying along world x, the field
    ``B(t) = (cos 0.5t, sin 0.5t, 0)`` T: the needle follows the field with a lag
    and oscillates about it. Time-dependent torque; energy is not conserved.
    """
    q0, inertia, moment = _needle(dtype, np.pi / 2)
    field = {"moment_body": moment, "amplitude": _f(1.0, dtype), "angular_frequency": _f(0.5, dtype)}
    return Scene(
        "dipole_rotating_field",
        "magnetic needle in a 1 T field rotating at 0.5 rad/s",
        RotState(q0, quat.rotate(q0, _f([0.0, 0.0, 1.0], dtype))),
        inertia,
        RotatingField(),
        {"rotating_field": field},
        dt=0.005,
        t_end=10.0,
    )


def dipole_cloud(dtype=jnp.float64, n_side=4, external_field=(0.0, 0.0, 0.5)) -> Scene:
    """``n_side²`` magnetic needles pinned on a square grid, each turned by all the others' fields.

    Reduced units: μ₀/4π = 1, grid spacing 1, moment 1 along each needle,
    inertia ``(0.1, 0.1, 0.02)``, random initial orientations (seed 0) at rest,
    plus a uniform ``external_field`` (pass zeros for none). The dipole–dipole
    torque is coupled (`jaxrot.torques.DipoleInteraction`). Energy is conserved;
    the total spin angular momentum changes by the external torque and by the
    pins' reaction (see `DipoleInteraction`).
    """
    n = n_side * n_side
    grid = np.stack(np.meshgrid(np.arange(n_side), np.arange(n_side), indexing="ij"), -1).reshape(n, 2)
    positions = _f(np.concatenate([grid, np.zeros((n, 1))], axis=1), dtype)
    q0 = quat.normalize(jax.random.normal(jax.random.PRNGKey(0), (n, 4), dtype=dtype))
    moment = _f([0.0, 0.0, 1.0], dtype)
    args = {
        "dipoles": {"positions": positions, "moment_body": moment, "strength": _f(1.0, dtype)},
        "field": {"moment_body": moment, "field": _f(external_field, dtype)},
    }
    return Scene(
        "dipole_cloud",
        f"{n} coupled magnetic needles on a grid (dipole–dipole torques), reduced units",
        RotState(q0, jnp.zeros((n, 3), dtype)),
        _f([0.1, 0.1, 0.02], dtype),
        DipoleInteraction() + UniformField(),
        args,
        dt=0.002,
        t_end=3.0,
    )
