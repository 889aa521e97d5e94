"""jaxrot: rigid-body rotation integrators in JAX.

Conventions: quaternions scalar first ``[w, x, y, z]`` mapping body to world;
angular velocity in the world frame; inertia in the body frame; torque a
callable ``torque(t, q, omega, args) -> (3,)`` in the world frame.
"""

import importlib.metadata

from . import analytic as analytic, diagnostics as diagnostics, quaternion as quaternion, schemes as schemes
from ._drive import Drive as Drive
from ._inertia import BodyInertia as BodyInertia, body_inertia as body_inertia
from ._reference import reference_rollout as reference_rollout
from ._rollout import rollout as rollout
from ._scenes import SCENES as SCENES, Scene as Scene
from ._state import RotState as RotState, Trajectory as Trajectory
from .schemes import SCHEMES as SCHEMES, AbstractScheme as AbstractScheme


__version__ = importlib.metadata.version("jaxrot")
