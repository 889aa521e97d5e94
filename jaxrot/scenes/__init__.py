"""Built-in scenes: bodies, initial state, torque model, drives, a suggested step and horizon.

A `Scene` declares what is simulated and nothing more: a torque-free scene has
``torque=None`` and no torque is ever evaluated; diagonal inertia (principal
moments) takes the fast path with no 3×3 products; a scene without drives runs
no drive code. `SCENES` maps names to factories ``factory(dtype=float64) ->
Scene``; ``python -m jaxrot compare --scene NAME`` runs any of them and
``--list-scenes`` lists them. Units are SI (kg m², rad/s, N m, s, A m², T)
except in `dipole_cloud`, which uses reduced units (μ₀/4π = 1).

Example:
    >>> import jaxrot
    >>> scene = jaxrot.SCENES["viscous_drag"]()
    >>> traj = jaxrot.rollout("zhao", scene.state, scene.inertia, scene.dt, 100, torque=scene.torque,
    ...                       args=scene.args)
    >>> traj.q.shape
    (101, 4)
"""

from types import MappingProxyType

# Bound here since jaxrot.scenes was one module (jaxrot.scenes.Gravity, jaxrot.scenes.Fluid, ...): kept.
from .._fluid._equilibrium import dipole_orientations as dipole_orientations, maxwell_spins as maxwell_spins
from .._fluid._fluid import Fluid as Fluid
from .._particles import per_body
from .._state import RotState as RotState
from ..diagnostics import kinetic_energy as kinetic_energy
from ..torques import (
    DipoleInteraction as DipoleInteraction,
    Gravity as Gravity,
    RotatingField as RotatingField,
    UniformField as UniformField,
    ViscousDrag as ViscousDrag,
)
from ._fluid import (
    FLUID_SCENES,
    spheroid_shear as spheroid_shear,
    spheroid_shear_overdamped as spheroid_shear_overdamped,
)
from ._magnetic import dipole_cloud, dipole_field, dipole_rotating_field
from ._mechanical import free_top, gravity_torque, heavy_top, lagrange_top, tumbling_cloud, viscous_drag
from ._scene import Scene
from ._thermal import (
    THERMAL_SCENES,
    magnetic_nanoparticles as magnetic_nanoparticles,
    magnetic_nanoparticles_inertial as magnetic_nanoparticles_inertial,
)


SCENES = MappingProxyType(
    {
        f.__name__: f
        for f in (
            free_top,
            heavy_top,
            lagrange_top,
            dipole_field,
            dipole_rotating_field,
            viscous_drag,
            dipole_cloud,
            tumbling_cloud,
        )
    }
)

# Strings only (griffe reads them statically); the check below keeps them complete.
__all__ = [
    "FLUID_SCENES",
    "SCENES",
    "Scene",
    "THERMAL_SCENES",
    "dipole_cloud",
    "dipole_field",
    "dipole_rotating_field",
    "free_top",
    "gravity_torque",
    "heavy_top",
    "lagrange_top",
    "magnetic_nanoparticles",
    "magnetic_nanoparticles_inertial",
    "per_body",
    "spheroid_shear",
    "spheroid_shear_overdamped",
    "tumbling_cloud",
    "viscous_drag",
]
if not {*SCENES, *FLUID_SCENES, *THERMAL_SCENES} <= set(__all__):  # a new scene must be listed above
    raise ImportError("jaxrot.scenes.__all__ misses a scene of SCENES, FLUID_SCENES or THERMAL_SCENES")
