"""The fit's optimiser: L-BFGS in Gauss–Newton-whitened coordinates, with a weak-Wolfe line search.

Measured against optimistix's least-squares solvers (``benchmarks/fit_optimisers.py``:
``optimistix.least_squares`` with ``GaussNewton`` / ``LevenbergMarquardt``,
``rtol=atol=1e-10``, on `_residuals` in the same whitened coordinates, whitening
timed in; the problems of ``tests/test_fit.py``, float64, CPU, from the same start).
Median wall time of 5 runs interleaved in one process, compiled, on a 2-core machine
shared with other work (load average ~8.5), so the ratios to L-BFGS matter more than
the seconds; iterations in brackets:

==========================  ===============  ============  ============
data                        L-BFGS (here)    LM            GN
==========================  ===============  ============  ============
noisy, torque-free          2.00 s (2)       0.65× (9)     0.31× (5)
noisy, heavy top            1.00 s (2)       0.51× (9)     0.27× (5)
noise-free, torque-free     0.59 s (2)       0.24× (8)     0.09× (4)
noise-free, heavy top       0.87 s (3)       0.25× (9)     0.09× (5)
==========================  ===============  ============  ============

All three reach the same objective (noisy: 3.0656e-06 and 3.0694e-06; noise-free:
round-off, 4e-30 to 8e-29) and the same moments to ~1e-8 relative (noisy: L-BFGS
stops on ``ftol``, 0.01 standard errors short of the optimum GN and LM agree on to
1e-10). First calls (compiling) took 7–46 s each under that load, GN's the least.

Decision: Gauss–Newton wins on these numbers (3–11× faster compiled, same fit); the
hand-written L-BFGS is kept for now only because a switch changes every fit's result
bits and needs what optimistix's ``least_squares`` does not give by itself: the
per-iteration ``loss_history``, ``max_iter`` counting, the Adam warm-up and the
``converged`` test (``ftol`` on the predicted decrease, or the round-off floor). The
switch is the next step: drive ``optimistix.GaussNewton``'s ``init``/``step`` from
this loop (it needs no whitening: Gauss–Newton is invariant to a linear change of
coordinates) and keep `_Optimised` as it is.
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax

from ._objective import _residuals, _value_and_grad
from ._parameterisation import _flat, _Params, _unflat


REWHITEN_EVERY = 5


class _Optimised(NamedTuple):
    """Where `_optimise` stopped."""

    params: _Params
    loss_history: (
        np.ndarray
    )  # (n_iterations + 1,) float64: the objective before each iteration, and at the end
    n_iterations: int  # Adam steps + L-BFGS iterations
    converged: bool  # stopped on ftol or the round-off floor, not on max_iter or a failed line search


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


def _optimise(
    params, problem, free, *, adam_steps, adam_learning_rate, max_iter, ftol, floor
) -> "_Optimised":
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
    return _Optimised(_unflat(x, params, dtype), np.asarray(history), adam_steps + n, converged)
