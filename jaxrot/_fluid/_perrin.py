"""Perrin's rotational frictions of a spheroid and Jeffery's shape (Bretherton) factor.

A spheroid with semi-axis ``a`` along its symmetry axis and ``b`` across it, turning in a fluid of
viscosity ``η`` at rest at infinity (stick boundary), feels the torque ``−ζ ω`` about each principal
axis (F. Perrin, J. Phys. Radium 5, 497 (1934); S. H. Koenig, Biopolymers 14, 2421 (1975)):

    ζ_∥ = (32π/3) η (a² − b²) b² / (2a − b² S),
    ζ_⊥ = (32π/3) η (a⁴ − b⁴) / ((2a² − b²) S − 2a),

with ``S = 2 atanh(ξ)/(a ξ)`` (prolate, ``ξ² = 1 − b²/a²``) or ``2 atan(ξ)/(a ξ)`` (oblate,
``ξ² = b²/a² − 1``). Both are 0/0 at the sphere; written with ``x = 1 − b²/a²`` and
``F(x) = Σ xⁿ/(2n + 1)`` (``S = 2F/a``) they become

    ζ_∥ = (16π/3) η a³ (1 − x) / G(x),   G(x) = (1 − (1 − x) F) / x = Σ 2xⁿ / ((2n + 1)(2n + 3)),
    ζ_⊥ = (16π/3) η a³ (2 − x) / H(x),   H(x) = ((1 + x) F − 1) / x = Σ 4(n + 1)xⁿ / ((2n + 1)(2n + 3)),

whose series are used near the sphere (``|x| < 0.05``) and give ``8πηa³`` there. The closed forms
agree with Jeffery's couple on a general ellipsoid (Proc. R. Soc. A 102, 161 (1922)) evaluated by
quadrature, and reach the thin disc's ``32ηb³/3`` about both axes (tests/test_fluid.py).
"""

import jax.numpy as jnp


_SERIES_BELOW = 0.05  # |x|: 12 terms of the series leave < 1e-17 of G and H there
_TERMS = 12


def _f(ratio_sq, x):
    """``F(x) = atanh(√x)/√x`` (prolate, x > 0), ``atan(√−x)/√−x`` (oblate, x < 0), ``x = 1 − r²``.

    The prolate branch is ``log((1 + √x)/r)/√x``: ``atanh`` of an argument near 1 would lose the
    digits of ``1 − √x`` for a long needle (5e-12 relative at λ = 1000). ``x`` away from 0 (the
    caller's branch)."""
    root = jnp.sqrt(jnp.abs(x))
    prolate = jnp.log((1 + root) / jnp.sqrt(ratio_sq))
    return jnp.where(x > 0, prolate, jnp.arctan(root)) / root


def _series(x, coefficient):
    total = jnp.zeros_like(x)
    for n in reversed(range(_TERMS)):
        total = total * x + coefficient(n)
    return total


def spheroid_friction(polar, equatorial, viscosity):
    """Rotational frictions ``(ζ_⊥, ζ_⊥, ζ_∥)`` ``(..., 3)`` of a spheroid, its symmetry axis body z.

    ``polar`` is the semi-axis along the symmetry axis, ``equatorial`` the one across it (any
    shapes that broadcast); units: viscosity × length³ (torque per angular velocity).

    Example:
        >>> import jax.numpy as jnp
        >>> from jaxrot._fluid._perrin import spheroid_friction
        >>> (spheroid_friction(1.0, 1.0, 1.0) / (8 * jnp.pi)).tolist()  # a sphere: 8πηa³
        [1.0, 1.0, 1.0]
    """
    polar, equatorial, viscosity = jnp.broadcast_arrays(
        *(jnp.asarray(v) for v in (polar, equatorial, viscosity))
    )
    ratio_sq = (equatorial / polar) ** 2  # r² = 1 − x, kept apart: 1 − x would round for a needle
    x = 1 - ratio_sq
    near = jnp.abs(x) < _SERIES_BELOW
    # Double where: no 0/0 in values or gradients at the sphere.
    far_ratio_sq, x_far = jnp.where(near, 0.25, ratio_sq), jnp.where(near, 0.75, x)
    x_near = jnp.where(near, x, 0.0)
    f = _f(far_ratio_sq, x_far)
    g_far = (1 - far_ratio_sq * f) / x_far
    h_far = ((1 + x_far) * f - 1) / x_far
    g = jnp.where(near, _series(x_near, lambda n: 2 / ((2 * n + 1) * (2 * n + 3))), g_far)
    h = jnp.where(near, _series(x_near, lambda n: 4 * (n + 1) / ((2 * n + 1) * (2 * n + 3))), h_far)
    scale = (16 * jnp.pi / 3) * viscosity * polar**3
    perpendicular = scale * (1 + ratio_sq) / h
    parallel = scale * ratio_sq / g
    return jnp.stack([perpendicular, perpendicular, parallel], axis=-1)


def bretherton_factor(polar, equatorial):
    """Jeffery's shape factor ``B = (λ² − 1)/(λ² + 1)``, ``λ = polar / equatorial`` (0 for a sphere)."""
    polar, equatorial = jnp.asarray(polar), jnp.asarray(equatorial)
    return (polar**2 - equatorial**2) / (polar**2 + equatorial**2)
