"""`fit_inertia`: one body's inertia tensor and initial state from its observed orientations.

Its stages, one module each: `_model` (`build_model`: the checked observations, `Settings`,
and the `Model`, the padded segments and the rollout's configuration) → `_start`
(`starting_point`: the parameters it starts from) → `_residuals` (`residuals(params, model)`,
and the objective) → `_solve` (`solve`: Adam warm-up and Gauss–Newton, the `Solution`) →
`_fit_inertia` (`fit_inertia`, which runs them and returns the `FitResult`).
"""
