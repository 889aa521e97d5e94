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

One program. The default's and the candidates' residuals come from ONE compiled residual
program in which the scheme is data: a `SchemeSwitch` steps with ``jax.lax.switch`` on a
runtime index (`_model.Model.choice`), so the choice costs one compilation and one rollout
per scheme tried, and the fit then compiles its Jacobian program for the chosen scheme alone.
Each branch runs its scheme exactly as a model of that scheme alone would (its own carry, the
torque re-evaluated at a held control's switch where that scheme needs it): the measured
``e_w`` is the one the bound above is argued on. An a-priori bound from the step instead
(a scheme of order ``p`` errs by ``C_p (|ω| dt)^{p+1}`` a step) was not used: its constants
``C_p`` and the torque's derivatives would have to be guessed, and a guess low by 10× breaks
the guarantee. Measured (CPU seconds of one process, which load moves less than wall time; the
MuJoCo problem of `benchmarks/identify_speed.py`, 2 cores under load 12, jax 0.10.2): the
switched program of the three schemes compiles in 3.5-3.8 s (StableHLO 406 kB) against
2.2 + 1.4 + 1.8 = 5.4 s for the default's, zhao's and rkmk4's own (221 + 147 + 162 kB), and
runs the default as fast as its own program does (30 against 37 ms). Where zhao
passes (MuJoCo's 1 ms steps) the choice used to stop after two programs (3.6 s): no gain
there; where rkmk4 is tried, 3 programs → 1.
"""

import dataclasses
from typing import NamedTuple

import equinox as eqx
import jax
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


@dataclasses.dataclass(frozen=True)
class SchemeSwitch:
    """Several schemes as one: `_model.Model`'s static ``scheme`` when its ``choice`` picks one at run time.

    ``reinit[i]``: scheme ``i`` restarts its carry at every step (a held control with a scheme that
    carries a torque, `_problem.Problem.held`), as the model of that scheme alone does.
    """

    schemes: tuple
    reinit: tuple

    def bind(self, index):
        return _Bound(self, index)


class _Bound:
    """A `SchemeSwitch` with its runtime index: the scheme interface ``init``/``step``/``state``. The carry
    holds every scheme's own carry; a step advances the chosen one's (`jax.lax.switch`), so the others'
    cost nothing but their ``init``."""

    def __init__(self, switch, index):
        self.switch, self.index = switch, index

    def init(self, state, t0, inertia, torque, args):
        return tuple(s.init(state, t0, inertia, torque, args) for s in self.switch.schemes)

    def step(self, carry, t, dt, inertia, torque, args):
        def branch(i, scheme, reinit):
            def advance(carry):
                inner = carry[i]
                if reinit:
                    inner = scheme.init(scheme.state(inner), t, inertia, torque, args)
                inner = scheme.step(inner, t, dt, inertia, torque, args)
                return carry[:i] + (inner,) + carry[i + 1 :]

            return advance

        branches = [
            branch(i, *pair)
            for i, pair in enumerate(zip(self.switch.schemes, self.switch.reinit, strict=True))
        ]
        return jax.lax.switch(self.index, branches, carry)

    def state(self, carry):
        branches = [lambda c, i=i, s=s: s.state(c[i]) for i, s in enumerate(self.switch.schemes)]
        return jax.lax.switch(self.index, branches, carry)


@eqx.filter_jit
def _residuals(phi, model):
    return residuals(phi, model)


def choose_scheme(settings, problem, accuracy_step):
    """``(problem with the scheme to run, SchemeChoice)``: the problem unchanged unless the user left the
    scheme to identify, the controls force steps shorter than ``FORCED ×`` the accuracy step and the
    sample spacing, and every σ is given. One residual program (`SchemeSwitch`) for every scheme tried."""
    default = SchemeChoice(settings.scheme, "")
    if not settings.scheme_default or problem.estimated.any():
        return problem, default
    spacing = min(float(np.max(np.diff(e.t))) for e in settings.experiments)
    if not problem.max_step < FORCED * min(accuracy_step, spacing):
        return problem, default
    schemes = (problem.model.scheme, *CANDIDATES)
    reinit = tuple(problem.held and s.torque_evals_at_init > 0 for s in schemes)
    switched = dataclasses.replace(problem.model, scheme=SchemeSwitch(schemes, reinit), reinit=False)
    phi0 = jnp.asarray(problem.phi0, settings.dtype)

    def run(index):  # the same compiled program for every index: the index is an array
        model = dataclasses.replace(switched, choice=jnp.asarray(index, jnp.int32))
        return np.asarray(_residuals(phi0, model), np.float64)

    reference = run(0)
    if not np.all(np.isfinite(reference)):
        return problem, default
    for index, scheme in enumerate(CANDIDATES, start=1):
        error = float(np.linalg.norm(run(index) - reference))
        if error <= BIAS_BOUND:
            note = (
                f"{scheme.name} (chosen: the controls fix the step at {problem.max_step:.3g}, where its "
                f"whitened error on the start's model against the default's is {error:.2g} ≤ {BIAS_BOUND:g}: "
                f"no parameter moves by over {BIAS_BOUND:g} standard error)"
            )
            model = dataclasses.replace(problem.model, scheme=scheme, reinit=reinit[index])
            return problem._replace(model=model), SchemeChoice(scheme, note)
    return problem, default
