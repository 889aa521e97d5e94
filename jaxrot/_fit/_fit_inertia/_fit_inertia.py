"""`fit_inertia`, the public entry point: it runs the stages (`_model` → `_start` → `_solve`) and returns
the `FitResult`."""

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ... import quaternion as quat
from ..._state import Trajectory
from ..._validation import check_int, check_weight
from .._parameterisation import inertia_from_cholesky
from ._model import build_model
from ._residuals import residuals, unpack
from ._solve import round_off_floor, solve
from ._start import starting_point


class FitResult(NamedTuple):
    """What `fit_inertia` found.

    Attributes:
        inertia: fitted body-frame tensor ``(3, 3)`` (symmetric, positive
            definite, triangle inequality). Torque-free fits are normalised to
            ``trace(inertia) == 1`` (only the ratios are determined); with a
            torque it is in the units of the torque × time².
        moments: its principal moments ``(3,)``, ascending.
        axes: its principal axes ``(3, 3)`` in the body frame, one per column, in
            the order of ``moments`` (``inertia = axes @ diag(moments) @ axes.T``).
        q0: fitted initial orientation ``(4,)`` (scalar first, body → world).
        omega0: fitted initial angular velocity ``(3,)``, world frame.
        trajectory: the fitted model at the observed times (`Trajectory`); with
            multiple shooting each segment starts from its own fitted state.
        loss: final objective (scalar, ≥ 0; rad² for the orientation part).
        rms_angle: root-mean-square geodesic misfit of the orientations (rad).
        loss_history: objective before each optimiser iteration and at the end
            ``(n_iterations + 1,)`` (Adam steps first, if any, then Gauss–Newton).
        converged: True when Gauss–Newton stopped on its tolerance (predicted
            relative decrease of the objective ≤ ``ftol``, or the objective down
            to round-off: see ``ftol`` in `fit_inertia`), not on ``max_iter`` or
            a failed line search.
        n_iterations: optimiser iterations run (Adam + Gauss–Newton).
        initial_inertia: the linear angular-momentum-balance estimate the fit
            started from ``(3, 3)`` (same normalisation as ``inertia``).
        dt: the largest integrator step used.
        scale_determined: False for a torque-free fit (tensor normalised to unit
            trace), True with a torque.
    """

    inertia: jax.Array
    moments: jax.Array
    axes: jax.Array
    q0: jax.Array
    omega0: jax.Array
    trajectory: Trajectory
    loss: jax.Array
    rms_angle: jax.Array
    loss_history: jax.Array
    converged: bool
    n_iterations: int
    initial_inertia: jax.Array
    dt: float
    scale_determined: bool


def fit_inertia(
    observed: Trajectory,
    *,
    torque=None,
    args=None,
    scheme="zhao",
    dt=None,
    substeps=None,
    inertia0=None,
    omega0=None,
    segments: int = 1,
    continuity_weight: float = 100.0,
    omega_weight: float = 1.0,
    adam_steps: int = 0,
    adam_learning_rate: float = 1e-2,
    max_iter: int = 500,
    ftol: float = 1e-7,
    checkpoint: bool = True,
    checkpoint_every: int | None = None,
    normalize: bool = False,
) -> FitResult:
    r"""Fit a body-frame inertia tensor and the initial state to observed orientations of one body.

    The model steps the body with ``scheme`` from ``(q0, ω0)`` through the
    observed times and minimises the mean squared geodesic misfit
    ``4 |v|² = 4 sin²(θ/2) ≈ θ²`` of ``q_obs* ⊗ q = (w, v)`` (rad², sign
    invariant) over the observations, plus ``omega_weight · |ω − ω_obs|²``
    when ``observed.omega`` is given.
    Fitted: the full tensor (principal moments and axes, through
    `inertia_from_cholesky`: always symmetric, positive definite and obeying the
    triangle inequality), ``ω0`` and ``q0`` (a rotation-vector offset from
    ``observed.q[0]``, which is noisy too).

    Identifiability: without torque, Euler's equations ``I ω̇ = −ω × I ω`` are
    unchanged by ``I → c I``: only the ratios of the moments (and the axes) are
    determined, and the result is normalised to ``trace(inertia) == 1``. With a
    known torque the scale is determined too (units: torque × time²).

    Start: a linear estimate. The angular-momentum balance
    ``R_k I R_kᵀ ω_k − L₀ = ∫₀^{t_k} τ dt`` is linear in ``(I, L₀)``; it is solved by
    least squares (torque-free: the smallest singular vector) with ``ω_k`` from
    three-point differences of the observed ``q`` (or the observed ``ω``), and
    ``ω0 = R₀ I⁻¹ R₀ᵀ L₀``. It lands within ~0.3 % of the tensor, inside the basin
    of the nonlinear fit, so no multi-start is needed.

    Optimiser: Gauss–Newton (the step from a least-squares solve with ``J``, ``J`` by
    forward-mode differentiation of the residuals through the rollout) with a
    backtracking Armijo search from the full step, compiled as one loop. Why: the
    misfit of a long rollout is a narrow curved valley (the phase of the motion
    is very sensitive to ``I`` and ``ω0``: 0.3 % in ``I`` costs 0.2 rad of misfit
    over 10 s), with parameter sensitivities spread over ~5 decades; Gauss–Newton
    takes its curvature from ``JᵀJ``, so the spread costs it nothing, and it
    reaches the noise floor in 3–5 iterations on the test problems. It replaced
    L-BFGS in Gauss–Newton-whitened coordinates, which took 2.7–13× longer to the
    same fit (the table is in ``jaxrot/_fit/_optimiser.py``). Adam
    (``adam_steps``, ``adam_learning_rate``; off by default) with a fixed learning
    rate cannot follow the valley and stalls far above the noise floor
    (``benchmarks/fit_memory.py`` prints the comparison); it is kept as an
    optional warm-up for a start far from the optimum.

    Time step: each observation interval is split into ``substeps`` equal
    steps. By default ``dt`` turns the body by at most 0.01 rad per step at the
    largest estimated ``|ω|``; Zhao's bias in the fitted moments is then ~1e-5
    relative, far below what 1e-3 rad noise allows.

    Long horizons: with ``checkpoint=True`` (default) the ``N`` steps of a segment
    run as an outer ``lax.scan`` over ``jax.checkpoint``-ed chunks of
    ``checkpoint_every`` (default ``⌈√N⌉``) steps, and the misfit is accumulated in
    the scan carry, so a gradient stores ``O(√N)`` states instead of ``O(N)``.
    For chaotic motion pass ``segments > 1`` (multiple shooting): each segment
    starts from its own fitted state, and ``continuity_weight`` × the mean squared
    mismatch at the joints (orientation in rad², angular velocity × the mean
    observation interval) is added to the objective.

    Args:
        observed: `jaxrot.Trajectory` of one body: ``t`` ``(n,)`` strictly
            increasing (any spacing), ``q`` ``(n, 4)`` unit quaternions (scalar
            first, body → world), ``omega`` ``(n, 3)`` world frame or None. ``n ≥ 3``.
        torque, args: known world-frame torque ``torque(t, q, omega, args) -> (3,)``
            (None: torque-free) and its arguments, as in `jaxrot.rollout`.
        scheme: integrator name or object (default ``"zhao"``).
        dt: largest step (each interval uses ``spacing / ⌈spacing / dt⌉``), or
        substeps: steps per observation interval (give one of the two).
        inertia0: starting tensor ``(3, 3)`` instead of the linear estimate.
        omega0: starting ``ω0`` ``(3,)`` instead of the estimate.
        segments: number of multiple-shooting segments (1: single shooting).
        continuity_weight: weight of the joint mismatch (``segments > 1``).
        omega_weight: weight (time²) of the angular-velocity misfit.
        adam_steps, adam_learning_rate: optional Adam warm-up before Gauss–Newton.
        max_iter: Gauss–Newton iteration cap.
        ftol: stop when the decrease that the Gauss–Newton model predicts for
            the next full step ``d``, ``|J d|²``, is ≤ ``ftol ×`` the objective ``f``. With ``N``
            residuals at the noise floor this leaves the parameters within
            ``√(ftol N)`` standard errors of the optimum (0.01 for the default
            and ``N = 600``). A relative test cannot end a perfect fit
            (noise-free data stepped by the same scheme): there ``f`` and
            ``|J d|²`` are both round-off, with no ratio of their own. So the fit
            also stops, converged, once ``f`` is at most its round-off floor:
            each of the ``n`` steps of a segment rounds the state by ~eps of the
            dtype, so an exact model misses exact data by up to
            ``θ = (n + 1) eps`` rad (steps' errors added linearly, plus the
            data's rounding; random signs give ~√n eps), and the floor is the
            objective with every residual that large: ``θ²``, plus
            ``omega_weight (θ |ω|max)²`` when ω is observed, plus
            ``continuity_weight θ² (1 + (spacing |ω|max)²)`` with segments. For
            2000 steps, ``θ`` is 4e-13 rad in float64 and 2.4e-4 rad in float32:
            misfits below it are round-off, not information. Measured: perfect
            fits of 400 steps end at 4–5 eps. The objective is a sum of squares
            computed without cancellation, so ``f ≥ 0`` exactly.
        checkpoint, checkpoint_every: gradient checkpointing (see above).
        normalize: normalise ``observed.q`` instead of rejecting non-unit ones.

    Returns:
        `FitResult`.

    Raises:
        ValueError: ``observed`` of the wrong type or shape, non-finite, not
            strictly increasing in time, non-unit quaternions, or bad options.

    Example:
        >>> import jax.numpy as jnp, jaxrot
        >>> inertia = jnp.array([2.0, 3.0, 4.0])  # principal moments of the "unknown" body
        >>> state = jaxrot.RotState(jnp.array([1.0, 0, 0, 0]), jnp.array([1.0, 0.2, 1.5]))
        >>> obs = jaxrot.rollout("zhao", state, inertia, 0.01, 400, save_every=20)
        >>> fit = jaxrot.fit_inertia(obs, substeps=20)  # torque-free: trace normalised to 1
        >>> print((fit.moments / fit.moments[0]).round(4).tolist(), fit.converged)
        [1.0, 1.5, 2.0] True
    """
    for name, value in (("continuity_weight", continuity_weight), ("omega_weight", omega_weight)):
        check_weight(value, name)
    adam_steps = check_int(adam_steps, "adam_steps", 0)
    max_iter = check_int(max_iter, "max_iter", 0)
    unit_trace = torque is None
    model, settings = build_model(
        observed,
        torque=torque,
        args=args,
        segments=segments,
        unit_trace=unit_trace,
        scheme=scheme,
        dt=dt,
        substeps=substeps,
        checkpoint=checkpoint,
        checkpoint_every=checkpoint_every,
        omega_weight=omega_weight,
        continuity_weight=continuity_weight,
        normalize=normalize,
    )
    params = starting_point(
        settings,
        torque=torque,
        args=args,
        unit_trace=unit_trace,
        segments=segments,
        inertia0=inertia0,
        omega0=omega0,
    )
    initial_inertia = inertia_from_cholesky(params.chol, unit_trace=unit_trace)
    free = np.arange(1 if unit_trace else 0, 6 + 6 * segments)
    params, loss_history, n_iterations, converged = solve(
        params,
        model,
        free,
        adam_steps=adam_steps,
        adam_learning_rate=float(adam_learning_rate),
        max_iter=max_iter,
        ftol=float(ftol),
        floor=round_off_floor(model, float(np.max(np.linalg.norm(settings.omega_estimate, axis=-1)))),
    )
    loss_history = jnp.asarray(loss_history, settings.dtype)

    inertia, q_start = unpack(params, model)
    moments, axes = jnp.linalg.eigh(inertia)
    _, q_seg, omega_seg = residuals(params, model)
    n = settings.t.shape[0]
    q_fit = np.empty((n, 4))
    omega_fit = np.empty((n, 3))
    bounds = settings.bounds
    for s in range(segments):
        lo, hi = bounds[s], bounds[s + 1]
        q_fit[lo : hi + 1] = np.asarray(q_seg[s, : hi - lo + 1])
        omega_fit[lo : hi + 1] = np.asarray(omega_seg[s, : hi - lo + 1])
    trajectory = Trajectory(
        jnp.asarray(settings.t, settings.dtype),
        jnp.asarray(q_fit, settings.dtype),
        jnp.asarray(omega_fit, settings.dtype),
    )
    obs_q = jnp.asarray(settings.q, settings.dtype)
    rms = jnp.sqrt(jnp.mean(quat.angle_between(trajectory.q, obs_q) ** 2))
    return FitResult(
        inertia=inertia,
        moments=moments,
        axes=axes,
        q0=q_start[0],
        omega0=params.omega[0],
        trajectory=trajectory,
        loss=loss_history[-1],
        rms_angle=rms,
        loss_history=loss_history,
        converged=bool(converged),
        n_iterations=n_iterations,
        initial_inertia=initial_inertia,
        dt=float(np.max(np.diff(settings.t))) / model.substeps,
        scale_determined=not unit_trace,
    )
