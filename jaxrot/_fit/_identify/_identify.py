"""`identify`: a rigid body's parameters from several experiments' telemetry, with their uncertainty.

Six named stages, each in its own module: every argument checked, the `Settings`
(`_check`) → the `Start` (`_start`) → the `Problem`, the `Model` and ``φ₀`` (`_problem`,
on the model and its `residuals` in `_model`) → Gauss–Newton, the `Solution` (`_solve`) →
the uncertainty (`_uncertainty`) → the result, an `Identification` (`_result`, its report
`_report`).
"""

import warnings
from collections.abc import Sequence

from ._check import check_arguments
from ._experiment import Experiment
from ._health import FitWarning, diagnose
from ._problem import build_problem
from ._result import Identification, result
from ._scheme import (
    DEFAULT_SCHEME as DEFAULT_SCHEME,  # re-exported: the benchmarks name it
    choose_scheme,
)
from ._solve import solve
from ._start import starting_point
from ._uncertainty import uncertainty


def identify(
    experiments: Experiment | Sequence[Experiment],
    *,
    torque=None,
    args=None,
    free_args=None,
    inertia0=None,
    free_inertia: bool | str = True,
    scheme=None,
    dt: float | None = None,
    q0=None,
    omega0=None,
    max_iter: int = 100,
    ftol: float = 1e-10,
    rcond: float | None = None,
    sensors: dict | None = None,
) -> Identification:
    r"""Fit a rigid body's inertia, torque parameters and initial states to several experiments.

    The model steps each experiment with ``scheme`` from its fitted ``(q₀, ω₀)``
    under ``torque(t, q, ω, args)`` plus the experiment's known ``control``
    torque, and minimises the sum of squared whitened residuals
    (misfit / σ) of every observation (`jaxrot.Experiment`):

    - orientation: the rotation vector ``2 v sign(w)`` of ``q_obs* ⊗ q = (w, v)``
      (rad, sign invariant);
    - gyro: the body-frame angular velocity ``q* ⊗ ω ⊗ q − ω_b,obs``;
    - tracked axis: ``rotate(q, b) − d_obs`` (2 informative components).

    Sensors (``sensors``, see below) read the model as real ones do: a gyro with a bias
    per experiment, a scale factor and a delay, a star tracker mounted at a rotation of
    the body frame and with a delay of its own. Controls may be world- or body-frame,
    interpolated or held (`jaxrot.Experiment`); the model's steps land on every control
    and sample time.

    Fitted, jointly over all experiments: the inertia (``free_inertia=True``:
    the full tensor through `inertia_from_cholesky`, always positive definite
    with the triangle inequality; ``"moments"``: the principal moments, with the
    axes of ``inertia0`` held; ``False``: ``inertia0`` held), the leaves of
    ``args`` that ``free_args`` marks (True; ``"positive"`` keeps a leaf > 0
    through a log; ``"per_experiment"`` fits one value per experiment, starting from that
    experiment's ``args`` or from ``args``), the fitted sensor parameters, and each
    experiment's ``q₀`` and ``ω₀``. Without any torque the tensor's scale is not
    determined: it keeps the trace of ``inertia0``.

    Optimiser: the Gauss–Newton of `fit_inertia` (forward-mode Jacobian through
    the rollout, Armijo backtracking), every pass in one compiled loop: a start whose
    modelled orientations are more than 1 rad off the data (or gyro rates off by their size)
    is first fitted over growing windows of the records, a closer one over the whole
    records at once (`_identify._solve`). Noise: a kind whose σ
    is None has it estimated from its residuals,
    ``σ² = RSS_kind / (m_kind (1 − n/m))`` (``m`` informative residuals, ``n``
    parameters); when several kinds are weighed against each other the fit is
    repeated once with the estimated σ.

    Uncertainty: ``Cov ≈ (JᵀJ)⁻¹`` at the optimum (whitened residuals), carried
    to the reported units by the delta method. Directions whose singular value
    of the column-scaled ``J`` falls below ``rcond`` (default √eps of the dtype)
    times the largest are undetermined: the parameters they move are listed in
    ``unidentified``, get infinite standard errors and a warning.

    Default scheme: ``RKMKDopri5(chart="cayley")`` (fifth-order Lie-group Runge–Kutta
    in Cayley coordinates, `jaxrot.schemes.RKMKDopri5`) at steps turning the body by at
    most 0.6 rad at the largest ``|ω|`` seen. Measured on the three-manoeuvre satellite
    of ``tests/_telemetry.py`` (noise-free data from the reference solver, 5 s sample
    spacing, |ω| ≤ 0.12 rad/s; bias = the largest parameter error in standard errors of
    the noisy fit; 2-core CPU, float64, one run each, so fit times within ±20 % are
    noise; reproduced by ``benchmarks/identify_schemes.py``):

    ===========  ==========  ========  =================  =======  ==============
    scheme       step (rad)  substeps  bias / std. error  fit (s)  first call (s)
    ===========  ==========  ========  =================  =======  ==============
    zhao         0.05        9         4.3                0.22     4.0
    zhao         0.2         3         38                 0.11     4.6
    rkmk4        0.05        9         8e-5               0.41     5.9
    rkmk4        0.2         3         0.0066             0.14     5.8
    rkmk4        0.5         1         0.6                0.10     —
    rkmk_dopri5  0.15        3         3e-5               0.25     5.7
    rkmk_dopri5  0.3         2         8e-5               0.17     5.7
    rkmk_dopri5  0.6         1         0.0015             0.10     5.2
    … cayley     0.3         2         2e-4               0.16     5.8
    … cayley     0.6         1         0.0066             0.11     4.8
    splitting    0.05        9         0.46               0.33     12.2
    ===========  ==========  ========  =================  =======  ==============

    (``… cayley``: ``RKMKDopri5(chart="cayley")``.) Second-order schemes bias the fit by
    several standard errors at any step that runs as fast; the fifth-order pair at one
    step per sample leaves a bias under 1 % of a standard error with the fewest stages
    per sample (6, against ``rkmk4``'s 12 at 0.2 rad). Of its two charts, the Cayley
    map (rational, no trigonometry) biases 4× more (0.66 % of a standard error against
    0.15 %) and its Jacobian rollout, the cost of each iteration, runs 1.24× faster
    (8.45 against 10.46 ms, median of 15 interleaved rounds, same process).

    Args:
        experiments: one `jaxrot.Experiment` or a sequence of them.
        torque: world-frame torque model ``torque(t, q, omega, args) -> (3,)``
            (None: only the experiments' controls, or torque-free).
        args: its arguments, a pytree (e.g. a dict of arrays).
        free_args: which leaves of ``args`` are fitted: a pytree of True / False /
            ``"positive"`` / ``"per_experiment"`` with the structure of ``args``, or a
            dict naming some of its keys (the others held). A leaf that an
            experiment's ``args`` gives is held at that experiment's value unless
            marked ``"per_experiment"``.
        inertia0: starting (or held) tensor ``(3, 3)`` or principal moments
            ``(3,)``; None: a linear angular-momentum estimate from the
            experiment with the most orientation samples.
        free_inertia: True, ``"moments"`` or False (see above).
        scheme: integrator name or object; None: the default above, or, when the controls' sample times
            force steps shorter than half the default's and every σ is given, the cheapest of ``zhao``,
            ``rkmk4`` (Cayley chart) and the default whose error on the start's model keeps every
            parameter's bias below 0.1 standard error (`_identify._scheme`; the summary names the
            choice and its measured error).
        dt: largest step (each sample interval is cut into equal steps).
        q0, omega0: starting initial states ``(k, 4)``, ``(k, 3)`` instead of
            those read from the data (needed when a record starts far from
            anything its observations suggest).
        max_iter: the cap on Gauss–Newton iterations of the whole call (windows, the whole record
            and the refit with estimated σ together).
        ftol: stop when the next step's predicted decrease is ``≤ ftol ×`` the
            objective, or the objective is at the round-off floor.
        rcond: singular-value ratio below which a direction is undetermined.
        sensors: a dict naming sensor parameters, each ``True`` (fitted from its ideal
            value) or an array (held there): ``"gyro_bias"`` ``(k, 3)`` one per
            experiment [rad/time], ``"gyro_scale"`` ``(3,)`` or one number for the three
            axes [1], ``"gyro_delay"`` ``()``
            [time] (gyro reading ``= gyro_scale ⊙ ω_b(t − gyro_delay) + gyro_bias``),
            ``"tracker_mount"`` ``(3,)``, the rotation vector of the tracker's frame in
            the body frame [rad], and ``"tracker_delay"`` ``()`` [time] (tracker reading
            ``= q(t − tracker_delay) ⊗ exp(tracker_mount)``). A delay should stay well
            inside the record (the state before its start is extrapolated by one step).
            Delays are relative to the controls' and the torque's clock: with neither,
            a common shift of both delays is undetermined and is reported so.

    A failed fit is loud: when Gauss–Newton did not converge, its Jacobian was too
    ill-conditioned for its own steps, or a sensor whose σ is given has whitened residuals far
    above 1 (the model does not fit the data; thresholds argued in `_identify._health`),
    ``identify`` warns with a `jaxrot.FitWarning`, the result has ``reliable`` False and its
    ``problems``, the summary's first line says so and its standard errors are headed
    "unreliable"; a fit that did not converge also names in ``unidentified`` the parameters
    its next step would still move by more than their standard error.

    Returns:
        `Identification` (``summary()`` prints a report, ``plot_residuals()`` draws the
        whitened residuals).

    Warns:
        jaxrot.FitWarning: a fit that cannot be trusted (above), or parameters the data do not
            determine (``unidentified``).

    Raises:
        ValueError: before any compilation, for a bad experiment, a ``free_args``
            naming what is not in ``args``, experiment ``args`` that are not a subset of
            ``args``, an unknown sensor key, a sensor parameter without that sensor's
            data, a bad ``inertia0`` or option.

    Example:
        >>> import jax.numpy as jnp, numpy as np, jaxrot
        >>> true = jaxrot.rollout("rkmk4", jaxrot.RotState(jnp.array([1.0, 0, 0, 0]),
        ...                       jnp.array([0.3, 0.1, 1.0])), jnp.array([1.0, 1.5, 2.0]), 0.01, 600,
        ...                       save_every=20)
        >>> exp = jaxrot.Experiment(true.t, q=true.q, sigma_q=1e-3)
        >>> fit = jaxrot.identify(exp)  # torque-free: the moments up to scale
        >>> m = np.linalg.eigvalsh(np.asarray(fit.inertia))
        >>> print((m / m[0]).round(4).tolist(), fit.converged)
        [1.0, 1.5, 2.0] True
    """
    settings = check_arguments(
        experiments, torque=torque, args=args, free_args=free_args, inertia0=inertia0,
        free_inertia=free_inertia, scheme=scheme, dt=dt, q0=q0, omega0=omega0, max_iter=max_iter,
        ftol=ftol, rcond=rcond, sensors=sensors,
    )  # fmt: skip
    start = starting_point(settings)
    problem = build_problem(settings, start)
    problem, choice = choose_scheme(settings, problem, start.max_step)
    solution = solve(problem, settings, start.speed)
    found = uncertainty(solution, settings)
    health = diagnose(settings, solution, found, problem.estimated)
    if health.unsettled:
        extra = tuple(name for name in health.unsettled if name not in found.unidentified)
        found = found._replace(unidentified=found.unidentified + extra)
    if health.problems:
        names = ", ".join(health.unsettled)
        moving = f", and unidentified names {names}, still moving" if health.unsettled else ""
        warnings.warn(
            f"identify: the fit cannot be trusted: {'; '.join(health.problems)}. Its standard errors are "
            f"unreliable (Identification.reliable is False{moving}); fit.summary() shows the residuals of "
            "each sensor.",
            FitWarning,
            stacklevel=2,
        )
    elif found.unidentified:
        warnings.warn(
            "identify: the data do not determine " + ", ".join(found.unidentified) + " (see "
            "Identification.unidentified; their standard errors are infinite where a combination of "
            "parameters is undetermined). Fix them, or add experiments or observations that excite them.",
            FitWarning,
            stacklevel=2,
        )
    return result(settings, problem, solution, found, health.problems, choice)
