"""jaxrot: rigid-body rotation integrators in JAX.

Conventions: quaternions scalar first ``[w, x, y, z]`` mapping body to world;
angular velocity in the world frame; inertia in the body frame; torque a
callable ``torque(t, q, omega, args) -> (3,)`` in the world frame.
"""

import importlib.metadata

from . import (
    analytic as analytic,
    comparison as comparison,
    diagnostics as diagnostics,
    quaternion as quaternion,
    scenes as scenes,
    schemes as schemes,
    stability as stability,
    torques as torques,
)
from ._core._compile import compiler_options as compiler_options
from ._diffrax._reference import reference_rollout as reference_rollout
from ._diffrax._solver import solver as solver
from ._diffrax._term import RigidBodyTerm as RigidBodyTerm
from ._fit import (
    Experiment as Experiment,
    FitResult as FitResult,
    FitWarning as FitWarning,
    Identification as Identification,
    fit_inertia as fit_inertia,
    identify as identify,
)
from ._fluid._fluid import Fluid as Fluid
from ._inertia import (
    BodyInertia as BodyInertia,
    MathematicalBody as MathematicalBody,
    body_inertia as body_inertia,
)
from ._integrate._chunked import (
    Checkpoint as Checkpoint,
    load_checkpoint as load_checkpoint,
    rollout_chunks as rollout_chunks,
    save_checkpoint as save_checkpoint,
)
from ._integrate._drive import Drive as Drive
from ._integrate._overdamped import overdamped_rollout as overdamped_rollout
from ._integrate._rollout import rollout as rollout
from ._integrate._runtime_check import IntegrationError as IntegrationError
from ._particles import per_body as per_body
from ._pivot import central_inertia as central_inertia, pivot_inertia as pivot_inertia
from ._state import RotState as RotState, Trajectory as Trajectory
from .scenes import SCENES as SCENES, Scene as Scene
from .schemes import (
    BROWNIAN_SCHEMES as BROWNIAN_SCHEMES,
    FLUID_SCHEMES as FLUID_SCHEMES,
    OVERDAMPED_SCHEMES as OVERDAMPED_SCHEMES,
    SCHEMES as SCHEMES,
    THERMAL_SCHEMES as THERMAL_SCHEMES,
    AbstractScheme as AbstractScheme,
    schemes_for as schemes_for,
)


__version__ = importlib.metadata.version("jaxrot")


# Every public name above but the submodules; tests/test_structure.py checks that none is missing.
__all__ = [
    "AbstractScheme",
    "BROWNIAN_SCHEMES",
    "BodyInertia",
    "Checkpoint",
    "Drive",
    "Experiment",
    "FLUID_SCHEMES",
    "FitResult",
    "FitWarning",
    "Fluid",
    "Identification",
    "IntegrationError",
    "MathematicalBody",
    "OVERDAMPED_SCHEMES",
    "RigidBodyTerm",
    "RotState",
    "SCENES",
    "SCHEMES",
    "Scene",
    "THERMAL_SCHEMES",
    "Trajectory",
    "body_inertia",
    "central_inertia",
    "compiler_options",
    "fit_inertia",
    "identify",
    "load_checkpoint",
    "overdamped_rollout",
    "per_body",
    "pivot_inertia",
    "reference_rollout",
    "rollout",
    "rollout_chunks",
    "save_checkpoint",
    "schemes_for",
    "solver",
]
