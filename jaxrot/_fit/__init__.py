"""Fitting rigid bodies to data: `fit_inertia` (one body, full orientations) and `identify` (telemetry).

Both stacks speak one vocabulary, one module per stage:

    Settings  →  Start  →  Model  →  residuals(phi, model)  →  Solution  →  result

==============  ===========================================  ==============================================
stage           `fit_inertia` (`_fit_inertia/`)              `identify` (`_identify/`)
==============  ===========================================  ==============================================
settings        `_model.Settings` (checked observations)     `_check.Settings` (every argument checked)
start           `_start.starting_point` (`_Params`)          `_start.Start`
model           `_model.Model` (padded segments)             `_model.Model`; `_problem.Problem` = it + ``φ₀``
residuals       `_residuals.residuals`                       `_model.residuals`
solution        `_solve.Solution` (Adam, Gauss–Newton)       `_solve.Solution` (windows, noise levels)
result          `_fit_inertia.FitResult`                     `_uncertainty` → `_result.Identification`
==============  ===========================================  ==============================================

`identify`'s data are `_identify/_experiment` (`Experiment`), `_controls` and `_sensors`;
its report is `_identify/_report`. Each stack's entry point runs its stages:
`_fit_inertia/_fit_inertia.fit_inertia` and `_identify/_identify.identify`.

The shared floor, which imports neither stack: `_parameterisation` (the physical tensor
parameters, `inertia_from_cholesky`), `_initial` (`estimate_omega`, the linear
angular-momentum estimate both starts use), `_misfit` (the orientation misfit and its
signed rotation vector), `_optimiser` (`gauss_newton`) and `_covariance` (covariance,
standard errors and identifiability from the Jacobian at the optimum).

`fit_inertia`: the model is a rigid body stepped by a jaxrot scheme (Zhao–van Wachem by
default) from a fitted initial state; the objective is the mean squared geodesic angle
between modelled and observed orientations (plus, when given, angular velocities). The
tensor is parameterised so that only physically possible tensors can come out
(`inertia_from_cholesky`); the optimiser is Gauss–Newton, started from a linear
angular-momentum-balance estimate (see `fit_inertia` for the reasons). Long horizons: the
scan over time is split into checkpointed chunks of about ``√N`` steps (``jax.checkpoint``
around an inner ``lax.scan``), so the memory of a gradient through ``N`` steps grows like
``√N``; chaotic motion can be fitted by multiple shooting (``segments > 1``).
"""

from ._fit_inertia._fit_inertia import FitResult as FitResult, fit_inertia as fit_inertia
from ._identify._experiment import Experiment as Experiment
from ._identify._health import FitWarning as FitWarning
from ._identify._identify import identify as identify
from ._identify._result import Identification as Identification, StandardErrors as StandardErrors
from ._initial import estimate_omega as estimate_omega
from ._parameterisation import (
    cholesky_from_inertia as cholesky_from_inertia,
    inertia_from_cholesky as inertia_from_cholesky,
)
