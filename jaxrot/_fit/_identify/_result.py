"""`identify`'s last stage: the `Identification` it returns, and its `StandardErrors`."""

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..._state import Trajectory
from .._covariance import correlations
from . import _report
from ._experiment import KINDS


class StandardErrors(NamedTuple):
    """Standard errors of `Identification`'s fields in their units: 0 where held, inf where undetermined."""

    inertia: np.ndarray  # (3, 3)
    args: Any  # a pytree like args
    q0: np.ndarray  # (k, 4)
    omega0: np.ndarray  # (k, 3)
    sensors: dict  # like Identification.sensors


class Identification(NamedTuple):
    """What `jaxrot.identify` found.

    Attributes:
        inertia: fitted body-frame tensor ``(3, 3)``; without any torque (no
            ``torque``, no ``control``) only its shape is determined and it has the
            trace of ``inertia0`` (1 when not given): ``scale_determined`` False.
        args: the torque arguments with the fitted leaves replaced; a leaf fitted
            ``"per_experiment"`` (or given per experiment) has a leading axis ``k``.
        q0: fitted initial orientation of each experiment ``(k, 4)``.
        omega0: fitted initial angular velocity of each experiment ``(k, 3)``, world frame.
        sensors: the sensor parameters named in ``identify``'s ``sensors`` (fitted or
            held), e.g. ``{"gyro_bias": (k, 3), "gyro_scale": (3,)}``.
        stderr: `StandardErrors` of the fields above (delta method through the
            parameterisation; inf for anything an undetermined combination moves).
        covariance: ``(p, p)`` covariance of the labelled parameters ``names``, in
            their own units: the inertia's six distinct elements (or the three moments),
            the shared free elements of ``args``, the shared fitted sensor parameters,
            then per experiment the rotation vector of ``q0`` from its fitted value (rad),
            ``omega0``, its ``"per_experiment"`` args and its gyro bias.
        names: the covariance's row labels, e.g. ``"inertia[0,1]"``, ``"args.dipole[2]"``,
            ``"sensors.gyro_scale[0]"``, ``"q0[1].rotation[0]"``, ``"omega0[1,2]"``,
            ``"args.mass[1]"`` (experiment 1's value), ``"sensors.gyro_bias[1,2]"``.
        units: each label's unit (``"M L²"``, ``"rad"``, ``"rad/time"``, ``"time"``, ``"1"``,
            ``"args"`` for the torque's own units).
        estimates: each label's value (the ``q0`` rotations are 0: offsets from the fit).
        correlation: the covariance as correlations ``(p, p)``.
        unidentified: labels of the parameters the data do not determine (an
            undetermined combination of the Jacobian's scaled columns moves them,
            or their standard error exceeds their own size), and in a fit that did not
            converge those its next Gauss–Newton step would still move by more than their
            standard error; empty when all are determined.
        converged: Gauss–Newton stopped on its tolerance, not on ``max_iter``.
        reliable: whether the standard errors can be trusted: the fit converged, its Jacobian
            was usable by the optimiser, and every sensor with a given σ has a whitened RMS
            near 1 (`problems` says what failed; `identify` then raises a `jaxrot.FitWarning`
            and ``summary()`` says so on its first line).
        problems: the failed checks, one sentence each (empty when ``reliable``).
        sigma: the noise level used per experiment and kind ``(k, 3)``
            (``q``, ``omega_body``, ``direction``), given or estimated; NaN where absent.
        residuals: per experiment, a dict of the whitened misfits ``(n, 3)`` of each
            observed kind (NaN where a sample is missing).
        trajectories: per experiment, the fitted model at its sample times (`Trajectory`).
        loss: final sum of squared whitened residuals.
        loss_history: the sum at each accepted iterate (each pass's start included) and at the end.
        n_iterations: Gauss–Newton iterations of the whole call (every pass; what ``max_iter`` bounds).
        scale_determined: whether a torque fixes the tensor's scale.
        dt: the largest integrator step used.
        scheme: the scheme's name or object (the one `identify` chose when it was left to it).
        scheme_note: why `identify` chose a scheme other than its default (empty otherwise).
    """

    inertia: jax.Array
    args: Any
    q0: jax.Array
    omega0: jax.Array
    sensors: dict
    stderr: StandardErrors
    covariance: np.ndarray
    names: tuple
    units: tuple
    estimates: np.ndarray
    correlation: np.ndarray
    unidentified: tuple
    converged: bool
    reliable: bool
    problems: tuple
    sigma: np.ndarray
    residuals: list
    trajectories: list
    loss: float
    loss_history: np.ndarray
    n_iterations: int
    scale_determined: bool
    dt: float
    scheme: Any
    scheme_note: str = ""

    def summary(self) -> str:
        """A report a person reads: each parameter ± its standard error in its units, the strongest
        correlations, per experiment and sensor the whitened residuals' RMS and lag-one
        autocorrelation (a model error shows as residuals correlated from one sample to the
        next), and the unidentified parameters.

        Example:
            >>> import jax.numpy as jnp, jaxrot
            >>> true = jaxrot.rollout("rkmk4", jaxrot.RotState(jnp.array([1.0, 0, 0, 0]),
            ...                       jnp.array([0.3, 0.1, 1.0])), jnp.array([1.0, 1.5, 2.0]), 0.01, 600,
            ...                       save_every=20)
            >>> fit = jaxrot.identify(jaxrot.Experiment(true.t, q=true.q, sigma_q=1e-3))
            >>> print(fit.summary().splitlines()[0])
            jaxrot.identify: 1 experiment(s), 12 parameters, converged after 3 iteration(s)
        """
        return _report.summary(self)

    def plot_residuals(self):
        """A matplotlib figure of the whitened residuals against time: a row per experiment, a column per
        sensor (tracker, gyro, tracked direction), the three components and the ±2 band.

        Returns a `matplotlib.figure.Figure` that pyplot does not hold (no global state to close):
        a notebook shows it as a cell's value once pyplot is imported; elsewhere ``fig.savefig(path)``.
        """
        return _report.plot_residuals(self)


def result(settings, problem, solution, found, problems=(), choice=None) -> Identification:
    """The `Identification` of a solved problem (`_solve.Solution`) and its `_uncertainty.Uncertainties`."""
    dtype = settings.dtype
    data = solution.model.data
    sigma = np.asarray(data.sigma, np.float64)
    whitened = solution.raw / sigma[:, :, None, None]
    q_fit, omega_world = solution.states
    trajectories, residual_dicts = [], []
    for j, e in enumerate(settings.experiments):
        n = e.t.shape[0]
        trajectories.append(
            Trajectory(
                jnp.asarray(e.t, dtype),
                jnp.asarray(q_fit[j, :n], dtype),
                jnp.asarray(omega_world[j, :n], dtype),
            )
        )
        parts = {}
        for a, (name, _, _, _) in enumerate(KINDS):
            if settings.counts[j, a]:
                r = whitened[j, a, :n].copy()
                r[np.asarray(data.weight)[j, a, :n] == 0] = np.nan
                parts[name] = r
        residual_dicts.append(parts)
    inertia, args, q0, omega0, sensors = found.fitted
    se_inertia, se_args, se_q0, se_omega0, se_sensors = found.stderr
    fitted_args = any(leaf.mode is not None or leaf.per_experiment is not None for leaf in settings.leaves)
    return Identification(
        inertia=jnp.asarray(inertia, dtype),
        args=jax.tree_util.tree_map(lambda x: jnp.asarray(x, dtype), args) if fitted_args else settings.args,
        q0=jnp.asarray(q0, dtype),
        omega0=jnp.asarray(omega0, dtype),
        sensors={name: jnp.asarray(value, dtype) for name, value in sensors.items()},
        stderr=StandardErrors(se_inertia, se_args, se_q0, se_omega0, se_sensors),
        covariance=found.covariance,
        names=found.names,
        units=found.units,
        estimates=found.estimates,
        correlation=correlations(found.covariance),
        unidentified=found.unidentified,
        converged=solution.converged,
        reliable=not problems,
        problems=tuple(problems),
        sigma=np.where(settings.counts > 0, sigma, np.nan),
        residuals=residual_dicts,
        trajectories=trajectories,
        loss=float(solution.history[-1]),
        loss_history=solution.history,
        n_iterations=solution.n_iterations,
        scale_determined=not settings.unit_scale,
        dt=problem.max_step,
        scheme=settings.scheme_arg if choice is None or not choice.note else choice.scheme,
        scheme_note="" if choice is None else choice.note,
    )
