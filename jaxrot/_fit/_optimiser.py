"""The fit's optimiser: optimistix's Gauss–Newton with a backtracking Armijo search, one compiled loop.

Why Gauss–Newton. The objective is a sum of squared residuals of a long rollout:
a narrow curved valley with parameter sensitivities spread over ~5 decades.
Gauss–Newton takes its curvature from ``JᵀJ`` and is invariant to a linear
change of coordinates, so it needs no rescaling; the previous optimiser, L-BFGS
(optax's directions, a weak-Wolfe line search in Python) had to run in
coordinates whitened by a finite-difference ``JᵀJ``, re-whitened every few
iterations. Measured (``benchmarks/fit_optimisers.py --repeats 3``, the problems of
``tests/test_fit.py``, float64, CPU, 2-core AMD EPYC, quiet; median wall time of the
compiled fit from the same start, iterations in brackets; L-BFGS is the previous
optimiser, run from the commit before the switch in the same session):

==========================  ==============  ==============  ===========  ===========
data                        L-BFGS (then)   GN (here)       optx GN      optx LM
==========================  ==============  ==============  ===========  ===========
noisy, torque-free          0.504 s (2)     0.185 s (2)     0.192 (5)    0.813 (20)
noisy, heavy top            0.864 s (2)     0.233 s (2)     0.253 (5)    0.517 (11)
noise-free, torque-free     0.400 s (2)     0.030 s (2)     0.026 (4)    0.076 (10)
noise-free, heavy top       0.465 s (3)     0.058 s (3)     0.042 (5)    0.171 (11)
==========================  ==============  ==============  ===========  ===========

All reach the same objective (noisy: 3.0656e-06 and 3.0694e-06; noise-free:
round-off, 3e-30 to 8e-29) and the same moments to ~1e-8 relative (here and L-BFGS
stop on ``ftol``, 0.01 standard errors short of the optimum that optimistix's
``rtol=atol=1e-10`` runs reach). Gauss–Newton is 2.7–13× faster than the L-BFGS it
replaced. optimistix's ``least_squares`` alone does not give what `fit_inertia`
returns, so ``GaussNewton``'s ``init``/``step`` run here in one ``lax.while_loop``
that keeps the per-iteration ``loss_history``, counts ``max_iter``, applies the
``converged`` test (see `fit_inertia`'s ``ftol``) and searches with backtracking
Armijo instead of the bare unit step (a safeguard for starts far from the
optimum, e.g. a user's ``inertia0``; the full step is taken whenever it decreases
the objective enough, which is every step on the test problems).

Memory: the Jacobian is computed in forward mode together with the residuals
(``n_free`` tangents pushed through the rollout, nothing stored per step), so a
Gauss–Newton iteration holds ``J`` (``n_residuals × n_free``) rather than the
per-step tape that ``jax.linearize`` of the rollout would keep.
"""

from collections.abc import Callable
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
import optax
import optimistix as optx

from ._objective import _residuals, _value_and_grad
from ._parameterisation import _flat, _Params, _unflat


MAX_REJECTIONS = 40  # consecutive Armijo halvings before giving up: the step is then 2⁻⁴⁰ of Gauss–Newton's


class _Optimised(NamedTuple):
    """Where `_optimise` stopped."""

    params: _Params
    loss_history: (
        np.ndarray
    )  # (n_iterations + 1,) float64: the objective before each iteration, and at the end
    n_iterations: int  # Adam steps + Gauss–Newton iterations
    converged: bool  # stopped on ftol or the round-off floor, not on max_iter or a failed search


class _DampedGaussNewton(optx.AbstractGaussNewton):
    """Gauss–Newton (Newton descent on ``JᵀJ``) with a backtracking Armijo search from the full step."""

    rtol: float = 0.0  # unused: `gauss_newton` decides when to stop
    atol: float = 0.0
    norm: Callable = optx.max_norm
    descent: optx.NewtonDescent = optx.NewtonDescent()
    search: optx.BacktrackingArmijo = optx.BacktrackingArmijo()
    verbose: Callable = lambda **_: None


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


def _forward_jacobian(residuals):
    """``residuals`` whose derivative is its forward-mode Jacobian, computed along with the value.

    ``jax.linearize`` of the rollout (optimistix's default for Gauss–Newton) keeps
    every step's linearisation point; here the JVP rule computes ``J`` by
    ``jax.jacfwd`` and the linear part is ``J @ t``, so only ``J`` is kept.
    """

    @jax.custom_jvp
    def fn(z):
        return residuals(z)

    def value_twice(z):  # jacfwd's output and, as its aux, the value: one rollout traced, not two
        r = residuals(z)
        return r, r

    @fn.defjvp
    def fn_jvp(primals, tangents):
        (z,), (t,) = primals, tangents
        jac, r = jax.jacfwd(value_twice, has_aux=True)(z)
        return r, jac @ t

    return fn


def _inertia_residuals(z, data):
    """`fit_inertia`'s residual vector at the free coordinates ``z`` (the rest of ``x`` fixed)."""
    x, free, like, problem = data
    return _residuals(_unflat(x.at[free].set(z), like, z.dtype), problem)[0]


@eqx.filter_jit
def gauss_newton(residual_fn, z0, data, ftol, floor, max_iter: int, minimum_norm: bool = False):
    """Gauss–Newton on ``residual_fn(z, data)`` from ``z0``: ``(z, history, n, converged, r, J)``.

    ``history[k]`` is the objective (the sum of squared residuals) at iterate ``k``
    for ``k ≤ n``. Converged: the objective is at most ``floor``, or the decrease
    that the Gauss–Newton model predicts for the next full step, ``|J d|²``, is at
    most ``ftol ×`` the objective. ``residual_fn`` is static (a module-level
    function); ``data`` is a pytree of its arrays and static configuration.
    ``r`` and ``J`` are the residuals and their Jacobian at ``z`` (the last
    accepted iterate), which the solver already holds: a covariance needs no
    second differentiation of the rollout. ``minimum_norm``: solve for the step
    by SVD, so that a direction the data do not determine is not moved along
    (QR's step there is arbitrary, and was measured at 1e12 × the parameters).
    """
    solver = (
        _DampedGaussNewton(descent=optx.NewtonDescent(linear_solver=lx.SVD()))
        if minimum_norm
        else _DampedGaussNewton()
    )
    residuals = _forward_jacobian(lambda z: residual_fn(z, data))

    def fn(z, _):
        return residuals(z), None

    # "bwd": optimistix materialises J (from our forward-mode rule, transposed), so the solver state
    # holds arrays only and can be a while_loop carry; "fwd" would carry a closure over a jaxpr.
    options = {"jac": "bwd"}
    f_struct = jax.eval_shape(residuals, z0)
    state = solver.init(fn, z0, None, options, f_struct, None, frozenset())
    history = jnp.zeros(max_iter + 1, z0.dtype)
    zero = jnp.zeros((), state.num_accepted_steps.dtype)

    def cond(carry):
        *_, done, _ = carry
        return ~done

    def body(carry):
        z, state, history, _, _, _ = carry
        z, state, _ = solver.step(fn, z, None, options, state, frozenset())
        r = state.f_info.residual
        f = jnp.sum(r * r)
        n = state.num_accepted_steps - 1  # the first step evaluates z0 and always accepts it
        history = history.at[jnp.clip(n, 0, max_iter)].set(f)
        full_step, _ = solver.descent.step(jnp.ones((), z.dtype), state.descent_state)
        moved = state.f_info.jac.mv(full_step)
        predicted = -jnp.sum((2 * r + moved) * moved)
        accepted = state.num_steps_since_acceptance == 0
        converged = accepted & ((f <= floor) | (predicted <= ftol * f))
        done = converged | (accepted & (n >= max_iter)) | (state.num_steps_since_acceptance >= MAX_REJECTIONS)
        return z, state, history, n, done, converged

    carry = (z0, state, history, zero, jnp.array(False), jnp.array(False))
    z, state, history, n, _, converged = jax.lax.while_loop(cond, body, carry)
    return z, history, n, converged, state.f_info.residual, state.f_info.jac.as_matrix()


def _optimise(
    params, problem, free, *, adam_steps, adam_learning_rate, max_iter, ftol, floor
) -> "_Optimised":
    """Adam warm-up (optional, eager), then Gauss–Newton (`gauss_newton`) over the ``free`` coordinates."""
    dtype = params.chol.dtype
    x = _flat(params)
    history = []
    if adam_steps:
        adam = optax.adam(adam_learning_rate)
        state = adam.init(jnp.asarray(x[free]))
        adam_update = jax.jit(adam.update)
        for _ in range(adam_steps):
            value, grad = _value_and_grad(_unflat(x, params, dtype), problem)
            history.append(float(value))
            with jax.numpy_dtype_promotion("standard"):
                step, state = adam_update(jnp.asarray(_flat(grad)[free]), state)
            x = x.copy()
            x[free] += np.asarray(step)
    z, gn_history, n, converged, _, _ = gauss_newton(
        _inertia_residuals,
        jnp.asarray(x[free], dtype),
        (jnp.asarray(x, dtype), jnp.asarray(free), params, problem),
        jnp.asarray(ftol, dtype),
        jnp.asarray(floor, dtype),
        max_iter,
    )
    n = int(n)
    x[free] = np.asarray(z, np.float64)
    history.extend(np.asarray(gn_history[: n + 1], np.float64).tolist())
    return _Optimised(_unflat(x, params, dtype), np.asarray(history), adam_steps + n, bool(converged))
