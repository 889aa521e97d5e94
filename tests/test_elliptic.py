"""Jacobi elliptic functions and elliptic integrals: against scipy, float32, gradients, jit + vmap."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import integrate, special

from jaxrot._free_body import _elliptic as ell


# Parameters the free top uses: m from 0 (symmetric limit) to 1 − 1e-9 (near the separatrix),
# arguments u = ν t + u0 up to ~60 for t <= 50.
M_GRID = np.concatenate(
    [[0.0, 1e-12, 1e-6, 0.1, 0.5, 0.9, 0.99, 1 - 1e-6, 1 - 1e-9], np.random.default_rng(0).uniform(0, 1, 20)]
)
U_GRID = np.concatenate([np.linspace(-60.0, 60.0, 121), [1e-3, 0.5, float(special.ellipk(0.5))]])


@pytest.fixture(scope="module")
def ellipj_grid():
    u, m = np.meshgrid(U_GRID, M_GRID)
    ours = [np.asarray(x) for x in jax.jit(ell.ellipj)(u, m)]
    return u, m, ours, special.ellipj(u, m)


def test_ellipj_matches_scipy_sn_cn_am(ellipj_grid):
    """Measured max |error|: 7e-15 (sn, cn, am) over |u| <= 60, the rounding of u itself."""
    _, _, ours, ref = ellipj_grid
    for name, a, b in zip(
        ("sn", "cn", "am"), (ours[0], ours[1], ours[3]), (ref[0], ref[1], ref[3]), strict=True
    ):
        assert np.max(np.abs(a - b)) < 1e-13, name


def test_ellipj_dn_matches_scipy_and_is_consistent(ellipj_grid):
    """dn = sqrt(cn² + (1 − m) sn²) here; scipy's Cephes uses cn / cos(φ₁ − φ₀).

    Measured: 3e-15 against sqrt(cn² + (1 − m) sn²) from scipy's own sn, cn, and
    6e-14 against scipy's dn (whose formula loses digits where cos(φ₁ − φ₀) is small).
    """
    _, m, ours, ref = ellipj_grid
    assert np.max(np.abs(ours[2] - ref[2])) < 1e-13
    from_scipy_sn_cn = np.sqrt(ref[1] ** 2 + (1 - m) * ref[0] ** 2)
    assert np.max(np.abs(ours[2] - from_scipy_sn_cn)) < 1e-14


def test_ellipj_at_m_one_and_outside_the_domain():
    u = np.linspace(-5.0, 5.0, 11)
    ours = ell.ellipj(u, 1.0)
    for a, b in zip(ours, special.ellipj(u, 1.0), strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-14, atol=1e-15)
    for m in (-0.1, 1.1):
        assert all(bool(jnp.all(jnp.isnan(x))) for x in ell.ellipj(u, m))


def test_ellipk_matches_scipy():
    """Measured max relative error 5e-16."""
    np.testing.assert_allclose(ell.ellipk(M_GRID), special.ellipk(M_GRID), rtol=1e-14)
    assert float(ell.ellipk(1.0)) == np.inf
    assert np.isnan(float(ell.ellipk(1.5)))


def test_carlson_rf_rj_match_scipy():
    """Measured max relative error 7e-16 (R_F) and 8e-15 (R_J), including x = 0 and tiny y."""
    rng = np.random.default_rng(1)
    x, y, z = rng.uniform(0.0, 3.0, size=(3, 400))
    x[:40] = 0.0
    y[40:80] = 10.0 ** rng.uniform(-12, -6, size=40)  # 1 − m sin²φ near the separatrix
    z[80:120] = 0.0  # a zero in any position
    p = rng.uniform(0.01, 10.0, size=400)
    np.testing.assert_allclose(ell.elliprf(x, y, z), special.elliprf(x, y, z), rtol=1e-13)
    np.testing.assert_allclose(ell.elliprj(x, y, z, p), special.elliprj(x, y, z, p), rtol=1e-13)
    assert float(ell.elliprf(0.0, 0.0, 1.0)) == np.inf
    assert np.isnan(float(ell.elliprf(-1.0, 1.0, 1.0)))
    assert np.isnan(float(ell.elliprj(1.0, 1.0, 1.0, -1.0)))


def test_incomplete_first_kind_matches_scipy_beyond_half_pi():
    """F(φ|m) = 2jK + F(φ − jπ): measured max error 4e-14 for |φ| <= 20 (F up to ~90)."""
    phi, m = np.meshgrid(np.linspace(-20.0, 20.0, 161), M_GRID)
    ref = special.ellipkinc(phi, m)
    err = np.abs(np.asarray(ell.ellipkinc(phi, m)) - ref)
    assert np.max(err / np.maximum(1.0, np.abs(ref))) < 1e-14
    assert np.max(err) < 1e-13


def _pi_reference(n, phi, m):
    """Π(n; φ|m) from scipy's Carlson integrals (DLMF 19.25.14), extended as in the module."""
    j = np.round(phi / np.pi)
    r = phi - j * np.pi
    s, c = np.sin(r), np.cos(r)
    y = c * c + (1 - m) * s * s
    reduced = s * special.elliprf(c * c, y, 1) + n / 3 * s**3 * special.elliprj(c * c, y, 1, 1 - n * s * s)
    complete = special.elliprf(0, 1 - m, 1) + n / 3 * special.elliprj(0, 1 - m, 1, 1 - n)
    return reduced + 2 * j * complete


def test_incomplete_third_kind():
    """Against scipy's R_F/R_J (measured 2e-15) and against quadrature of the integrand (2e-14)."""
    n, phi, m = np.meshgrid(
        [-5.0, -0.5, -1e-3, 0.0, 0.3],
        [-4.0, 0.3, 1.2, 1.5707963, 2.5, 7.0, 60.0],
        [0.0, 1e-12, 0.3, 0.9, 1 - 1e-9],
        indexing="ij",
    )
    ours = np.asarray(ell.ellippi(n, phi, m))
    ref = _pi_reference(n, phi, m)
    assert np.max(np.abs(ours - ref) / np.maximum(1.0, np.abs(ref))) < 1e-13

    for n_, phi_, m_ in [(-2.0, 1.1, 0.4), (-0.3, 5.0, 0.8), (0.5, -2.0, 0.2), (-1.0, 1.5, 0.0)]:
        quad, _ = integrate.quad(
            lambda t, n_=n_, m_=m_: 1 / ((1 - n_ * np.sin(t) ** 2) * np.sqrt(1 - m_ * np.sin(t) ** 2)),
            0.0,
            phi_,
            epsabs=1e-13,
            epsrel=1e-13,
            limit=200,
        )
        assert abs(float(ell.ellippi(n_, phi_, m_)) - quad) < 1e-13 * max(1.0, abs(quad))
    assert float(ell.ellippi(0.0, 1.0, 0.0)) == pytest.approx(1.0, abs=1e-15)
    assert np.isnan(float(ell.ellippi(1.5, 0.3, 0.5)))


def test_float32_in_float32_out():
    u = jnp.linspace(-10.0, 10.0, 41, dtype=jnp.float32)
    m = jnp.float32(0.7)
    outs = ell.ellipj(u, m)
    assert all(x.dtype == jnp.float32 for x in outs)
    ref = special.ellipj(np.asarray(u, np.float64), 0.7)
    for a, b in zip(outs, ref, strict=True):
        assert np.max(np.abs(np.asarray(a, np.float64) - b)) < 2e-6  # measured 6e-7 for |u| <= 10
    f32 = jnp.float32
    for value in (
        ell.ellipk(f32(0.3)),
        ell.elliprf(f32(1), f32(2), f32(3)),
        ell.elliprj(f32(1), f32(2), f32(3), f32(4)),
        ell.ellipkinc(f32(2.0), f32(0.5)),
        ell.ellippi(f32(-0.5), f32(2.0), f32(0.5)),
    ):
        assert value.dtype == jnp.float32 and bool(jnp.isfinite(value))
    np.testing.assert_allclose(ell.ellipkinc(f32(2.0), f32(0.5)), special.ellipkinc(2.0, 0.5), rtol=1e-6)


@pytest.mark.slow
def test_gradients_are_finite_and_correct_away_from_m_one():
    u = jnp.linspace(-5.0, 5.0, 11)
    # Derivatives of (sn, cn, dn, am) in u and m, one compiled Jacobian for every m.
    jac = jax.jit(jax.vmap(jax.jacfwd(lambda u, m: jnp.stack(ell.ellipj(u, m)), argnums=(0, 1)), (0, None)))
    for m in (0.0, 1e-12, 0.5, 1 - 1e-9):
        d_u, d_m = jac(u, m)
        assert bool(jnp.all(jnp.isfinite(d_u))) and bool(jnp.all(jnp.isfinite(d_m)))
    sn, cn, dn, _ = ell.ellipj(u, 0.3)
    d_u, d_m = jac(u, 0.3)
    np.testing.assert_allclose(d_u, jnp.stack([cn * dn, -sn * dn, -0.3 * sn * cn, dn], axis=-1), atol=1e-13)
    h = 1e-5
    fd = (jnp.stack(ell.ellipj(u, 0.3 + h)) - jnp.stack(ell.ellipj(u, 0.3 - h))) / (2 * h)
    np.testing.assert_allclose(d_m, fd.T, atol=1e-8)
    # Reverse mode agrees with forward mode.
    d_m_rev = jax.grad(lambda m: jnp.sum(jnp.stack(ell.ellipj(u, m))))(0.3)
    np.testing.assert_allclose(d_m_rev, jnp.sum(d_m), rtol=1e-12)

    # Integrals: dF/dφ = 1/Δ, dΠ/dφ = 1/((1 − n sin²φ) Δ), Δ = sqrt(1 − m sin²φ); d/dm and d/dn
    # by central differences; dK/dm = π/8 at m = 0; R_F finite at a zero argument.
    n, phi, m = -0.5, 2.3, 0.4
    delta = np.sqrt(1 - m * np.sin(phi) ** 2)
    g_f = jax.grad(ell.ellipkinc, argnums=(0, 1))(phi, m)
    g_pi = jax.grad(ell.ellippi, argnums=(0, 1, 2))(n, phi, m)
    np.testing.assert_allclose(g_f[0], 1 / delta, rtol=1e-13)
    np.testing.assert_allclose(g_pi[1], 1 / ((1 - n * np.sin(phi) ** 2) * delta), rtol=1e-13)
    fd_f = (ell.ellipkinc(phi, m + h) - ell.ellipkinc(phi, m - h)) / (2 * h)
    fd_pi_n = (ell.ellippi(n + h, phi, m) - ell.ellippi(n - h, phi, m)) / (2 * h)
    fd_pi_m = (ell.ellippi(n, phi, m + h) - ell.ellippi(n, phi, m - h)) / (2 * h)
    np.testing.assert_allclose([g_f[1], g_pi[0], g_pi[2]], [fd_f, fd_pi_n, fd_pi_m], rtol=1e-8)
    assert float(jax.grad(ell.ellipk)(0.0)) == pytest.approx(np.pi / 8, rel=1e-12)
    g_rf = jax.grad(ell.elliprf, argnums=(0, 1, 2))(0.0, 0.5, 1.0)
    assert all(bool(jnp.isfinite(g)) for g in g_rf)


def test_jit_and_vmap_agree_with_eager():
    u = jnp.linspace(-3.0, 3.0, 7)
    m = jnp.linspace(0.0, 0.95, 7)
    eager = ell.ellipj(u, m)
    batched = jax.jit(jax.vmap(ell.ellipj))(u, m)
    for a, b in zip(eager, batched, strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-15, atol=1e-15)
    pi_batched = jax.jit(jax.vmap(ell.ellippi, in_axes=(None, 0, 0)))(-0.5, u, m)
    np.testing.assert_allclose(pi_batched, ell.ellippi(-0.5, u, m), rtol=1e-15, atol=1e-15)
