"""Whether an `identify` fit can be trusted: the checks behind `Identification.reliable` and `FitWarning`.

The standard errors ``(JᵀJ)⁻¹`` hold for a fit that (1) stopped at its optimum, (2) whose
Jacobian the optimiser could use, and (3) whose model explains the data down to the noise.
Each is checked, and a failure is named in ``problems`` (one sentence each):

1. **Not converged**: Gauss–Newton stopped on ``max_iter`` or after `MAX_REJECTIONS` failed
   halvings, not on its tolerance. The parameters the next Gauss–Newton step would move by
   more than their standard error are not settled; they are named in ``unidentified``.
2. **Ill-conditioned Jacobian**: the Gauss–Newton step (`_optimiser._least_squares_step`)
   drops the directions of the *unscaled* ``J`` whose singular value is below
   ``eps · max(m, n)`` of the largest (lineax's and numpy's rank cut-off: below it a
   singular value is round-off). The covariance is read from the *column-scaled* ``J``
   and keeps every direction above ``rcond`` (√eps) there. A direction that the covariance
   keeps while the optimiser cannot see it was never fitted: its standard errors describe
   an optimum that was not reached. Also a Jacobian or loss that is not finite.
3. **The model does not fit the data**: with σ given, the loss is χ² with ``ν = m − n``
   degrees of freedom for a model that holds (m informative residuals, n parameters):
   mean ``ν``, standard deviation ``√(2ν)``. A series (one experiment's one sensor, ``mᵢ``
   residuals, ``νᵢ = mᵢ (1 − n/m)`` of the freedom) is flagged when its sum of squares
   exceeds both ``νᵢ + Z_CHI2 √(2νᵢ)`` (``Z_CHI2 = 10``: never reached by chance, a
   10-σ excess, probability < 1e-7 even at ``νᵢ = 10`` where the χ² tail is heaviest
   of those a fit meets) and ``RMS_FACTOR² νᵢ`` (whitened RMS above 2: the given σ
   would understate the misfit, and the standard errors, by more than 2×, far beyond a
   spec sheet's σ being somewhat off). A σ that `identify` estimated makes the RMS 1 by
   construction; there the lag-one autocorrelation of the summary is the evidence.
"""

from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from ._experiment import KINDS


Z_CHI2 = 10.0  # a series' excess over its χ² mean, in its standard deviations, that chance never reaches
RMS_FACTOR = 2.0  # and its whitened RMS above which the given σ understate the misfit by too much


class FitWarning(UserWarning):
    """`jaxrot.identify`'s warning that a fit cannot be trusted as it stands: it did not converge, its
    Jacobian is too ill-conditioned for its steps, its model does not fit the data, or the data do
    not determine some parameters (``Identification.problems`` and ``unidentified`` say which)."""


class Health(NamedTuple):
    problems: tuple  # sentences, empty for a fit that can be trusted
    unsettled: tuple  # labels of the parameters a non-converged fit would still move by > 1 std. error


def diagnose(settings, solution, found, estimated) -> Health:
    """The `Health` of a solved fit (`_solve.Solution`, `_uncertainty.Uncertainties`, ``estimated``
    the ``(k, 3)`` σ that were estimated)."""
    problems, unsettled = [], ()
    sigma = np.asarray(solution.model.data.sigma, np.float64)
    whitened = solution.raw / sigma[:, :, None, None]
    jac = np.asarray(solution.jac, np.float64)
    r = whitened.reshape(-1)
    finite = bool(np.all(np.isfinite(jac)) and np.all(np.isfinite(r)))
    if not solution.converged:
        problems.append(
            f"not converged after {solution.n_iterations} iteration(s) (max_iter reached or no step "
            "decreased the loss)"
        )
    if not finite:
        problems.append("the residuals or their Jacobian are not finite at the end")
    else:
        dropped = _dropped_directions(found, settings.dtype, jac.shape)
        if dropped:
            problems.append(
                f"the Jacobian is too ill-conditioned for Gauss–Newton: {dropped} direction(s) that the "
                "covariance keeps are below its steps' round-off cut-off (eps · max(m, n)), so they were "
                "never fitted; rescale the parameters (units) or hold some"
            )
        if not solution.converged:
            unsettled = _unsettled(jac, r, found)
    misfits = _misfits(settings, whitened, estimated)
    if misfits:
        problems.append(
            "the model does not fit the data: whitened residual RMS "
            + ", ".join(misfits)
            + f" (a model that holds gives ≈ 1; flagged above {RMS_FACTOR:g} and {Z_CHI2:g} χ² standard "
            "deviations): a torque, sensor flaw or frame is missing or wrong, or the given σ are too small"
        )
    return Health(tuple(problems), unsettled)


def _dropped_directions(found, dtype, shape):
    """How many directions kept by the covariance (column-scaled ``J``, above ``rcond``) the
    Gauss–Newton step drops (unscaled ``J`` of ``shape``, below ``eps · max(m, n)`` of the fit's dtype)."""
    s_raw = found.raw_singular_values
    if s_raw.size == 0 or not s_raw[0] > 0:
        return 0
    seen = int(np.sum(s_raw > float(jnp.finfo(dtype).eps) * max(shape) * s_raw[0]))
    return max(found.kept - seen, 0)


def _unsettled(jac, r, found):
    """Labels of the parameters the next full Gauss–Newton step moves by more than their standard error."""
    step, *_ = np.linalg.lstsq(jac, -r, rcond=None)
    g = found.parameter_jacobian
    move = np.abs(g @ step)
    se = np.sqrt(np.maximum(np.diag(found.covariance), 0))
    with np.errstate(invalid="ignore"):
        flags = ~(move <= se)  # also where the step or the error is not finite
    return tuple(name for name, flag in zip(found.names, flags, strict=True) if flag)


def _misfits(settings, whitened, estimated):
    """``"experiment j gyro 85"``-like strings for each series with given σ whose misfit is far above
    its noise (module docstring, point 3)."""
    dof = np.array([d for _, _, _, d in KINDS], np.float64)
    m_info = float(np.sum(settings.counts * dof))
    shrink = max(1 - settings.n_params / m_info, 1e-12)
    out = []
    names = {"q": "tracker", "omega_body": "gyro", "direction": "direction"}
    for j in range(settings.k):
        for a, (name, _, _, _) in enumerate(KINDS):
            count = settings.counts[j, a]
            if not count or estimated[j, a]:
                continue
            rss = float(np.sum(whitened[j, a] ** 2))
            nu = count * dof[a] * shrink
            if rss > nu + Z_CHI2 * np.sqrt(2 * nu) and rss > RMS_FACTOR**2 * nu:
                out.append(f"{np.sqrt(rss / nu):.3g} (experiment {j} {names[name]})")
    return out
