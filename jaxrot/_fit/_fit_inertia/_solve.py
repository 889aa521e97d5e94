"""`fit_inertia`'s solve: an optional Adam warm-up, then Gauss–Newton over the free parameters.

`solve` runs the shared `gauss_newton` on the `residuals` of the `Model` at the free
coordinates (`_free_residuals`); `round_off_floor` is the objective below which a fit
has converged (see ``ftol`` in `fit_inertia`).
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax

from .._optimiser import gauss_newton
from .._parameterisation import _flat, _Params, _unflat
from ._residuals import residuals, value_and_grad


class Solution(NamedTuple):
    """Where `solve` stopped."""

    params: _Params
    loss_history: (
        np.ndarray
    )  # (n_iterations + 1,) float64: the objective before each iteration, and at the end
    n_iterations: int  # Adam steps + Gauss–Newton iterations
    converged: bool  # stopped on ftol or the round-off floor, not on max_iter or a failed search


def round_off_floor(model, omega_scale):
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
    eps = float(jnp.finfo(model.data.t.dtype).eps)
    angle = (model.n_outer * model.n_inner + 1) * eps
    floor = angle**2
    if model.data.omega is not None:
        floor += model.omega_weight * (angle * omega_scale) ** 2
    if model.data.q.shape[0] > 1:
        floor += model.continuity_weight * angle**2 * (1 + (model.spacing * omega_scale) ** 2)
    return floor


def _free_residuals(z, data):
    """`fit_inertia`'s residual vector at the free coordinates ``z`` (the rest of ``x`` fixed)."""
    x, free, like, model = data
    return residuals(_unflat(x.at[free].set(z), like, z.dtype), model)[0]


def solve(params, model, free, *, adam_steps, adam_learning_rate, max_iter, ftol, floor) -> Solution:
    """Adam warm-up (optional, eager), then Gauss–Newton (`gauss_newton`) over the ``free`` coordinates."""
    dtype = params.chol.dtype
    x = _flat(params)
    history = []
    if adam_steps:
        adam = optax.adam(adam_learning_rate)
        state = adam.init(jnp.asarray(x[free]))
        adam_update = jax.jit(adam.update)
        for _ in range(adam_steps):
            value, grad = value_and_grad(_unflat(x, params, dtype), model)
            history.append(float(value))
            with jax.numpy_dtype_promotion("standard"):
                step, state = adam_update(jnp.asarray(_flat(grad)[free]), state)
            x = x.copy()
            x[free] += np.asarray(step)
    z, gn_history, n, converged, _, _, _ = gauss_newton(
        _free_residuals,
        jnp.asarray(x[free], dtype),
        (jnp.asarray(x, dtype), jnp.asarray(free), params, model),
        jnp.asarray(ftol, dtype),
        jnp.asarray(floor, dtype),
        max_iter,
    )
    n = int(n)
    x[free] = np.asarray(z, np.float64)
    history.extend(np.asarray(gn_history, np.float64)[: n + 1].tolist())
    return Solution(_unflat(x, params, dtype), np.asarray(history), adam_steps + n, bool(converged))
