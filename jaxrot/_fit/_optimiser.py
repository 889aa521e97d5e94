"""The fits' optimiser: Gauss–Newton with a backtracking Armijo search, one compiled loop.

Why Gauss–Newton. The objective is a sum of squared residuals of a long rollout:
a narrow curved valley with parameter sensitivities spread over ~5 decades.
Gauss–Newton takes its curvature from ``JᵀJ`` and is invariant to a linear
change of coordinates, so it needs no rescaling; the previous optimiser, L-BFGS
(optax's directions, a weak-Wolfe line search in Python) had to run in
coordinates whitened by a finite-difference ``JᵀJ``, re-whitened every few
iterations. Measured (``benchmarks/fit_optimisers.py --repeats 3``, the problems of
``tests/test_fit.py``, float64, CPU, 2-core AMD EPYC; median wall time of the compiled fit from the
same start, iterations in brackets; L-BFGS is the previous optimiser):

==========================  ==============  ==============  ===========  ===========
data                        L-BFGS (then)   GN (here)       optx GN      optx LM
==========================  ==============  ==============  ===========  ===========
noisy, torque-free          0.504 s (2)     0.055 s (2)     0.096 (5)    0.304 (12)
noisy, heavy top            0.864 s (2)     0.085 s (2)     0.160 (5)    1.064 (29)
noise-free, torque-free     0.400 s (2)     0.020 s (2)     0.021 (4)    0.056 (10)
noise-free, heavy top       0.465 s (3)     0.017 s (3)     0.033 (5)    0.083 (11)
==========================  ==============  ==============  ===========  ===========

(GN and optx: one run, 2026-11-25, jax 0.10.2; L-BFGS: an earlier session's run.) Gauss–Newton
is 9–27× faster than the L-BFGS it replaced and 1.0–1.9× faster than optimistix's own.

All reach the same objective (noisy: 3.0656e-06 and 3.0694e-06; noise-free:
round-off, 3e-30 to 3e-27) and the same moments to ~1e-8 relative (here and
L-BFGS stop on ``ftol``, 0.01 standard errors short of the optimum that optimistix's
``rtol=atol=1e-10`` runs reach). optimistix's ``least_squares`` alone does not give
what the fits return (the per-iteration ``loss_history``, ``max_iter``, the
``converged`` test of `fit_inertia`'s ``ftol``, the Jacobian at the optimum for the
covariance), and its Gauss–Newton materialises ``J`` from the transposed
linearisation (`gauss_newton`'s docstring), so the loop is written out here:
`gauss_newton`, with backtracking Armijo instead of the bare unit step (a safeguard
for starts far from the optimum, e.g. a user's ``inertia0``; the full step is taken
whenever it decreases the objective enough, which is every step on the test problems).

Memory: the Jacobian is computed in forward mode together with the residuals
(``n_free`` tangents pushed through the rollout, nothing stored per step), so a
Gauss–Newton iteration holds ``J`` (``n_residuals × n_free``) rather than the
per-step tape that ``jax.linearize`` of the rollout would keep.
"""

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.extend.core import jaxpr_as_fun


MAX_REJECTIONS = 40  # consecutive Armijo halvings before giving up: the step is then 2⁻⁴⁰ of Gauss–Newton's
ARMIJO_SLOPE = 0.1  # accept a step that achieves this fraction of the decrease its slope predicts
ARMIJO_FACTOR = 0.5  # and halve it otherwise


def triangular_factor(a):
    """``R`` ``(n, n)`` of ``A = Q R`` for a tall ``A`` ``(m, n)``, ``m ≥ n``: Householder reflections in
    `jax.numpy` (LAPACK's sign convention, ``β = −sign(α) ‖x‖``, so no cancellation).

    Not `jnp.linalg.qr`: on CPU that calls LAPACK's ``geqrf`` in the threaded OpenBLAS that NumPy
    and SciPy bring, whose threads spin against XLA's and other processes' on a shared machine: a
    3 267 × 28 QR measured 200 ms there (1.1 ms with ``OPENBLAS_NUM_THREADS=1``), four times the
    Jacobian evaluation it follows. Here the ``n`` reflections are ``O(m n)`` each in XLA's own loop.
    """
    m, n = a.shape
    rows = jnp.arange(m)

    def reflect(k, a):
        x = jnp.where(rows >= k, a[:, k], 0)
        alpha = a[k, k]
        beta = -jnp.where(alpha >= 0, 1, -1) * jnp.sqrt(jnp.sum(x * x))
        v = x.at[k].set(alpha - beta)  # x − β e_k, |v_k| = |α| + ‖x‖
        norm2 = jnp.sum(v * v)
        scale = jnp.where(norm2 > 0, 2 / jnp.where(norm2 > 0, norm2, 1), 0)  # a zero column: no reflection
        return a - (scale * v)[:, None] * (v @ a)[None, :]

    return jnp.triu(jax.lax.fori_loop(0, n, reflect, a)[:n])


def _least_squares_step(jac, r, minimum_norm, factor=None):
    """The Gauss–Newton step ``d`` minimising ``|J d + r|``: ``J = Q R``, then the SVD of ``R`` (the
    minimum-norm ``d``) or a triangular solve. ``factor``: the triangular factor ``(n + 1, n + 1)`` of
    ``[J | r]`` when the caller has it (`search_step`'s ``factor_of``)."""
    m, n = jac.shape
    if factor is not None:
        upper, q_r = factor[:n, :n], factor[:n, n]
    elif m > n:
        # ``Qᵀ r`` without ``Q``: the triangular factor of ``[J | r]`` holds ``R`` and, in its last
        # column, ``Qᵀ r`` (the same reflections applied to ``r``). Forming the 3 267 × 27 ``Q`` of
        # identify's satellite took 0.83 ms of the step's 2.8 (XLA:CPU profile, per iteration).
        both = triangular_factor(jnp.concatenate([jac, r[:, None]], axis=1))
        upper, q_r = both[:n, :n], both[:n, n]
    else:
        q, upper = jnp.linalg.qr(jac)
        q_r = q.T @ r
    if minimum_norm:
        # The SVD of the small triangular factor (J = Q R, R = U S Vᵀ: J's singular values and right
        # vectors; Chan, ACM TOMS 8, 1982): 2.2 ms instead of 7.0 ms for the whole step on a 3 267 × 27
        # matrix with column norms spread over 5 decades like the Jacobian of `jaxrot.identify`'s
        # satellite (one-off script), same step to 1e-15.
        u, s, vt = jnp.linalg.svd(upper, full_matrices=False)
        # lineax's and numpy's cut-off: singular values below eps · max(m, n) · s_max count as zero.
        cutoff = jnp.finfo(jac.dtype).eps * max(jac.shape) * s[0]
        s_inv = jnp.where(s > cutoff, 1 / jnp.where(s > cutoff, s, 1), 0)
        return -(vt.T @ (s_inv * (u.T @ q_r)))
    return -jax.scipy.linalg.solve_triangular(upper, q_r)


def _converged(f, predicted, ftol, floor):
    """Whether the objective ``f`` (predicted next decrease ``predicted``) is as low as it can be shown to go.

    ``floor`` is the objective of residuals that are round-off only (`fit_inertia`'s ``round_off_floor``);
    the objective itself is then uncertain by up to ``2 √(f · floor)`` (Cauchy–Schwarz
    on ``Σ 2 rᵢ δᵢ``), and a smaller predicted decrease cannot be verified by any
    step. Measured on the noise-free satellite of the tests with ``rkmk_dopri5`` at 3
    steps per sample: its model error (~2e-10 rad against σ = 1e-4) leaves ``f`` at
    7.2e-9, far above ``floor`` but with ``ftol × f`` far below its round-off, and
    the search had stalled, accepting unchanged points, until ``max_iter`` (100 s).
    """
    return (f <= floor) | (predicted <= ftol * f) | (predicted <= 2 * jnp.sqrt(f * floor))


class Search(NamedTuple):
    """Gauss–Newton's line-search state: the accepted iterate and what is known there, and the trial."""

    z: jax.Array  # the accepted iterate
    r: jax.Array  # its residuals
    jac: jax.Array  # their Jacobian
    aux: object  # the evaluation's auxiliary values there (a pytree)
    f: jax.Array  # the objective there (inf before the first evaluation)
    d: jax.Array  # the Gauss–Newton step from z (zero: the next trial is z itself)
    slope: jax.Array  # the objective's slope along d
    alpha: jax.Array  # the trial's fraction of d
    rejections: jax.Array  # consecutive rejected trials


def trace_once(evaluate, *example):
    """``(evaluate as one traced jaxpr, its output shapes)``: a loop that calls it from several places
    of its body (or once, from inside) traces and compiles the rollout once."""
    traced, shapes = jax.make_jaxpr(evaluate, return_shape=True)(*example)
    out_tree = jax.tree_util.tree_structure(shapes)

    def call(*args):
        return jax.tree_util.tree_unflatten(out_tree, jaxpr_as_fun(traced)(*args))

    return call, shapes


def start_search(z0, shapes):
    """The `Search` before the first evaluation (``shapes``: `trace_once`'s ``(r, J, aux)``): its first
    trial is ``z0`` itself, to be accepted with ``force``."""
    r_shape, jac_shape, aux_shape = shapes
    zeros = lambda x: jnp.zeros(x.shape, x.dtype)  # noqa: E731
    return Search(
        z=z0, r=zeros(r_shape), jac=zeros(jac_shape), aux=jax.tree.map(zeros, aux_shape),
        f=jnp.asarray(jnp.inf, z0.dtype), d=jnp.zeros_like(z0), slope=jnp.zeros((), z0.dtype),
        alpha=jnp.ones((), z0.dtype), rejections=jnp.zeros((), jnp.int32),
    )  # fmt: skip


def search_step(s, evaluate, force, minimum_norm, factor_of=None):
    """One trial of Gauss–Newton with backtracking Armijo: ``(Search, accepted, predicted decrease)``.

    The trial ``z + α d`` is evaluated (``evaluate(z) -> (r, J, aux)``) and accepted when ``force`` (a
    pass's start) or when its objective is strictly lower and within Armijo's test; then the next
    proposal is the full Gauss–Newton step from the accepted point (``α = 1``), or the same step
    halved after a rejection. ``predicted``: the model's decrease for the full step from the
    accepted point (`_converged`). ``factor_of(aux)``: the triangular factor of ``[J | r]`` where the
    evaluation computed it more cheaply than a QR of the whole ``J`` (`jaxrot.identify`: from each
    experiment's own columns); None: the QR of ``[J | r]`` here.
    """
    z_try = s.z + s.alpha * s.d
    r_try, jac_try, aux_try = evaluate(z_try)
    f_try = jnp.sum(r_try * r_try)
    # Strictly lower, too: once alpha * slope is below f's last digit, Armijo's test alone would
    # accept an unchanged point; False for a NaN objective as well.
    accept = force | ((f_try < s.f) & (f_try <= s.f + ARMIJO_SLOPE * s.alpha * s.slope))
    z, r, jac, aux, f = jax.tree.map(
        lambda a, b: jnp.where(accept, a, b),
        (z_try, r_try, jac_try, aux_try, f_try),
        (s.z, s.r, s.jac, s.aux, s.f),
    )
    d = _least_squares_step(jac, r, minimum_norm, None if factor_of is None else factor_of(aux))
    moved = jac @ d
    predicted = -jnp.sum((2 * r + moved) * moved)  # the model's decrease for the full step
    one = jnp.ones((), s.alpha.dtype)
    out = Search(
        z=z, r=r, jac=jac, aux=aux, f=f,
        d=jnp.where(accept, d, s.d),
        slope=jnp.where(accept, 2 * jnp.sum(r * moved), s.slope),
        alpha=jnp.where(accept, one, ARMIJO_FACTOR * s.alpha),
        rejections=jnp.where(accept, 0, s.rejections + 1).astype(jnp.int32),
    )  # fmt: skip
    return out, accept, predicted


@eqx.filter_jit
def gauss_newton(
    residual_fn, z0, data, ftol, floor, max_iter: int, minimum_norm: bool = False, jacobian_fn=None
):
    """Gauss–Newton on ``residual_fn(z, data)`` from ``z0``: ``(z, history, n, converged, r, J, aux)``.

    ``history[k]`` is the objective (the sum of squared residuals) at iterate ``k``
    for ``k ≤ n``. Converged (`_converged`): the objective is at most ``floor``, or
    the decrease that the Gauss–Newton model predicts for the next full step is at
    most ``ftol ×`` the objective or too small to be seen in it. ``residual_fn`` is static (a module-level
    function); ``data`` is a pytree of its arrays and static configuration.
    ``r`` and ``J`` are the residuals and their Jacobian at ``z`` (the last
    accepted iterate), which the loop already holds: a covariance needs no
    second differentiation of the rollout. ``minimum_norm``: solve for the step
    by SVD, so that a direction the data do not determine is not moved along
    (QR's step there is arbitrary, and was measured at 1e12 × the parameters).

    Each trial point costs one rollout with ``len(z)`` forward-mode tangents
    (``jax.jacfwd``, the residuals as its auxiliary output), nothing stored per
    step; or ``jacobian_fn(z, data) -> (r, J, aux)`` (static) where the caller knows
    a cheaper way (`jaxrot.identify`: per experiment, only the tangents it depends on),
    ``aux`` a pytree of values computed on the way (identify: the modelled states),
    returned at ``z`` (``None`` without ``jacobian_fn``).
    A trial is accepted by Armijo's test from the full step, halved up to
    ``MAX_REJECTIONS`` times. The loop is written out rather than taken from
    optimistix: its Gauss–Newton materialises ``J`` by transposing the
    linearisation (``jax.jacrev``: an ``m × m`` identity of cotangents, ``m`` the
    residuals, 3 267 for the three-manoeuvre satellite, and an ``m² n`` product per
    trial). Measured on that satellite, same iterates: 0.32 s → 0.19 s.

    The iteration itself (trial point, Armijo's test, the next proposal) is `search_step`, which
    `jaxrot.identify`'s staged loop (`_identify._solve`) runs too: one Gauss–Newton in the package.
    """

    def evaluate(z):
        if jacobian_fn is not None:
            return jacobian_fn(z, data)

        def twice(z):
            r = residual_fn(z, data)
            return r, r

        jac, r = jax.jacfwd(twice, has_aux=True)(z)
        return r, jac, None

    # The first pass of the loop evaluates z0 (accepted unconditionally, no iteration counted), so
    # the Jacobian program is compiled once, inside the loop, and traced once, here, instead of
    # also before the loop: on the three-manoeuvre satellite of `jaxrot.identify`, tracing 1.7 →
    # 1.0 s and compiling 5.2 → 3.8 s; with the states riding along as ``aux`` (no program of their
    # own, 1.6 s) its first call went from 12.0 to 6.4 s (one run each, `jax_log_compiles`, at
    # 06a7bff; `benchmarks/identify_speed.py` has the current figure).
    evaluate_traced, shapes = trace_once(evaluate, z0)
    zero, false = jnp.zeros((), jnp.int32), jnp.zeros((), bool)
    # carry: the search, history, accepted steps, started, done, converged
    carry = (start_search(z0, shapes), jnp.zeros(max_iter + 1, z0.dtype), zero, false, false, false)

    def body(carry):
        s, history, n, started, _, _ = carry
        s, accept, predicted = search_step(s, evaluate_traced, ~started, minimum_norm)
        n = jnp.where(accept & started, n + 1, n)
        history = jnp.where(accept, history.at[jnp.clip(n, 0, max_iter)].set(s.f), history)
        converged = accept & _converged(s.f, predicted, ftol, floor)
        done = converged | (accept & (n >= max_iter)) | (s.rejections >= MAX_REJECTIONS)
        return s, history, n, jnp.ones((), bool), done, converged

    s, history, n, _, _, converged = jax.lax.while_loop(lambda carry: ~carry[-2], body, carry)
    return s.z, history, n, converged, s.r, s.jac, s.aux
