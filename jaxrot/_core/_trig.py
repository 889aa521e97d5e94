"""``sin`` and ``cos`` in float64 as one vectorisable polynomial, for the hot loops.

XLA:CPU evaluates float64 ``sin`` and ``cos`` one element at a time (measured
7.3 ns per element for ``sin`` and 9.2 ns for both, against 1.0 ns for ``exp``,
on this project's 2-core machine), and the schemes call them at every step:
Zhao twice, NO_SQUISH five times. `sincos` is the fdlibm/musl kernel (Cody–Waite
reduction by π/2 in three compensated rounds, degree-13/14 minimax polynomials on
``[−π/4, π/4]``) written in `jax.numpy`, so it fuses and vectorises with the
rest of the step. Accuracy: within 1 ulp of the correctly rounded result for
``|x| ≤ 2²⁰·π/2``, including the doubles closest to multiples of π/2 (tested
against the platform's libm); beyond that, where one ulp of ``x`` is already a
sizeable fraction of a radian, the result is within 4 ulp(x) of libm's and
``sin² + cos²`` within 1e-13 of 1. float32 and other dtypes use ``jnp.sin``/``jnp.cos``, which XLA already
vectorises. Derivatives are exact (``d sin = cos dx``) through a `custom_jvp`.
"""

import jax
import jax.numpy as jnp


# π/2 = PIO2_1 + PIO2_2 + PIO2_3 + PIO2_3T, each of the first three with 33 significant bits, and
# PIO2_nT = π/2 − (PIO2_1 + … + PIO2_n) (fdlibm/musl __rem_pio2): k·PIO2_n is exact for |k| < 2²⁰,
# and three compensated rounds keep 151 bits, enough for the doubles closest to multiples of π/2.
_PIO2 = (
    (1.57079632673412561417e00, 6.07710050650619224932e-11),
    (6.07710050630396597660e-11, 2.02226624879595063154e-21),
    (2.02226624871116645580e-21, 8.47842766036889956997e-32),
)
_TWO_OVER_PI = 6.36619772367581382433e-01

# musl __sin / __cos minimax coefficients on [-π/4, π/4].
_S1, _S2, _S3 = -1.66666666666666324348e-01, 8.33333333332248946124e-03, -1.98412698298579493134e-04
_S4, _S5, _S6 = 2.75573137070700676789e-06, -2.50507602534068634195e-08, 1.58969099521155010221e-10
_C1, _C2, _C3 = 4.16666666666666019037e-02, -1.38888888888741095749e-03, 2.48015872894767294178e-05
_C4, _C5, _C6 = -2.75573143513906633035e-07, 2.08757232129817482790e-09, -1.13596475577881948265e-11


def _kernel(x):
    """``(sin x, cos x)`` for float64 ``x`` of any shape, by reduction to ``[−π/4, π/4]``."""
    k = jnp.round(x * _TWO_OVER_PI)
    # r = x − k·π/2 as hi + lo: the three rounds of musl's __rem_pio2, all taken (musl skips the
    # later ones when no cancellation occurred; taking them costs a few FMAs and loses nothing).
    r = x - k * _PIO2[0][0]
    w = k * _PIO2[0][1]
    for part, tail in _PIO2[1:]:
        t = r
        w_part = k * part
        r = t - w_part
        w = k * tail - ((t - r) - w_part)
    hi = r - w
    lo = (r - hi) - w

    z = hi * hi
    zz = z * z
    s_poly = _S2 + z * (_S3 + z * _S4) + z * zz * (_S5 + z * _S6)
    v = z * hi
    sin_r = hi - ((z * (0.5 * lo - v * s_poly) - lo) - v * _S1)
    c_poly = z * (_C1 + z * (_C2 + z * _C3)) + zz * zz * (_C4 + z * (_C5 + z * _C6))
    half_z = 0.5 * z
    one_minus = 1.0 - half_z
    cos_r = one_minus + (((1.0 - one_minus) - half_z) + (z * c_poly - hi * lo))

    # Quadrant k mod 4, in floating point (k may exceed any integer type).
    quadrant = k - 4.0 * jnp.floor(0.25 * k)
    swap = (quadrant == 1.0) | (quadrant == 3.0)
    sin_x = jnp.where(swap, cos_r, sin_r)
    cos_x = jnp.where(swap, sin_r, cos_r)
    sin_x = jnp.where(quadrant >= 2.0, -sin_x, sin_x)
    cos_x = jnp.where((quadrant == 1.0) | (quadrant == 2.0), -cos_x, cos_x)
    # inf and NaN propagate as NaN, like libm.
    # sin(±0) = ±0 exactly, like libm.
    sin_x = jnp.where(x == 0, x, sin_x)
    bad = ~jnp.isfinite(x)
    return jnp.where(bad, jnp.nan, sin_x), jnp.where(bad, jnp.nan, cos_x)


@jax.custom_jvp
def sincos(x):
    """``(sin x, cos x)`` elementwise; float64 through the vectorisable kernel.

    Example:
        >>> import jax.numpy as jnp
        >>> from jaxrot._core._trig import sincos
        >>> s, c = sincos(jnp.array([0.0, 0.5]))
        >>> bool(jnp.allclose(s, jnp.sin(jnp.array([0.0, 0.5])))), c.shape
        (True, (2,))
    """
    if x.dtype == jnp.float64:
        return _kernel(x)
    return jnp.sin(x), jnp.cos(x)


@sincos.defjvp
def _sincos_jvp(primals, tangents):
    (x,), (dx,) = primals, tangents
    s, c = sincos(x)
    return (s, c), (c * dx, -s * dx)
