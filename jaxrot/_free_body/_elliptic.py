"""Jacobi elliptic functions and elliptic integrals in pure ``jax.numpy``.

The exact torque-free rigid body (`jaxrot.analytic`) needs ``sn, cn, dn, am``,
the complete and incomplete integrals of the first kind and the incomplete
integral of the third kind; ``jax.scipy.special`` has none of them. Everything
here is jit-able, vmap-able and differentiable, works in float32 and float64
(results keep the input dtype) and runs a **fixed** number of iterations, so
there is no Python control flow on traced values.

Convention: the *parameter* ``m = k²`` (scipy's convention), ``0 <= m <= 1``.

- `ellipj` (``sn, cn, dn, am``): arithmetic–geometric mean with the descending
  Landen transformation (Abramowitz & Stegun 16.4; the algorithm of Cephes'
  ``ellpj``), 16 steps, enough for every float64 ``m < 1`` down to
  ``1 − m ≈ 1e-300``. ``dn`` is taken as ``sqrt(cn² + (1 − m) sn²)``, which has
  no cancellation near ``m = 1`` and no 0/0 at ``u = K`` (Cephes' ``cn / cos(φ₁ −
  φ₀)`` has one there).
- `elliprf`, `elliprj`: Carlson's symmetric integrals by the duplication
  theorem (B. C. Carlson, "Numerical computation of real or complex elliptic
  integrals", Numer. Algorithms 10, 13–26 (1995); DLMF §19.36(i)), 16
  duplications and the fifth-order series. `elliprj` is for ``p > 0``.
- `ellipk` ``K(m) = R_F(0, 1 − m, 1)``; `ellipkinc` ``F(φ|m)`` and `ellippi`
  ``Π(n; φ|m)`` through R_F and R_J (DLMF 19.25.5, 19.25.14), extended beyond
  ``|φ| <= π/2`` by ``F(φ) = 2jK + F(φ − jπ)``, ``Π(n; φ) = 2jΠ(n) + Π(n; φ − jπ)``
  with ``j = round(φ/π)``.

Gradients are finite for ``0 <= m < 1``, the ``m``-derivative at ``m = 0``
included. At ``m = 1`` the values are the limits (``sn = tanh``,
``cn = dn = sech``, ``am = gd``; ``K = ∞``) but gradients are not promised.
The derivative of ``R_F``/``R_J`` with respect to an argument that is exactly 0
is infinite; there the finite part is returned (its ``√x`` term contributes 0).
Arguments outside the domain give NaN, as in scipy.

The internal functions take ``mc = 1 − m`` (``_ellipj`` takes ``m`` and ``mc``)
so that callers who know ``mc`` more accurately than ``1 − m`` (near the
separatrix of a free top) keep that accuracy.
"""

import jax
import jax.numpy as jnp
from jax import lax

from .._core._checks import float_dtype


__all__ = ["ellipj", "ellipk", "ellipkinc", "ellippi", "elliprf", "elliprj"]

# AGM steps: the ratio log(a/b) roughly halves per step while b << a, then
# convergence is quadratic; 1 − m = 1e-300 needs 14 steps.
AGM_STEPS = 16
# Carlson duplications: after N steps the series variables are 4^-N (A0 − x)/A_N,
# and the fifth-order series leaves an error ~ (that)^6. A_0/A_N grows like
# R_F², i.e. like log(1/(1 − m))² at worst; 16 steps keep the error below 1e-17
# for every float64 argument used here.
CARLSON_STEPS = 16


def _sqrt0(x):
    """sqrt with value 0 and gradient 0 (not NaN) at x <= 0."""
    pos = x > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, x, 1)), 0)


def _common(*xs):
    dtype = float_dtype(*xs)
    return jnp.broadcast_arrays(*(jnp.asarray(x).astype(dtype) for x in xs))


# --------------------------------------------------------------------------- Jacobi


def _ellipj(u, m, mc):
    """sn, cn, dn, am for ``0 <= m < 1``; ``m`` and ``mc = 1 − m`` both given, ``mc > 0``.

    Descending Landen: ``a₀ = 1``, ``b₀ = √mc``, ``c_{i+1} = c_i² / (4 a_{i+1})`` (the
    stable form of ``(a_i − b_i)/2``, with ``c₀² = m``), ``φ_N = 2^N a_N u``,
    ``φ_{i−1} = (φ_i + asin(c_i sin φ_i / a_i)) / 2``; ``am u = φ₀``. Extra steps after
    convergence have ``c_i = 0`` and only multiply, then divide, by 2 (exact).
    """

    def forward(carry, _):
        a, b, c_sq = carry
        a_next = 0.5 * (a + b)
        c_next = c_sq / (4 * a_next)
        return (a_next, jnp.sqrt(a * b), c_next * c_next), (a_next, c_next)

    (a_n, _, _), (a_seq, c_seq) = lax.scan(
        forward, (jnp.ones_like(u), jnp.sqrt(mc), m), None, length=AGM_STEPS
    )

    def backward(phi, ac):
        a, c = ac
        return 0.5 * (phi + jnp.arcsin(c * jnp.sin(phi) / a)), None

    ph, _ = lax.scan(backward, float(2**AGM_STEPS) * a_n * u, (a_seq, c_seq), reverse=True)
    sn = jnp.sin(ph)
    cn = jnp.cos(ph)
    dn = jnp.sqrt(cn * cn + mc * sn * sn)
    return sn, cn, dn, ph


@jax.jit
def ellipj(u, m):
    """Jacobi elliptic functions ``(sn, cn, dn, ph)`` of ``u`` with parameter ``m = k²``.

    ``ph = am(u|m)`` is the amplitude, continuous and increasing in ``u``
    (``sn = sin ph``, ``cn = cos ph``). Same convention and outputs as
    ``scipy.special.ellipj``; ``u`` and ``m`` broadcast; NaN for ``m`` outside
    ``[0, 1]``.

    Example:
        >>> from jaxrot._free_body._elliptic import ellipj
        >>> sn, cn, dn, ph = ellipj(0.5, 0.3)
        >>> print(round(float(sn), 6), round(float(dn), 6))
        0.474216 0.965679
    """
    u, m = _common(u, m)
    mc = 1 - m
    inside = (m >= 0) & (m < 1)
    sn, cn, dn, ph = _ellipj(u, jnp.where(inside, m, 0.5), jnp.where(inside, mc, 0.5))
    # m = 1: sn = tanh, cn = dn = sech, am = gd.
    at_one = m == 1
    u1 = jnp.where(at_one, u, 0)
    e = jnp.exp(-jnp.abs(u1))
    sech = 2 * e / (1 + e * e)
    sn = jnp.where(at_one, jnp.tanh(u1), sn)
    cn = jnp.where(at_one, sech, cn)
    dn = jnp.where(at_one, sech, dn)
    ph = jnp.where(at_one, 2 * jnp.arctan(jnp.tanh(0.5 * u1)), ph)
    bad = ~((m >= 0) & (m <= 1))
    return tuple(jnp.where(bad, jnp.nan, x) for x in (sn, cn, dn, ph))


# --------------------------------------------------------------------------- Carlson


def _series_rf(dx, dy):
    dz = -(dx + dy)
    e2 = dx * dy - dz * dz
    e3 = dx * dy * dz
    return 1 - e2 / 10 + e3 / 14 + e2 * e2 / 24 - 3 * e2 * e3 / 44


def _series_rj(dx, dy, dz):
    dp = -0.5 * (dx + dy + dz)
    xyz = dx * dy * dz
    e2 = dx * dy + dx * dz + dy * dz - 3 * dp * dp
    e3 = xyz + 2 * e2 * dp + 4 * dp * dp * dp
    e4 = (2 * xyz + e2 * dp + 3 * dp * dp * dp) * dp
    e5 = xyz * dp * dp
    return 1 - 3 * e2 / 14 + e3 / 6 + 9 * e2 * e2 / 88 - 3 * e4 / 22 - 9 * e2 * e3 / 52 + 3 * e5 / 26


def _rc_one(e):
    """R_C(1, 1 + e) for e > -1: atan(√e)/√e, atanh(√−e)/√−e, or its series near 0."""
    small = jnp.abs(e) < 1e-3
    e_safe = jnp.where(small, 1, e)
    r = jnp.sqrt(jnp.abs(e_safe))
    closed = jnp.where(e_safe > 0, jnp.arctan(r), jnp.arctanh(jnp.minimum(r, 1))) / r
    series = 1 + e * (-1 / 3 + e * (1 / 5 + e * (-1 / 7 + e * (1 / 9 + e * (-1 / 11 + e / 13)))))
    return jnp.where(small, series, closed)


def _rf_rj(x, y, z, p):
    """Carlson's ``(R_F(x, y, z), R_J(x, y, z, p))`` from one duplication loop.

    ``x >= 0``, ``y, z, p > 0`` (sort the arguments so that a zero comes first:
    R_F and R_J are symmetric in ``x, y, z``). The duplication of
    ``(x, y, z)`` is the same for both integrals (Carlson 1995, DLMF 19.36.1 and
    19.36.9): ``λ = √x√y + √x√z + √y√z``, each argument ``← (· + λ)/4``; R_J adds
    ``6 Σ 4^-k R_C(1, 1 + e_k) / d_k`` with ``d_k = (√p+√x)(√p+√y)(√p+√z)`` and
    ``e_k = 4^-3k δ / d_k²``, ``δ = (p−x)(p−y)(p−z)``.
    """
    a0 = (x + y + z) / 3
    a0_j = (x + y + z + 2 * p) / 5
    delta = (p - x) * (p - y) * (p - z)

    def body(_, carry):
        x, y, z, p, a, a_j, total, fac = carry
        sx, sy, sz, sp = _sqrt0(x), jnp.sqrt(y), jnp.sqrt(z), jnp.sqrt(p)
        lam = sx * sy + sx * sz + sy * sz
        d = (sp + sx) * (sp + sy) * (sp + sz)
        total = total + fac * _rc_one(fac * fac * fac * delta / (d * d)) / d
        return (
            0.25 * (x + lam),
            0.25 * (y + lam),
            0.25 * (z + lam),
            0.25 * (p + lam),
            0.25 * (a + lam),
            0.25 * (a_j + lam),
            total,
            0.25 * fac,
        )

    init = (x, y, z, p, a0, a0_j, jnp.zeros_like(a0), jnp.ones_like(a0))
    *_, a_n, a_j, total, _ = lax.fori_loop(0, CARLSON_STEPS, body, init)
    four_n = float(4**CARLSON_STEPS)
    rf = _series_rf((a0 - x) / (four_n * a_n), (a0 - y) / (four_n * a_n)) / jnp.sqrt(a_n)
    scale = four_n * a_j
    rj = _series_rj((a0_j - x) / scale, (a0_j - y) / scale, (a0_j - z) / scale) / (scale * jnp.sqrt(a_j))
    return rf, rj + 6 * total


def _rf(x, y, z):
    """Carlson's R_F(x, y, z) for ``x >= 0``, ``y, z > 0``."""
    a0 = (x + y + z) / 3

    def body(_, carry):
        x, y, z, a = carry
        sx, sy, sz = _sqrt0(x), jnp.sqrt(y), jnp.sqrt(z)
        lam = sx * sy + sx * sz + sy * sz
        return 0.25 * (x + lam), 0.25 * (y + lam), 0.25 * (z + lam), 0.25 * (a + lam)

    _, _, _, a_n = lax.fori_loop(0, CARLSON_STEPS, body, (x, y, z, a0))
    scale = float(4**CARLSON_STEPS) * a_n
    return _series_rf((a0 - x) / scale, (a0 - y) / scale) / jnp.sqrt(a_n)


def _rj(x, y, z, p):
    """Carlson's R_J(x, y, z, p) for ``x >= 0``, ``y, z, p > 0``."""
    return _rf_rj(x, y, z, p)[1]


@jax.jit
def elliprf(x, y, z):
    """Carlson's symmetric integral ``R_F(x, y, z)``, as ``scipy.special.elliprf`` (real arguments).

    ``R_F = ½ ∫₀^∞ dt / √((t+x)(t+y)(t+z))``; NaN for a negative argument,
    ``inf`` when two arguments are zero.
    """
    x, y, z = _common(x, y, z)
    zeros = (x == 0).astype(jnp.int32) + (y == 0).astype(jnp.int32) + (z == 0).astype(jnp.int32)
    lo, mid, hi = jnp.sort(jnp.stack([x, y, z]), axis=0)  # R_F is symmetric; a zero goes first
    ok = (mid > 0) & (lo >= 0)
    out = _rf(jnp.where(ok, lo, 0), jnp.where(ok, mid, 1), jnp.where(ok, hi, 1))
    out = jnp.where(zeros >= 2, jnp.inf, out)
    return jnp.where((x < 0) | (y < 0) | (z < 0), jnp.nan, out)


@jax.jit
def elliprj(x, y, z, p):
    """Carlson's symmetric integral ``R_J(x, y, z, p)`` for ``p > 0``, as ``scipy.special.elliprj``.

    ``R_J = (3/2) ∫₀^∞ dt / ((t+p) √((t+x)(t+y)(t+z)))``. NaN for a negative
    ``x, y, z`` or ``p <= 0`` (the Cauchy principal value for ``p < 0`` is not
    implemented); ``inf`` when two of ``x, y, z`` are zero.
    """
    x, y, z, p = _common(x, y, z, p)
    zeros = (x == 0).astype(jnp.int32) + (y == 0).astype(jnp.int32) + (z == 0).astype(jnp.int32)
    lo, mid, hi = jnp.sort(jnp.stack([x, y, z]), axis=0)  # R_J is symmetric in x, y, z
    ok = (mid > 0) & (lo >= 0) & (p > 0)
    out = _rj(jnp.where(ok, lo, 0), jnp.where(ok, mid, 1), jnp.where(ok, hi, 1), jnp.where(ok, p, 1))
    out = jnp.where(zeros >= 2, jnp.inf, out)
    return jnp.where((x < 0) | (y < 0) | (z < 0) | ~(p > 0), jnp.nan, out)


# --------------------------------------------------------------------------- Legendre


def _ellipk(mc):
    return _rf(jnp.zeros_like(mc), mc, jnp.ones_like(mc))


def _reduce(phi):
    """``j = round(φ/π)`` and ``φ − jπ`` in ``[−π/2, π/2]``."""
    j = jnp.round(phi / jnp.pi)
    return j, phi - j * jnp.pi


def _carlson_args(phi, mc):
    """``(sin φ, cos²φ, 1 − m sin²φ)``, the last without cancellation near m = 1."""
    s = jnp.sin(phi)
    c = jnp.cos(phi)
    x = c * c
    return s, x, x + mc * s * s


def _ellipf(phi, mc):
    """F(φ|m) for any real φ (``mc = 1 − m > 0``)."""
    j, r = _reduce(phi)
    s, x, y = _carlson_args(r, mc)
    one = jnp.ones_like(x)
    zero = jnp.zeros_like(x)
    rf = _rf(jnp.stack([x, zero]), jnp.stack([y, mc]), jnp.stack([one, one]))
    return s * rf[0] + 2 * j * rf[1]


def _ellippi_parts(n, phi, mc):
    """``(F(φ|m), Π(n; φ|m), K(m), Π(n|m))`` for ``|φ| <= π/2``, ``n < 1``, from one Carlson loop."""
    s, x, y = _carlson_args(phi, mc)
    s2 = s * s
    one = jnp.ones_like(x)
    zero = jnp.zeros_like(x)
    rf, rj = _rf_rj(
        jnp.stack([x, zero]), jnp.stack([y, mc]), jnp.stack([one, one]), jnp.stack([1 - n * s2, 1 - n])
    )
    f = s * rf[0]
    return f, f + (n / 3) * s * s2 * rj[0], rf[1], rf[1] + (n / 3) * rj[1]


def _ellippi(n, phi, mc):
    """Π(n; φ|m) for any real φ, ``n < 1``, ``mc > 0``."""
    j, r = _reduce(phi)
    _, pi_r, _, pi_complete = _ellippi_parts(n, r, mc)
    return pi_r + 2 * j * pi_complete


def _amplitude_and_pi(n, s0, c0, du, m, mc):
    """Jacobi functions at ``u = F(φ₀|m) + du`` and ``Π(n; am u|m) − Π(n; φ₀|m)``.

    ``φ₀`` in ``[−π/2, π/2]`` is given by ``s0 = sin φ₀`` and ``c0 = cos φ₀ >= 0``, not
    by its value: near ``φ₀ = ±π/2`` (a state close to the unstable intermediate axis,
    ``m`` close to 1) the small ``c0`` keeps its relative precision, which ``π/2 − φ₀``
    would not, and ``F(φ₀|m)`` depends on it strongly there. For ``n <= 0``,
    ``0 <= m < 1`` (both ``m`` and ``mc`` given). Returns ``(sn, cn, dn, am, ΔΠ)``; one
    R_F and one fused R_F/R_J loop, the elliptic part of one torque-free-top evaluation.
    """
    x0 = c0 * c0
    y0 = x0 + mc * s0 * s0
    one = jnp.ones_like(x0)
    zero = jnp.zeros_like(x0)
    u0 = s0 * _rf(x0, y0, one)
    sn, cn, dn, am = _ellipj(u0 + du, m, mc)
    j, r = _reduce(am)
    s1, x1, y1 = _carlson_args(r, mc)
    rf, rj = _rf_rj(
        jnp.stack([x0, x1, zero]),
        jnp.stack([y0, y1, mc]),
        jnp.stack([one, one, one]),
        jnp.stack([1 - n * s0 * s0, 1 - n * s1 * s1, 1 - n]),
    )
    third = n / 3
    pi0 = u0 + third * s0 * s0 * s0 * rj[0]
    pi1 = s1 * rf[1] + third * s1 * s1 * s1 * rj[1]
    pi_complete = rf[2] + third * rj[2]
    return sn, cn, dn, am, pi1 + 2 * j * pi_complete - pi0


@jax.jit
def ellipk(m):
    """Complete elliptic integral of the first kind ``K(m)``, as ``scipy.special.ellipk``.

    ``K(m) = R_F(0, 1 − m, 1)``; ``inf`` at ``m = 1``, NaN for ``m > 1``.

    Example:
        >>> from jaxrot._free_body._elliptic import ellipk
        >>> print(round(float(ellipk(0.5)), 10))
        1.8540746773
    """
    (m,) = _common(m)
    mc = 1 - m
    ok = mc > 0
    out = _ellipk(jnp.where(ok, mc, 1))
    return jnp.where(ok, out, jnp.where(mc == 0, jnp.inf, jnp.nan))


@jax.jit
def ellipkinc(phi, m):
    """Incomplete integral of the first kind ``F(φ|m) = ∫₀^φ dθ / √(1 − m sin²θ)``.

    Same convention as ``scipy.special.ellipkinc``; any real ``φ`` (quasi-periodic
    extension), ``0 <= m < 1`` (NaN outside ``[0, 1]``; at ``m = 1`` only
    ``|φ| < π/2`` is finite).
    """
    phi, m = _common(phi, m)
    mc = 1 - m
    inside = (m >= 0) & (mc > 0)
    out = _ellipf(phi, jnp.where(inside, mc, 0.5))
    # m = 1: F = atanh(sin φ) for |φ| < π/2, infinite beyond.
    at_one = mc == 0
    s1 = jnp.where(at_one, jnp.sin(phi), 0)
    one_val = jnp.where(jnp.abs(phi) < 0.5 * jnp.pi, jnp.arctanh(s1), jnp.sign(phi) * jnp.inf)
    out = jnp.where(at_one, one_val, out)
    return jnp.where((m >= 0) & (mc >= 0), out, jnp.nan)


@jax.jit
def ellippi(n, phi, m):
    """Incomplete integral of the third kind ``Π(n; φ|m) = ∫₀^φ dθ / ((1 − n sin²θ) √(1 − m sin²θ))``.

    Through Carlson's integrals: for ``|φ| <= π/2``,
    ``Π = s R_F(c², 1 − m s², 1) + (n/3) s³ R_J(c², 1 − m s², 1, 1 − n s²)``
    (``s = sin φ``, ``c = cos φ``), extended to any real ``φ`` with the complete
    integral. Valid for ``n < 1`` and ``0 <= m < 1`` (the free top uses ``n < 0``);
    NaN outside.

    Example:
        >>> from jaxrot._free_body._elliptic import ellippi
        >>> print(round(float(ellippi(0.0, 1.0, 0.0)), 12))  # Π(0; φ|0) = φ
        1.0
    """
    n, phi, m = _common(n, phi, m)
    mc = 1 - m
    ok = (m >= 0) & (mc > 0) & (n < 1)
    out = _ellippi(jnp.where(ok, n, 0), phi, jnp.where(ok, mc, 0.5))
    return jnp.where(ok, out, jnp.nan)
