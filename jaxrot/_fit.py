"""`fit_inertia`: the body-frame inertia tensor from observed orientations, by gradients through a scheme.

The model is a rigid body stepped by a jaxrot scheme (Zhao–van Wachem by
default) from a fitted initial state; the objective is the mean squared
geodesic angle between modelled and observed orientations (plus, when given,
angular velocities). The tensor is parameterised so that only physically
possible tensors can come out (`inertia_from_cholesky`); the optimiser is
L-BFGS (optax) in Gauss–Newton-whitened coordinates, started from a linear
angular-momentum-balance estimate (see `fit_inertia` for the reasons).

Long horizons: the scan over time is split into checkpointed chunks of about
``√N`` steps (``jax.checkpoint`` around an inner ``lax.scan``), so the memory of a
gradient through ``N`` steps grows like ``√N``; chaotic motion can be fitted by
multiple shooting (``segments > 1``).
"""

import math
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax

from . import quaternion as quat
from ._inertia import body_inertia
from ._state import RotState, Trajectory
from ._validation import QUATERNION_NORM_TOL, check_torque, is_concrete
from .schemes import resolve_scheme


# The default time step turns the body by at most this angle (radians) per step.
DEFAULT_STEP_ANGLE = 0.01
REWHITEN_EVERY = 5


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
            ``(n_iterations + 1,)`` (Adam steps first, if any, then L-BFGS).
        converged: True when L-BFGS stopped on its tolerance (predicted
            relative decrease of the objective ≤ ``ftol``, or the objective down
            to round-off: see ``ftol`` in `fit_inertia`), not on ``max_iter`` or
            a failed line search.
        n_iterations: optimiser iterations run (Adam + L-BFGS).
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


def inertia_from_cholesky(params, *, unit_trace: bool = False):
    r"""Inertia tensor ``(..., 3, 3)`` of the mass distribution with second moments ``S = L Lᵀ``.

    ``params`` ``(..., 6)`` = ``[L₀₀, L₁₁, L₂₂, L₁₀, L₂₀, L₂₁]`` fill a lower-triangular
    ``L``, so ``S = L Lᵀ`` (the body-frame second-moment matrix ``∫ρ r rᵀ dV``) is
    symmetric positive semidefinite, and

        ``I = tr(S) 𝟙 − S``.

    If ``S`` has eigenvalues ``s₁, s₂, s₃ ≥ 0`` along some axes, ``I`` has the same
    axes and moments ``s₂ + s₃, s₁ + s₃, s₁ + s₂``: every moment is ≥ 0 (> 0 unless
    ``S`` has rank one: a rod) and ``I₁ + I₂ − I₃ = 2 s₃ ≥ 0``, so the triangle
    inequality holds for every permutation. Conversely every physical tensor is
    reached (``S = ½ tr(I) 𝟙 − I``, then Cholesky; `cholesky_from_inertia`),
    including planar bodies on the boundary ``I₁ + I₂ = I₃`` (``s₃ = 0``, a finite
    parameter value; a log-diagonal would push them to infinity, which we
    measured to stall the fit). Nothing non-physical can come out of an
    optimiser step, and the map is a smooth polynomial, so gradients are finite
    everywhere.

    With ``unit_trace=True`` the tensor is divided by ``tr I = 2 tr S``: the
    scale-free form used for torque-free fits, where only ratios are determined.

    Example:
        >>> import jax.numpy as jnp
        >>> from jaxrot._fit import inertia_from_cholesky
        >>> inertia_from_cholesky(jnp.array([1.0, 1.0, 1.0, 0.0, 0.0, 0.0])).tolist()  # a sphere
        [[2.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 2.0]]
    """
    params = jnp.asarray(params)
    d = params[..., :3]
    zero = jnp.zeros_like(d[..., 0])
    lower = jnp.stack(
        [
            jnp.stack([d[..., 0], zero, zero], axis=-1),
            jnp.stack([params[..., 3], d[..., 1], zero], axis=-1),
            jnp.stack([params[..., 4], params[..., 5], d[..., 2]], axis=-1),
        ],
        axis=-2,
    )
    second = lower @ jnp.swapaxes(lower, -1, -2)
    trace = jnp.trace(second, axis1=-2, axis2=-1)[..., None, None]
    inertia = trace * jnp.broadcast_to(jnp.eye(3, dtype=second.dtype), second.shape) - second
    return inertia / (2 * trace) if unit_trace else inertia


def cholesky_from_inertia(inertia, *, floor: float = 1e-6):
    """Parameters ``(6,)`` of `inertia_from_cholesky` for a symmetric ``(3, 3)`` tensor (NumPy, eager).

    A tensor outside the physical set is projected onto it first: the
    eigenvalues of ``S = ½ tr(I) 𝟙 − I`` are raised to at least ``floor ×`` their
    largest (a tensor with a non-positive trace becomes a sphere).
    """
    inertia = np.asarray(inertia, dtype=np.float64)
    inertia = 0.5 * (inertia + inertia.T)
    second = 0.5 * np.trace(inertia) * np.eye(3) - inertia
    values, vectors = np.linalg.eigh(second)
    if not np.all(np.isfinite(values)) or np.trace(inertia) <= 0:
        values, vectors = np.ones(3), np.eye(3)
    values = np.maximum(values, floor * max(float(values.max()), np.finfo(np.float64).tiny))
    lower = np.linalg.cholesky(vectors @ np.diag(values) @ vectors.T)
    return np.array([*np.diag(lower), lower[1, 0], lower[2, 0], lower[2, 1]])


# --------------------------------------------------------------------------- the model


class _Params(NamedTuple):
    chol: jax.Array  # (6,)
    dq: jax.Array  # (K, 3) rotation-vector offsets of the segment starts from the observed q
    omega: jax.Array  # (K, 3) world-frame angular velocity at the segment starts


class _Segments(NamedTuple):
    """Observations cut into ``K`` segments, each padded to ``P`` intervals (+ chunk padding)."""

    t: jax.Array  # (K, P + 1)      padded by repeating the last time: dt = 0 steps are no-ops
    q: jax.Array  # (K, P + 1, 4)
    omega: jax.Array | None  # (K, P + 1, 3)
    weight: jax.Array  # (K, P + 1)  1 for an observation counted here, 0 otherwise
    q_start: jax.Array  # (K, 4) observed orientation at each segment start


class _Problem(eqx.Module):
    data: _Segments
    args: object
    scheme: object = eqx.field(static=True)
    torque: object = eqx.field(static=True)
    substeps: int = eqx.field(static=True)
    n_outer: int = eqx.field(static=True)
    n_inner: int = eqx.field(static=True)
    checkpoint: bool = eqx.field(static=True)
    unit_trace: bool = eqx.field(static=True)
    omega_weight: float = eqx.field(static=True)
    continuity_weight: float = eqx.field(static=True)
    spacing: float = eqx.field(static=True)  # mean observation interval: scales ω mismatches to rad


def _orientation_misfit(q, q_obs):
    """``4 |v|²`` of ``q_obs* ⊗ q = (w, v)``: ``4 sin²(θ/2) ≈ θ²``, sign invariant, smooth, finite gradient.

    For unit quaternions this is ``4 (1 − (q·q_obs)²)``, but computed without that
    cancellation: ``1 − c²`` is a difference of O(1) numbers, so it is known only to
    ~eps absolute (it came out −5e-16 at a perfect fit, and could not resolve misfits
    below ~√eps rad: 3e-4 rad in float32). Each component of ``v`` is a short sum of
    products, correct to ~eps absolute, so ``4 |v|²`` is never negative and resolves
    angles down to ~eps; a ``|q|`` off 1 by round-off scales it instead of shifting it.
    """
    v = quat.multiply(quat.conjugate(q_obs), q)[..., 1:]
    return 4 * jnp.sum(v * v, axis=-1)


def _misfit(problem, state, q_obs, omega_obs):
    r = _orientation_misfit(state.q, q_obs)
    if omega_obs is not None:
        r = r + problem.omega_weight * jnp.sum((state.omega - omega_obs) ** 2, axis=-1)
    return r


def _segment_misfit(problem, inertia, q0, omega0, t, q_obs, omega_obs, weight):
    """Weighted misfit sum and final state of one segment, stepped ``substeps`` times per interval.

    Global step ``j`` lies in interval ``k = j // s`` at substep ``i = j % s``. With
    checkpointing the ``n_outer × n_inner`` steps are an outer scan over
    ``jax.checkpoint``-ed inner scans: the backward pass stores ``n_outer``
    carries and recomputes one chunk of ``n_inner`` steps at a time.
    """
    scheme, torque, args, s = problem.scheme, problem.torque, problem.args, problem.substeps
    dtype = q0.dtype

    def one_step(carry, j):
        inner, acc = carry
        k = j // s
        i = j - k * s
        dt = (t[k + 1] - t[k]) / s
        time = t[k] + i.astype(dtype) * dt
        inner = scheme.step(inner, time, dt, inertia, torque, args)
        state = scheme.state(inner)
        r = _misfit(problem, state, q_obs[k + 1], None if omega_obs is None else omega_obs[k + 1])
        acc = acc + jnp.where(i == s - 1, weight[k + 1] * r, jnp.zeros((), dtype))
        return (inner, acc), None

    def chunk(carry, o):
        js = o * problem.n_inner + jnp.arange(problem.n_inner)
        carry, _ = jax.lax.scan(one_step, carry, js)
        return carry, None

    state0 = RotState(q0, omega0)
    acc0 = weight[0] * _misfit(problem, state0, q_obs[0], None if omega_obs is None else omega_obs[0])
    carry = (scheme.init(state0, t[0], inertia, torque, args), acc0)
    if problem.checkpoint:
        carry, _ = jax.lax.scan(jax.checkpoint(chunk), carry, jnp.arange(problem.n_outer))
    else:
        carry, _ = jax.lax.scan(one_step, carry, jnp.arange(problem.n_outer * problem.n_inner))
    inner, acc = carry
    return acc, scheme.state(inner)


def _unpack(params, problem):
    inertia = inertia_from_cholesky(params.chol, unit_trace=problem.unit_trace)
    q_start = quat.multiply(quat.exp(params.dq), problem.data.q_start)
    return inertia, q_start


def _objective(params, problem):
    """Mean weighted misfit over the observations, plus the continuity penalty between segments."""
    inertia, q_start = _unpack(params, problem)
    prepared = body_inertia(inertia)
    d = problem.data
    misfit = jax.vmap(_segment_misfit, in_axes=(None, None, 0, 0, 0, 0, None if d.omega is None else 0, 0))
    sums, finals = misfit(problem, prepared, q_start, params.omega, d.t, d.q, d.omega, d.weight)
    loss = jnp.sum(sums) / jnp.sum(d.weight)
    if q_start.shape[0] > 1:
        defect = _orientation_misfit(finals.q[:-1], q_start[1:])
        mismatch = (finals.omega[:-1] - params.omega[1:]) * problem.spacing
        defect = defect + jnp.sum(mismatch**2, axis=-1)
        loss = loss + problem.continuity_weight * jnp.mean(defect)
    return loss


def _single_shooting_loss(problem, inertia, q0, omega0):
    """One-segment objective as a function of a raw tensor ``(3, 3)``, ``q0`` and ``omega0`` (for tests)."""
    d = problem.data
    total, _ = _segment_misfit(
        problem,
        body_inertia(inertia),
        q0,
        omega0,
        d.t[0],
        d.q[0],
        None if d.omega is None else d.omega[0],
        d.weight[0],
    )
    return total / jnp.sum(d.weight)


# --------------------------------------------------------------------------- optimisers


def _round_off_floor(problem, omega_scale):
    """The objective of a fit limited only by round-off: a fit that reaches it has converged.

    Each of the ``n`` steps of a segment rounds the state by about eps of the dtype
    (relative: a few ulp of random sign), so a model that reproduces the observations
    exactly in real arithmetic misses them in floating point by up to
    ``θ = (n + 1) eps`` rad: the step errors added up linearly (the worst case; random
    signs give ~√n eps), plus the observations' own rounding. Angular velocities are
    then off by up to ``θ ω_max`` (``omega_scale``: the largest observed or estimated
    ``|ω|``). The floor is the objective with every residual of that size:
    ``θ²`` for the orientations, ``+ omega_weight (θ ω_max)²`` when ω is observed,
    ``+ continuity_weight θ² (1 + (spacing ω_max)²)`` with several segments.
    """
    eps = float(jnp.finfo(problem.data.t.dtype).eps)
    angle = (problem.n_outer * problem.n_inner + 1) * eps
    floor = angle**2
    if problem.data.omega is not None:
        floor += problem.omega_weight * (angle * omega_scale) ** 2
    if problem.data.q.shape[0] > 1:
        floor += problem.continuity_weight * angle**2 * (1 + (problem.spacing * omega_scale) ** 2)
    return floor


@eqx.filter_jit
def _value_and_grad(params, problem):
    return jax.value_and_grad(_objective)(params, problem)


def _flat(params) -> np.ndarray:
    return np.concatenate([np.asarray(x, dtype=np.float64).reshape(-1) for x in params])


def _unflat(vector, like, dtype) -> _Params:
    out, i = [], 0
    for x in like:
        out.append(jnp.asarray(vector[i : i + x.size].reshape(x.shape), dtype))
        i += x.size
    return _Params(*out)


def _whitening(residuals, x, free, rel_step=1e-6):
    """``M`` with ``Mᵀ H M ≈ 𝟙``, ``H = 2 JᵀJ`` the Gauss–Newton Hessian over the ``free`` coordinates.

    ``J`` by central differences of the compiled residuals (``2 × len(free)``
    forward rollouts, no gradient); tiny eigenvalues are raised to ``1e-10 ×``
    the largest.
    """
    columns = []
    for i in free:
        h = rel_step * max(1.0, abs(x[i]))
        up, down = x.copy(), x.copy()
        up[i] += h
        down[i] -= h
        columns.append((residuals(up) - residuals(down)) / (2 * h))
    jac = np.stack(columns, axis=1)
    hess = 2 * jac.T @ jac
    n = len(free)
    if not np.all(np.isfinite(hess)):
        return np.eye(n)
    values, vectors = np.linalg.eigh(0.5 * (hess + hess.T))
    if values.max() <= 0:
        return np.eye(n)
    values = np.maximum(values, 1e-10 * values.max())
    return vectors / np.sqrt(values)


def _line_search(fun, z, f, g, d, c1=1e-4, c2=0.9, max_trials=40):
    """Weak-Wolfe bisection/expansion line search (Lewis & Overton) along ``d`` from ``z``.

    Returns ``(z_new, f_new, g_new, extra)`` or None. The curvature condition
    keeps ``sᵀy > 0``, which L-BFGS needs for a positive definite update.
    """
    slope = float(g @ d)
    lo, hi, a = 0.0, np.inf, 1.0
    best = None
    for _ in range(max_trials):
        f_new, g_new, extra = fun(z + a * d)
        if not np.isfinite(f_new) or f_new > f + c1 * a * slope:
            hi = a
        elif g_new @ d < c2 * slope:
            lo = a
            best = (z + a * d, f_new, g_new, extra)
        else:
            return z + a * d, f_new, g_new, extra
        a = 0.5 * (lo + hi) if np.isfinite(hi) else 2 * a
    return best


def _optimise(params, problem, free, *, adam_steps, adam_learning_rate, max_iter, ftol, floor):
    """Adam warm-up (optional), then L-BFGS in Gauss–Newton-whitened coordinates, in an eager loop.

    L-BFGS directions come from ``optax.scale_by_lbfgs``; steps from a weak-Wolfe
    line search in Python over the one compiled value-and-gradient (optax's
    zoom line search, compiled, inlines several copies of the gradient through
    the rollout and tripled the compile time). Converged: the objective is at
    most ``floor`` (`_round_off_floor`), or the predicted decrease at most
    ``ftol ×`` the objective (see `fit_inertia`).
    """
    dtype = params.chol.dtype

    def value_and_grad(vector):
        value, grad = _value_and_grad(_unflat(vector, params, dtype), problem)
        return float(value), _flat(grad)

    x = _flat(params)
    history = []
    f, g = value_and_grad(x)
    lbfgs = optax.scale_by_lbfgs()
    update = jax.jit(lbfgs.update)
    if adam_steps:
        adam = optax.adam(adam_learning_rate)
        state = adam.init(jnp.asarray(x[free]))
        adam_update = jax.jit(adam.update)
        for _ in range(adam_steps):
            history.append(f)
            with jax.numpy_dtype_promotion("standard"):
                step, state = adam_update(jnp.asarray(g[free]), state)
            x = x.copy()
            x[free] += np.asarray(step)
            f, g = value_and_grad(x)

    def residuals(vector):
        return np.asarray(_residuals(_unflat(vector, params, dtype), problem)[0], dtype=np.float64)

    converged, n = False, 0
    while True:
        # (Re)start L-BFGS in coordinates whitened by the Gauss–Newton Hessian at x; restart whenever
        # the objective has fallen 4× since, as the curvature far from the optimum goes stale.
        whiten = _whitening(residuals, x, free)
        x0, f0, n0 = x.copy(), f, n

        def in_z(z, x0=x0, whiten=whiten):
            xz = x0.copy()
            xz[free] += whiten @ z
            value, grad = value_and_grad(xz)
            return value, whiten.T @ grad[free], (xz, grad)

        z = np.zeros(len(free))
        gz = whiten.T @ g[free]
        state = lbfgs.init(jnp.asarray(z))
        restart = False
        while not restart:
            history.append(f)
            # optax's L-BFGS adds int32 and int64 indices: not allowed under strict dtype promotion.
            with jax.numpy_dtype_promotion("standard"):
                direction, state = update(jnp.asarray(gz), state, jnp.asarray(z))
            direction = -np.asarray(direction)
            slope = float(gz @ direction)
            if not slope < 0:
                direction, slope = -gz, -float(gz @ gz)  # fall back to steepest descent
            # f >= 0 exactly (a sum of squares; `_orientation_misfit` has no cancellation).
            if f <= floor or -0.5 * slope <= ftol * f:
                converged = True
                break
            if n >= max_iter:
                break
            found = _line_search(in_z, z, f, gz, direction)
            if found is None:
                break
            z, f, gz, (x, g) = found
            n += 1
            restart = f < 0.25 * f0 or n - n0 >= REWHITEN_EVERY
        if not restart:
            break
    return _unflat(x, params, dtype), np.asarray(history), adam_steps + n, converged


def _predict(params, problem):
    """Modelled states at the (padded) observation times of every segment: ``(K, P + 1, ...)``."""
    inertia, q_start = _unpack(params, problem)
    prepared = body_inertia(inertia)
    scheme, torque, args, s = problem.scheme, problem.torque, problem.args, problem.substeps

    def segment(q0, omega0, t):
        def interval(inner, k):
            dt = (t[k + 1] - t[k]) / s

            def one_step(inner, i):
                time = t[k] + i.astype(dt.dtype) * dt
                return scheme.step(inner, time, dt, prepared, torque, args), None

            inner, _ = jax.lax.scan(one_step, inner, jnp.arange(s))
            return inner, scheme.state(inner)

        state0 = RotState(q0, omega0)
        _, states = jax.lax.scan(
            interval, scheme.init(state0, t[0], prepared, torque, args), jnp.arange(t.shape[0] - 1)
        )
        q = jnp.concatenate([q0[None], states.q])
        omega = jnp.concatenate([omega0[None], states.omega])
        return q, omega

    return jax.vmap(segment)(q_start, params.omega, problem.data.t)


def _signed_vector(q, q_ref):
    """``2 v sign(w)`` of ``q_ref* ⊗ q = (w, v)``: its squared norm is `_orientation_misfit`."""
    d = quat.multiply(quat.conjugate(q_ref), q)
    return 2 * jnp.where(d[..., :1] < 0, -d[..., 1:], d[..., 1:])


@eqx.filter_jit
def _residuals(params, problem):
    """Residual vector whose sum of squares is `_objective`, and the predicted states ``(K, P + 1, ...)``."""
    q, omega = _predict(params, problem)
    d = problem.data
    scale = jnp.sqrt(d.weight / jnp.sum(d.weight))[..., None]
    parts = [(scale * _signed_vector(q, d.q)).reshape(-1)]
    if d.omega is not None:
        parts.append((scale * jnp.sqrt(problem.omega_weight) * (omega - d.omega)).reshape(-1))
    n_seg = q.shape[0]
    if n_seg > 1:
        _, q_start = _unpack(params, problem)
        joint = jnp.sqrt(problem.continuity_weight / (n_seg - 1))
        parts.append((joint * _signed_vector(q[:-1, -1], q_start[1:])).reshape(-1))
        parts.append((joint * problem.spacing * (omega[:-1, -1] - params.omega[1:])).reshape(-1))
    return jnp.concatenate(parts), q, omega


# --------------------------------------------------------------------------- initial estimate


def _log_np(q):
    return np.asarray(quat.log(jnp.asarray(q)))


def _mul_np(p, q):
    return np.asarray(quat.multiply(jnp.asarray(p), jnp.asarray(quat.conjugate(jnp.asarray(q)))))


def estimate_omega(t, q):
    """World angular velocity ``(n, 3)`` from orientations ``(n, 4)`` by three-point differences.

    ``φ(τ) = log(q(t_k + τ) ⊗ q(t_k)*)`` has ``φ'(0) = ω(t_k)`` (world frame); its
    derivative is taken from the neighbours (central inside, one-sided at the
    ends), second order also for uneven spacing. Needs ``n ≥ 3``.
    """
    t = np.asarray(t, dtype=np.float64)
    q = np.asarray(q, dtype=np.float64)
    n = t.shape[0]
    omega = np.empty((n, 3))
    # interior: points at -a, 0, +b
    a = (t[1:-1] - t[:-2])[:, None]
    b = (t[2:] - t[1:-1])[:, None]
    fwd = _log_np(_mul_np(q[2:], q[1:-1]))
    bwd = _log_np(_mul_np(q[:-2], q[1:-1]))
    omega[1:-1] = (a**2 * fwd - b**2 * bwd) / (a * b * (a + b))
    # ends: points at 0, h1, h2 (h1, h2 of either sign)
    for k, (k1, k2) in ((0, (1, 2)), (n - 1, (n - 2, n - 3))):
        h1, h2 = t[k1] - t[k], t[k2] - t[k]
        p1 = _log_np(_mul_np(q[k1], q[k]))
        p2 = _log_np(_mul_np(q[k2], q[k]))
        omega[k] = (p1 * h2**2 - p2 * h1**2) / (h1 * h2 * (h2 - h1))
    return omega


def _linear_estimate(t, q, omega, torque, args, dtype):
    """Inertia from the angular-momentum balance ``R_k I ω_b,k − L₀ = ∫₀^{t_k} τ dt``, linear in ``(I, L₀)``.

    Torque-free the system is homogeneous: ``(I, L₀)`` is its smallest right
    singular vector, normalised to ``tr I = 1``. With a torque the impulse on the
    right fixes the scale (least squares). Noisy ``ω`` makes this a rough but
    unbiased-enough start; the gradient fit then refines it.
    """
    rot = np.asarray(quat.to_matrix(jnp.asarray(q)))
    w_b = np.einsum("kji,kj->ki", rot, omega)  # R_kᵀ ω_k
    zero = np.zeros(len(t))
    wx, wy, wz = w_b[:, 0], w_b[:, 1], w_b[:, 2]
    # I ω_b as a linear map of (Ixx, Iyy, Izz, Ixy, Ixz, Iyz)
    a = np.stack(
        [
            np.stack([wx, zero, zero, wy, wz, zero], axis=-1),
            np.stack([zero, wy, zero, wx, zero, wz], axis=-1),
            np.stack([zero, zero, wz, zero, wx, wy], axis=-1),
        ],
        axis=1,
    )  # (n, 3, 6)
    rows = np.concatenate([rot @ a, np.broadcast_to(-np.eye(3), (len(t), 3, 3))], axis=-1).reshape(-1, 9)
    if torque is None:
        _, _, vt = np.linalg.svd(rows, full_matrices=False)
        x = vt[-1]
    else:
        tau = jax.vmap(lambda tk, qk, wk: torque(tk, qk, wk, args))(
            jnp.asarray(t, dtype), jnp.asarray(q, dtype), jnp.asarray(omega, dtype)
        )
        tau = np.asarray(tau, dtype=np.float64)
        impulse = np.concatenate(
            [np.zeros((1, 3)), np.cumsum(0.5 * (tau[1:] + tau[:-1]) * np.diff(t)[:, None], 0)]
        )
        x, *_ = np.linalg.lstsq(rows, impulse.reshape(-1), rcond=None)
    xx, yy, zz, xy, xz, yz = x[:6]
    inertia = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
    momentum = x[6:]
    if torque is None:
        trace = np.trace(inertia)
        if trace == 0:
            return np.eye(3) / 3, None
        inertia, momentum = inertia / trace, momentum / trace
    return inertia, momentum


# --------------------------------------------------------------------------- checks and set-up


def _check_observed(observed, normalize):
    if not (isinstance(observed, tuple) and len(observed) == 3):
        raise ValueError(
            "`observed` must be a jaxrot.Trajectory(t, q, omega) with omega an (n, 3) array or None; "
            f"got {type(observed).__name__}."
        )
    t, q, omega = observed
    if not is_concrete(t, q, omega):
        raise ValueError(
            "`observed` must hold concrete arrays: fit_inertia runs its optimiser eagerly (not under jit)."
        )
    t, q = np.asarray(t), np.asarray(q)
    if t.ndim != 1 or t.shape[0] < 3:
        raise ValueError(f"`observed.t` must be a 1-D array of at least 3 times; got shape {t.shape}.")
    n = t.shape[0]
    if q.shape != (n, 4):
        raise ValueError(
            f"`observed.q` must have shape (n, 4) = ({n}, 4) for one body (scalar-first quaternions at "
            f"the times observed.t); got {q.shape}. Fit several bodies one at a time."
        )
    if omega is not None:
        omega = np.asarray(omega)
        if omega.shape != (n, 3):
            raise ValueError(
                f"`observed.omega` must be None or world-frame angular velocities of shape ({n}, 3); "
                f"got {omega.shape}."
            )
    for label, x in (("t", t), ("q", q), ("omega", omega)):
        if x is not None and not np.all(np.isfinite(x)):
            raise ValueError(
                f"`observed.{label}` contains NaN or infinite values; drop those samples (or pass "
                "omega=None when angular velocities were not measured)."
            )
    if np.any(np.diff(t) <= 0):
        raise ValueError("`observed.t` must be strictly increasing.")
    norms = np.linalg.norm(q, axis=-1)
    if np.any(norms == 0):
        raise ValueError("`observed.q` contains a zero quaternion, which is not a rotation.")
    worst = float(np.max(np.abs(norms - 1)))
    if not normalize and worst > QUATERNION_NORM_TOL:
        raise ValueError(
            f"`observed.q` must be unit quaternions (| |q| - 1 | <= {QUATERNION_NORM_TOL:g}); the worst is "
            f"off by {worst:.3g}. Normalise them or pass normalize=True."
        )
    dtype = jnp.result_type(*(x for x in (t, q, omega) if x is not None))
    if not jnp.issubdtype(dtype, jnp.floating):
        dtype = jnp.result_type(float)
    q = q / norms[:, None]
    # Make consecutive quaternions sign-continuous (q and -q are the same rotation).
    dots = np.sum(q[1:] * q[:-1], axis=-1)
    signs = np.cumprod(np.concatenate([[1.0], np.where(dots < 0, -1.0, 1.0)]))
    q = q * signs[:, None]
    return (
        t.astype(np.float64),
        q.astype(np.float64),
        None if omega is None else omega.astype(np.float64),
        dtype,
    )


def _positive_int(value, name, minimum=1):
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise ValueError(f"`{name}` must be a Python int >= {minimum}; got {value!r}.")
    return int(value)


def _build_problem(
    observed,
    *,
    torque,
    args,
    segments,
    unit_trace,
    scheme="zhao",
    dt=None,
    substeps=None,
    checkpoint=True,
    checkpoint_every=None,
    omega_weight=1.0,
    continuity_weight=100.0,
    omega_estimate=None,
    normalize=False,
):
    """Validated, padded data and the static configuration; also the default start parameters."""
    scheme = resolve_scheme(scheme)
    check_torque(torque)
    t, q, omega, dtype = _check_observed(observed, normalize)
    n = t.shape[0]
    segments = _positive_int(segments, "segments")
    if segments > n - 1:
        raise ValueError(
            f"`segments` must be <= the number of observation intervals ({n - 1}); got {segments}."
        )
    if omega_estimate is None:
        omega_estimate = omega if omega is not None else estimate_omega(t, q)
    spacing = float(np.max(np.diff(t)))
    if substeps is not None:
        if dt is not None:
            raise ValueError("Pass `dt` or `substeps`, not both.")
        substeps = _positive_int(substeps, "substeps")
    else:
        if dt is None:
            w_max = float(np.max(np.linalg.norm(omega_estimate, axis=-1)))
            dt = DEFAULT_STEP_ANGLE / w_max if w_max > 0 else spacing
        dt = float(dt)
        if not np.isfinite(dt) or dt <= 0:
            raise ValueError(f"`dt` must be a finite time step > 0; got {dt}.")
        substeps = max(1, math.ceil(spacing / dt * (1 - 1e-12)))

    bounds = np.round(np.linspace(0, n - 1, segments + 1)).astype(int)
    n_intervals = int(np.max(np.diff(bounds)))
    n_steps = n_intervals * substeps
    if checkpoint:
        n_inner = (
            _positive_int(checkpoint_every, "checkpoint_every")
            if checkpoint_every is not None
            else max(1, math.ceil(math.sqrt(n_steps)))
        )
        n_outer = math.ceil(n_steps / n_inner)
    else:
        n_inner, n_outer = 1, n_steps
    length = math.ceil(n_outer * n_inner / substeps) + 1  # padded observation slots per segment

    ts, qs, ws, weights = [], [], [], []
    for s in range(segments):
        lo, hi = bounds[s], bounds[s + 1]
        idx = np.minimum(np.arange(lo, lo + length), hi)
        weight = (np.arange(lo, lo + length) <= hi).astype(np.float64)
        if s < segments - 1:
            weight[hi - lo] = 0.0  # the boundary sample is counted by the next segment
        ts.append(t[idx])
        qs.append(q[idx])
        weights.append(weight)
        if omega is not None:
            ws.append(omega[idx])
    data = _Segments(
        t=jnp.asarray(np.stack(ts), dtype),
        q=jnp.asarray(np.stack(qs), dtype),
        omega=None if omega is None else jnp.asarray(np.stack(ws), dtype),
        weight=jnp.asarray(np.stack(weights), dtype),
        q_start=jnp.asarray(q[bounds[:-1]], dtype),
    )
    problem = _Problem(
        data=data,
        args=args,
        scheme=scheme,
        torque=torque,
        substeps=substeps,
        n_outer=n_outer,
        n_inner=n_inner,
        checkpoint=bool(checkpoint),
        unit_trace=unit_trace,
        omega_weight=float(omega_weight),
        continuity_weight=float(continuity_weight),
        spacing=float((t[-1] - t[0]) / (n - 1)),
    )
    extra = {
        "t": t,
        "q": q,
        "omega": omega,
        "omega_estimate": omega_estimate,
        "bounds": bounds,
        "dtype": dtype,
    }
    return problem, extra


# --------------------------------------------------------------------------- the public entry point


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

    Optimiser: L-BFGS (optax's ``scale_by_lbfgs`` directions, a weak-Wolfe line
    search) in coordinates whitened by the Gauss–Newton Hessian ``2 JᵀJ`` (``J`` by
    finite differences of forward rollouts), re-whitened every 5 iterations or
    when the objective has dropped 4×. Why: the misfit of a long rollout is a
    narrow curved valley (the phase of the motion is very sensitive to ``I``
    and ``ω0``: 0.3 % in ``I`` costs 0.2 rad of misfit over 10 s), with
    parameter sensitivities spread over ~5 decades. Whitened, L-BFGS reaches
    the noise floor in 2–5 iterations on the test problems; unwhitened it
    took ~500. Adam (``adam_steps``, ``adam_learning_rate``; off by default)
    with a fixed learning rate cannot follow the valley and stalls far above
    the noise floor (``benchmarks/fit_memory.py`` prints the comparison); it
    is kept as an optional warm-up for a start far from the optimum. The line
    search runs in Python over the one compiled value-and-gradient: optax's
    compiled zoom line search inlines several more copies of the gradient
    through the rollout and tripled the compile time (6 s → 17–19 s).

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
        adam_steps, adam_learning_rate: optional Adam warm-up before L-BFGS.
        max_iter: L-BFGS iteration cap.
        ftol: stop when the decrease that the L-BFGS model predicts for the
            next step, ``−½ gᵀd``, is ≤ ``ftol ×`` the objective ``f``. With ``N``
            residuals at the noise floor this leaves the parameters within
            ``√(ftol N)`` standard errors of the optimum (0.01 for the default
            and ``N = 600``). A relative test cannot end a perfect fit
            (noise-free data stepped by the same scheme): there ``f`` and
            ``gᵀd`` are both round-off, with no ratio of their own. So the fit
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
        if not (np.isfinite(value) and value >= 0):
            raise ValueError(f"`{name}` must be a finite number >= 0; got {value}.")
    adam_steps = _positive_int(adam_steps, "adam_steps", 0)
    max_iter = _positive_int(max_iter, "max_iter", 0)
    unit_trace = torque is None
    problem, extra = _build_problem(
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
    dtype, bounds, omega_est = extra["dtype"], extra["bounds"], extra["omega_estimate"]

    momentum = None
    if inertia0 is None:
        start, momentum = _linear_estimate(extra["t"], extra["q"], omega_est, torque, args, dtype)
    else:
        start = np.asarray(inertia0, dtype=np.float64)
        if start.shape != (3, 3) or not np.all(np.isfinite(start)):
            raise ValueError(f"`inertia0` must be a finite (3, 3) tensor; got shape {start.shape}.")
    chol = cholesky_from_inertia(start)
    if unit_trace:
        # Only the shape of S is determined: L₀₀ stays at its start value (it is not a fit parameter).
        chol = chol / chol[0]
    start_omega = np.array(omega_est[bounds[:-1]])
    if momentum is not None and omega0 is None and segments == 1:
        # ω0 = R₀ I⁻¹ R₀ᵀ L₀ from the momentum fitted to all samples: far better than differencing.
        start_tensor = np.asarray(inertia_from_cholesky(jnp.asarray(chol), unit_trace=unit_trace))
        rot0 = np.asarray(quat.to_matrix(jnp.asarray(extra["q"][0])))
        candidate = rot0 @ np.linalg.solve(start_tensor, rot0.T @ momentum)
        if np.all(np.isfinite(candidate)):
            start_omega[0] = candidate
    if omega0 is not None:
        omega0 = np.asarray(omega0, dtype=np.float64)
        if omega0.shape != (3,) or not np.all(np.isfinite(omega0)):
            raise ValueError(f"`omega0` must be a finite world-frame (3,) vector; got shape {omega0.shape}.")
        start_omega[0] = omega0
    params = _Params(
        chol=jnp.asarray(chol, dtype),
        dq=jnp.zeros((segments, 3), dtype),
        omega=jnp.asarray(start_omega, dtype),
    )
    initial_inertia = inertia_from_cholesky(params.chol, unit_trace=unit_trace)
    free = np.arange(1 if unit_trace else 0, 6 + 6 * segments)
    params, loss_history, n_iterations, converged = _optimise(
        params,
        problem,
        free,
        adam_steps=adam_steps,
        adam_learning_rate=float(adam_learning_rate),
        max_iter=max_iter,
        ftol=float(ftol),
        floor=_round_off_floor(problem, float(np.max(np.linalg.norm(omega_est, axis=-1)))),
    )
    loss_history = jnp.asarray(loss_history, dtype)

    inertia, q_start = _unpack(params, problem)
    moments, axes = jnp.linalg.eigh(inertia)
    _, q_seg, omega_seg = _residuals(params, problem)
    n = extra["t"].shape[0]
    q_fit = np.empty((n, 4))
    omega_fit = np.empty((n, 3))
    for s in range(segments):
        lo, hi = bounds[s], bounds[s + 1]
        q_fit[lo : hi + 1] = np.asarray(q_seg[s, : hi - lo + 1])
        omega_fit[lo : hi + 1] = np.asarray(omega_seg[s, : hi - lo + 1])
    trajectory = Trajectory(
        jnp.asarray(extra["t"], dtype), jnp.asarray(q_fit, dtype), jnp.asarray(omega_fit, dtype)
    )
    obs_q = jnp.asarray(extra["q"], dtype)
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
        dt=float(np.max(np.diff(extra["t"]))) / problem.substeps,
        scale_determined=not unit_trace,
    )
