"""`jaxrot._core._trig.sincos`: the vectorisable float64 sine and cosine used in the hot loops."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxrot._core._trig import sincos


def ulps(got, want):
    """|got − want| in units of the last place of ``want`` (libm's result)."""
    return np.abs(np.asarray(got) - want) / np.spacing(np.abs(want))


@pytest.mark.parametrize("scale", [1e-300, 1e-8, 1.0, 10.0, 1e3, 1e6])
def test_within_one_ulp_of_libm(scale):
    x = np.random.default_rng(7).uniform(-scale, scale, 50_000)
    s, c = jax.jit(sincos)(jnp.asarray(x))
    assert ulps(s, np.sin(x)).max() <= 1
    assert ulps(c, np.cos(x)).max() <= 1


def test_doubles_closest_to_multiples_of_half_pi():
    # The hardest arguments for the reduction: sin x is ~1e-11 … 1e-17 of |x| here, so a
    # reduction short of ~118 bits is off by 10⁵ ulp (measured before the third round).
    k = np.arange(-200_000, 200_001, dtype=np.float64)
    for x in (k * np.pi / 2, np.nextafter(k * np.pi / 2, np.inf), k * np.pi / 4):
        s, c = jax.jit(sincos)(jnp.asarray(x))
        assert ulps(s, np.sin(x)).max() <= 1
        assert ulps(c, np.cos(x)).max() <= 1


def test_huge_arguments_are_backward_stable():
    # Beyond 2²⁰·π/2 the reduction is exact only to about ulp(x): the result is the sine of a
    # neighbour of x, which is all the argument's own rounding means anyway.
    x = np.random.default_rng(8).uniform(-1e15, 1e15, 50_000)
    s, c = jax.jit(sincos)(jnp.asarray(x))
    assert np.all(np.abs(np.asarray(s) - np.sin(x)) <= 4 * np.spacing(np.abs(x)))
    assert np.all(np.abs(np.asarray(c) - np.cos(x)) <= 4 * np.spacing(np.abs(x)))
    # k·π/2 is no longer exact there, so the reduced argument can overshoot π/4 a little and the
    # polynomials lose a few digits: measured |sin² + cos² − 1| ≤ 1.5e-14.
    assert np.abs(np.asarray(s) ** 2 + np.asarray(c) ** 2 - 1).max() < 1e-13


def test_special_values():
    x = jnp.array([0.0, -0.0, 5e-324, -1e-310, jnp.inf, -jnp.inf, jnp.nan])
    s, c = sincos(x)
    np.testing.assert_array_equal(s[:4], x[:4])
    np.testing.assert_array_equal(np.signbit(s[:2]), [False, True])
    np.testing.assert_array_equal(c[:4], 1.0)
    assert np.all(np.isnan(s[4:])) and np.all(np.isnan(c[4:]))


def test_float32_is_jax_own():
    x = jnp.linspace(-10, 10, 101, dtype=jnp.float32)
    s, c = jax.jit(sincos)(x)
    assert s.dtype == c.dtype == jnp.float32
    np.testing.assert_array_equal(s, jax.jit(jnp.sin)(x))
    np.testing.assert_array_equal(c, jax.jit(jnp.cos)(x))


def test_derivatives_are_exact():
    x = jnp.linspace(-7.0, 7.0, 29)
    s, c = sincos(x)
    np.testing.assert_array_equal(jax.vmap(jax.grad(lambda v: sincos(v)[0]))(x), c)
    np.testing.assert_array_equal(jax.vmap(jax.grad(lambda v: sincos(v)[1]))(x), -s)
    np.testing.assert_array_equal(jax.vmap(jax.grad(jax.grad(lambda v: sincos(v)[0])))(x), -s)
    tangent = jax.jvp(sincos, (x,), (2 * jnp.ones_like(x),))[1]
    np.testing.assert_array_equal(tangent[0], 2 * c)
