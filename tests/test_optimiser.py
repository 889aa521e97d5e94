"""`jaxrot._fit._optimiser`: `gauss_newton` on problems small enough to follow by hand, and its step.

``r(z) = arctan(z)`` from ``z₀ = 3``: the full Gauss–Newton step ``−arctan(z)(1 + z²)`` overshoots
to ``z ≈ −9.5`` (a larger objective), so Armijo's search halves it twice before accepting; then
the iteration converges to the root ``z = 0``.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxrot._fit._optimiser import MAX_REJECTIONS, _least_squares_step, gauss_newton, triangular_factor


def arctan_residual(z, data):
    return jnp.arctan(z)


def arctan_with_aux(z, data):
    """``(r, J, aux)``: ``aux`` records the point it was evaluated at."""
    return jnp.arctan(z), jnp.diag(1 / (1 + z * z)), {"at": z}


def fit(z0, max_iter=50, jacobian_fn=None, ftol=1e-12):
    z0 = jnp.asarray(z0)
    return gauss_newton(
        arctan_residual, z0, None, jnp.asarray(ftol), jnp.asarray(0.0), max_iter, jacobian_fn=jacobian_fn
    )


def test_backtracks_then_converges_and_aux_belongs_to_the_returned_iterate():
    z, history, n, converged, r, jac, aux = fit([3.0], jacobian_fn=arctan_with_aux)
    assert bool(converged)
    assert abs(float(z[0])) < 1e-12  # the root; each late step cubes the error
    history = np.asarray(history[: int(n) + 1])
    # The start, evaluated in the loop's first pass. XLA's and libm's arctan are each within an ulp
    # or two, squared: 1e-15 relative.
    np.testing.assert_allclose(history[0], np.arctan(3.0) ** 2, rtol=1e-15)
    assert np.all(np.diff(history) < 0)  # every accepted step lowered the objective
    # A rejected trial (the overshoot to z ≈ -9.5) never leaks into the returned values: they are
    # those of z (to the rounding of another compiled arctan for r and J).
    np.testing.assert_array_equal(aux["at"], z)
    np.testing.assert_allclose(r, jnp.arctan(z), rtol=1e-15, atol=1e-300)
    np.testing.assert_allclose(jac, jnp.diag(1 / (1 + z * z)), rtol=1e-15)


def test_forward_mode_default_gives_the_same_iterates_and_no_aux():
    own = fit([3.0], jacobian_fn=arctan_with_aux)
    default = fit([3.0])
    assert default[6] is None
    np.testing.assert_array_equal(default[0], own[0])
    np.testing.assert_array_equal(default[1], own[1])
    assert int(default[2]) == int(own[2])


def test_no_iterations_returns_the_start_and_its_objective():
    z, history, n, converged, r, _, aux = fit([3.0], max_iter=0, jacobian_fn=arctan_with_aux)
    assert int(n) == 0 and not bool(converged)
    np.testing.assert_array_equal(z, [3.0])
    np.testing.assert_array_equal(aux["at"], [3.0])
    np.testing.assert_allclose(float(history[0]), np.arctan(3.0) ** 2, rtol=1e-15)


def test_a_nan_start_stops_unconverged_after_the_rejections():
    z, history, n, converged, *_ = fit([jnp.nan], jacobian_fn=arctan_with_aux)
    assert int(n) == 0 and not bool(converged)
    assert np.isnan(float(history[0]))
    assert MAX_REJECTIONS > 0 and np.isnan(float(z[0]))


@pytest.mark.parametrize("shape", [(200, 6), (6, 6)])  # tall: R and Qᵀr from [J | r]; square: Q formed
def test_least_squares_step_is_numpys_lstsq(shape):
    """The Gauss–Newton step ``d = argmin |J d + r|`` against `np.linalg.lstsq`, with column scales
    spread over 4 decades (as identify's Jacobians): a backward-stable solve of condition κ ≈ 1e4
    is within a few κ eps of another, relative to |d|; 1e3 κ eps is that with margin."""
    rng = np.random.default_rng(shape[0])
    jac = rng.normal(size=shape) * np.logspace(0, 4, shape[1])
    r = rng.normal(size=shape[0])
    expected = -np.linalg.lstsq(jac, r, rcond=None)[0]
    bound = 1e3 * np.linalg.cond(jac) * np.finfo(np.float64).eps * np.abs(expected).max()
    for minimum_norm in (True, False):
        d = jax.jit(_least_squares_step, static_argnums=2)(jac, r, minimum_norm)
        np.testing.assert_allclose(d, expected, rtol=0, atol=bound)


def test_triangular_factor_is_lapacks_up_to_row_signs():
    """`triangular_factor` (Householder in jax.numpy, not LAPACK's threaded ``geqrf``) against
    `np.linalg.qr`: both backward stable, so ``R`` agrees up to the sign of each row within a few
    ``m n eps`` of its largest entry (1e3 eps here: m n eps = 1.3e-12 would be the crude bound, the
    error is in fact ~1e-15); ``RᵀR = AᵀA`` as well; a zero column stays zero and finite."""
    rng = np.random.default_rng(3)
    a = rng.normal(size=(300, 8)) * np.logspace(0, 5, 8)
    a[:, 3] = 0.0
    upper = np.asarray(jax.jit(triangular_factor)(jnp.asarray(a)))
    expected = np.linalg.qr(a, mode="r")
    signs = np.where(np.sign(np.diag(upper)) == np.sign(np.diag(expected)), 1.0, -1.0)
    scale = np.abs(expected).max()
    np.testing.assert_allclose(
        upper, signs[:, None] * expected, rtol=0, atol=1e3 * np.finfo(float).eps * scale
    )
    np.testing.assert_allclose(upper.T @ upper, a.T @ a, rtol=0, atol=1e3 * np.finfo(float).eps * scale**2)
    assert np.all(np.isfinite(upper)) and np.all(upper[:, 3] == 0) and np.all(np.tril(upper, -1) == 0)


def test_least_squares_step_of_a_rank_deficient_jacobian_is_the_minimum_norm_one():
    """Two equal columns: the data fix only their sum; the minimum-norm step splits it evenly, as
    the pseudo-inverse does (`np.linalg.lstsq`), and does not move along their difference."""
    rng = np.random.default_rng(3)
    jac = rng.normal(size=(50, 4))
    jac[:, 3] = jac[:, 2]
    r = rng.normal(size=50)
    d = jax.jit(_least_squares_step, static_argnums=2)(jac, r, True)
    expected = -np.linalg.lstsq(jac, r, rcond=None)[0]
    np.testing.assert_allclose(d, expected, rtol=0, atol=1e-12 * np.abs(expected).max())
    assert abs(float(d[2] - d[3])) < 1e-12 * np.abs(expected).max()
