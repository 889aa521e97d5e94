"""`identify`: a rigid body's parameters from several experiments' telemetry, with their uncertainty.

The data: `_experiment` (`Experiment`, one manoeuvre's data), `_controls` (the step grid of
sampled controls), `_sensors` (the sensor parameters and their models). Its stages, one
module each: `_check` (`check_arguments`: the `Settings`) → `_start` (`starting_point`: the
`Start`) → `_problem` (`build_problem`: the `Problem`, the `Model` of `_model` and its start
``φ₀``; `_model` holds `residuals(phi, model)`) → `_solve` (`solve`: the `Solution`) →
`_uncertainty` (`uncertainty`: on the shared `_covariance`) → `_result` (`Identification`,
with its report `_report`); `_identify` (`identify`) runs them.
"""
