"""`identify`'s default scheme sized to the step the data force: the cheapest one far below the noise.

The default, `DEFAULT_SCHEME` (`RKMKDopri5` in Cayley coordinates, six torque evaluations
a step), is chosen for steps that turn the body by up to 0.6 rad (`_start`). When the
controls' sample times force shorter steps (MuJoCo's 1 ms held motor commands, flight
software's control cycle), a cheaper scheme may be as good at that step: `CANDIDATES`,
cheapest first, are tried, and the first whose error passes `BIAS_BOUND` is used.

The bound. A model error ``e`` (per residual, whitened: ``e/σ``) moves the least-squares
optimum by ``δ = (JᵀJ)⁻¹ Jᵀ e_w``; for any combination ``cᵀθ`` of the parameters,
``|cᵀδ| ≤ ‖P e_w‖ · se(cᵀθ) ≤ ‖e_w‖₂ · se(cᵀθ)`` (Cauchy–Schwarz in the metric ``JᵀJ``, ``P``
the projection on J's columns). So ``‖e_w‖₂ ≤ BIAS_BOUND`` keeps every parameter's bias
below ``BIAS_BOUND`` of its standard error, whatever the Jacobian. ``e_w`` is measured on the
start's model: the candidate's whitened residuals at ``φ₀`` minus the default scheme's on the
same grid (the data cancel), so the bound is on the shift from the default scheme's fit (whose
own error is of higher order in the step). The start's parameters are not the optimum's, so
the bound is a tenth, not one: the error scales with ``|ω|^{p+1}`` and the torque's
derivatives, which the start has within tens of percent.

Only when every σ is given (an estimated σ is not known before the fit) and the user named
no scheme. The summary prints the choice and the measured ``‖e_w‖``.
"""

import dataclasses
from typing import NamedTuple

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ...schemes import RKMK4, RKMKDopri5, Zhao
from ._model import residuals


DEFAULT_SCHEME = RKMKDopri5(chart="cayley")
CANDIDATES = (Zhao(), RKMK4(chart="cayley"))  # cheaper than the default: 2 and 4 torque evaluations a step
BIAS_BOUND = 0.1  # ‖whitened model error‖₂: every parameter's bias below this many standard errors
# The controls fix the step when the grid's longest step is below this fraction of both the accuracy step and
# the sample spacing (every experiment's longest sample interval): the samples alone would allow twice it.
FORCED = 0.5


class SchemeChoice(NamedTuple):
    """Which scheme the fit runs and why."""

    scheme: object
    note: str  # a sentence for the summary ("" when the user named the scheme or nothing was tried)


@eqx.filter_jit
def _residuals(phi, model):
    return residuals(phi, model)


def choose_scheme(settings, problem, accuracy_step):
    """``(problem with the scheme to run, SchemeChoice)``: the problem unchanged unless the user left the
    scheme to identify, the controls force steps shorter than ``FORCED ×`` the accuracy step and the
    sample spacing, and every σ is given."""
    default = SchemeChoice(settings.scheme, "")
    if not settings.scheme_default or problem.estimated.any():
        return problem, default
    spacing = min(float(np.max(np.diff(e.t))) for e in settings.experiments)
    if not problem.max_step < FORCED * min(accuracy_step, spacing):
        return problem, default
    phi0 = jnp.asarray(problem.phi0, settings.dtype)
    reference = np.asarray(_residuals(phi0, problem.model), np.float64)
    if not np.all(np.isfinite(reference)):
        return problem, default
    for scheme in CANDIDATES:
        model = dataclasses.replace(
            problem.model, scheme=scheme, reinit=problem.held and scheme.torque_evals_at_init > 0
        )
        error = float(np.linalg.norm(np.asarray(_residuals(phi0, model), np.float64) - reference))
        if error <= BIAS_BOUND:
            note = (
                f"{scheme.name} (chosen: the controls fix the step at {problem.max_step:.3g}, where its "
                f"whitened error on the start's model against the default's is {error:.2g} ≤ {BIAS_BOUND:g}: "
                f"no parameter moves by over {BIAS_BOUND:g} standard error)"
            )
            return problem._replace(model=model), SchemeChoice(scheme, note)
    return problem, default
