"""Fitting rigid bodies to data: `fit_inertia` (one body, full orientations) and `identify` (telemetry).

Two stacks share the parameterisation, the linear start and the optimiser.

`identify` (several experiments, any sensors, torque and sensor parameters, uncertainty):
`_experiment` (`Experiment`, one manoeuvre's data), `_controls` (the step grid of sampled
controls), `_sensors` (the sensor parameters and their models), then one module per stage:
`_identify_check` → `_identify_start` → `_identify_problem` (on the model `_identify_model`)
→ `_identify_solve` → `_identify_uncertainty` (on `_uncertainty`) → `_identification`
(the result) and `_report` (its summary and residual figure); `_identify` runs them.

`fit_inertia`:
The model is a rigid body stepped by a jaxrot scheme (Zhao–van Wachem by
default) from a fitted initial state; the objective is the mean squared
geodesic angle between modelled and observed orientations (plus, when given,
angular velocities). The tensor is parameterised so that only physically
possible tensors can come out (`inertia_from_cholesky`); the optimiser is
Gauss–Newton, started from a linear angular-momentum-balance
estimate (see `fit_inertia` for the reasons).

Long horizons: the scan over time is split into checkpointed chunks of about
``√N`` steps (``jax.checkpoint`` around an inner ``lax.scan``), so the memory of a
gradient through ``N`` steps grows like ``√N``; chaotic motion can be fitted by
multiple shooting (``segments > 1``).

One concept per module: `_parameterisation` (the physical tensor parameters),
`_problem` (checked observations, segments, the model's configuration),
`_objective` (the model and its misfits), `_initial` (the linear start),
`_optimiser` (Gauss–Newton) and `_fit_inertia` (the entry point).
"""

from ._experiment import Experiment as Experiment
from ._fit_inertia import FitResult as FitResult, fit_inertia as fit_inertia
from ._identification import Identification as Identification, StandardErrors as StandardErrors
from ._identify import identify as identify
from ._initial import estimate_omega as estimate_omega
from ._objective import (
    _objective as _objective,
    _residuals as _residuals,
    _single_shooting_loss as _single_shooting_loss,
    _value_and_grad as _value_and_grad,
)
from ._optimiser import _round_off_floor as _round_off_floor
from ._parameterisation import (
    _flat as _flat,
    _Params as _Params,
    _unflat as _unflat,
    cholesky_from_inertia as cholesky_from_inertia,
    inertia_from_cholesky as inertia_from_cholesky,
)
from ._problem import _build_problem as _build_problem
