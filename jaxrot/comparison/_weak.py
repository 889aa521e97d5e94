r"""Weak errors, measured: ensemble averages along a ladder of steps driven by one refined noise.

A scheme's weak error is the bias of an ensemble average, ``E_h[f] − E[f]``, against the step
``h``. Each level of the ladder takes steps of ``h = m h_fine`` and draws its step's normals as the
sums of the finest level's, ``ξ = Σ_{i<m} ξ_{jm+i} / √m``: every level is the scheme in law (the
sums are standard normals, independent between steps), and all levels follow one refined Brownian
path, so the differences between levels vary far less than the averages (a body's ``f`` at two
levels differs by the scheme's strong error, not by the spread of ``f``). Then

    d(h) = E_h[f] − E_{h/2}[f] = C (1 − 2^{−p}) h^p + …

gives the weak order ``p`` from a log-log fit with small statistical errors, and the finest level,
extrapolated (``E_{h_min} − d(h_min)/(2^p − 1)``), is compared with the closed form (the check that
the limit is right). The statistical error of each mean is its standard error over independent
bodies (each body's time average is one sample).
"""

import math
from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..schemes._noise import body_keys, step_normals


class WeakProblem(NamedTuple):
    """A thermal problem for the ladder (one body's functions, vmapped over ``carry0``'s bodies).

    Attributes:
        advance: ``advance(carry, t, dt, normals) -> carry``: one step of one body.
        carry0: the bodies' initial carries, leading axis the bodies.
        observe: ``observe(carry) -> (k,)``: the quantities averaged.
        normals_per_step: standard normals a step takes.
    """

    advance: Callable
    carry0: Any
    observe: Callable
    normals_per_step: int


def _runner(problem: WeakProblem, impl: str):
    """One compiled program for every level of ``problem``: the step, the coarsening ``m``, the
    number of steps and the averaging window are traced (``fori_loop`` with traced bounds)."""
    count = problem.normals_per_step

    @jax.jit
    def run(carry0, key_data, dt_fine, m, n_coarse, first):
        dtype = dt_fine.dtype
        dt = m.astype(dtype) * dt_fine
        scale = jax.lax.rsqrt(m.astype(dtype))

        def one(carry, body_key):
            def step(j, state):
                carry, total = state

                def draw(i, acc):
                    return acc + step_normals(body_key, impl, j * m + i, count, dtype)

                normals = jax.lax.fori_loop(0, m, draw, jnp.zeros(count, dtype)) * scale
                carry = problem.advance(carry, j.astype(dtype) * dt, dt, normals)
                seen = problem.observe(carry)
                return carry, total + jnp.where(j + 1 >= first, 1, 0).astype(dtype) * seen

            zero = jnp.zeros_like(problem.observe(carry))
            _, total = jax.lax.fori_loop(0, n_coarse, step, (carry, zero))
            return total / (n_coarse - first + 1).astype(dtype)

        return jax.vmap(one)(carry0, key_data)

    return run


def level_averages(problem: WeakProblem, key, dt_fine, n_fine: int, m: int, average_from: float, run=None):
    """Per-body averages ``(N, k)`` of ``observe`` over the steps of ``h = m·dt_fine`` that end at
    times ``≥ average_from · n_fine · dt_fine`` (``1.0``: the final state only)."""
    n = jax.tree_util.tree_leaves(problem.carry0)[0].shape[0]
    key_data, impl = body_keys(key, n)
    n_coarse = n_fine // m
    first = max(1, math.ceil(average_from * n_coarse - 1e-9))
    run = _runner(problem, impl) if run is None else run
    integer = jnp.int32
    dt_fine = jnp.asarray(dt_fine, jax.tree_util.tree_leaves(problem.carry0)[0].dtype)
    return run(problem.carry0, key_data, dt_fine, integer(m), integer(n_coarse), integer(first))


class Ladder(NamedTuple):
    """A ladder's statistics, levels from the coarsest step to the finest, per observed quantity.

    Attributes: ``dt`` ``(L,)``; ``mean``, ``stderr`` ``(L, k)`` of the averages; ``difference``,
    ``difference_stderr`` ``(L − 1, k)`` of ``E_h − E_{h/2}`` (coupled)."""

    dt: np.ndarray
    mean: np.ndarray
    stderr: np.ndarray
    difference: np.ndarray
    difference_stderr: np.ndarray


def ladder(problem: WeakProblem, key, dt_fine, n_fine: int, coarsenings=(16, 8, 4, 2, 1), average_from=0.5):
    """The `Ladder` of ``problem`` at steps ``m·dt_fine`` for ``m`` in ``coarsenings`` (each twice the
    next, ``n_fine`` a multiple of each)."""
    n = jax.tree_util.tree_leaves(problem.carry0)[0].shape[0]
    run = _runner(problem, body_keys(key, 1)[1])
    values = [
        np.asarray(level_averages(problem, key, dt_fine, n_fine, m, average_from, run), np.float64)
        for m in coarsenings
    ]
    mean = np.array([v.mean(axis=0) for v in values])
    stderr = np.array([v.std(axis=0, ddof=1) / math.sqrt(n) for v in values])
    gaps = [a - b for a, b in zip(values[:-1], values[1:], strict=True)]
    difference = np.array([g.mean(axis=0) for g in gaps])
    difference_stderr = np.array([g.std(axis=0, ddof=1) / math.sqrt(n) for g in gaps])
    dt = np.asarray(coarsenings, np.float64) * float(dt_fine)
    return Ladder(dt, mean, stderr, difference, difference_stderr)


def fit_order(ladder_: "Ladder", k: int = 0):
    """``(p, p_stderr)`` of quantity ``k``: the slope of ``log |d(h)|`` against ``log h`` (``d(h)`` at
    the coarser step of each pair) weighted by the relative errors (``σ_log = σ_d / |d|``), over the
    levels where ``|d|`` exceeds three standard errors; NaN when fewer than two do."""
    dt = ladder_.dt[:-1]
    d, s = ladder_.difference[:, k], ladder_.difference_stderr[:, k]
    keep = np.abs(d) > 3 * s
    if keep.sum() < 2:
        return math.nan, math.nan
    x, y = np.log(dt[keep]), np.log(np.abs(d[keep]))
    w = (np.abs(d[keep]) / np.maximum(s[keep], 1e-300)) ** 2
    design = np.stack([np.ones_like(x), x], axis=1)
    normal = design.T @ (w[:, None] * design)
    coef = np.linalg.solve(normal, design.T @ (w * y))
    residual = y - design @ coef
    dof = max(1, len(x) - 2)
    scale = max(1.0, float(np.sum(w * residual**2) / dof))  # inflate by the misfit, never shrink
    covariance = np.linalg.inv(normal) * scale
    return float(coef[1]), float(math.sqrt(covariance[1, 1]))


def local_orders(ladder_: "Ladder", k: int = 0):
    """``[(p, p_stderr) or None]`` per pair of successive differences of quantity ``k``, coarse to fine:
    ``p = log2(d(h) / d(h/2))``, the order between those steps, where both differences exceed three
    standard errors and share a sign (None elsewhere). The error adds the two relative errors in
    quadrature (the differences' correlation, through the shared bodies, is left out)."""
    d, s = ladder_.difference[:, k], ladder_.difference_stderr[:, k]
    out = []
    for a, b, sa, sb in zip(d[:-1], d[1:], s[:-1], s[1:], strict=True):
        if abs(a) > 3 * sa and abs(b) > 3 * sb and a * b > 0:
            p = math.log2(a / b)
            out.append((p, math.hypot(sa / a, sb / b) / math.log(2)))
        else:
            out.append(None)
    return out


def extrapolated(ladder_: Ladder, order: float):
    """``(E_0, stderr)``: the finest level's mean with its bias removed by Richardson's rule at ``order``."""
    factor = 1 / (2**order - 1)
    value = ladder_.mean[-1] - factor * ladder_.difference[-1]
    error = np.hypot(ladder_.stderr[-1], factor * ladder_.difference_stderr[-1])
    return value, error
