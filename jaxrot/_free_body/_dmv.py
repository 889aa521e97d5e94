r"""One step of the preprocessed discrete Moser–Veselov map (DMV10) of a free rigid body.

The map, its modified moments and its round-off bookkeeping, for one body as tuples of scalar
components (`jaxrot._free_body._rotor` explains the method, its accuracy and its limits;
`jaxrot._free_body._rotor_loop` repeats the step). E. Hairer and G. Vilmart, J. Phys. A 39,
13225 (2006).
"""

import jax.numpy as jnp
from jax import lax

from .._core._fusion import stage


_SWEEPS = 2
_NEWTON = 2
# Largest rounding error allowed from the modified moments' cancellation: 100 ulp, or 1e-12 where
# that is more (float64: ~4500 ulp, which keeps needles of I₁/I₂ = 1e-3 valid to |ω| t ≈ 0.8).
_MAX_ROUNDING = 1e-12
_MAX_ROUNDING_ULP = 100


def _modification(moments, x, y):
    """``(S, D)`` of the modified moments ``1/Ĩ = S/I + D`` (Hairer & Vilmart's DMV10).

    ``x = h²|m|²/2``, ``y = h² E``. The coefficients are written with the power sums
    ``p_k = Σ I_j^k``, ``r_k = Σ I_j^-k``, ``Δ = I₁I₂I₃`` and ``x_ab = Σ_j (p_a − I_j^a) / I_j^b``.
    """
    i1, i2, i3 = moments
    v1, v2, v3 = 1 / i1, 1 / i2, 1 / i3
    p1 = i1 + i2 + i3
    p2 = i1 * i1 + i2 * i2 + i3 * i3
    p3 = i1**3 + i2**3 + i3**3
    p4 = i1**4 + i2**4 + i3**4
    r1 = v1 + v2 + v3
    r2 = v1 * v1 + v2 * v2 + v3 * v3
    r3 = v1**3 + v2**3 + v3**3
    r4 = v1**4 + v2**4 + v3**4
    det = i1 * i2 * i3
    det2 = det * det
    det3 = det2 * det
    det4 = det2 * det2
    x11 = p1 * r1 - 3
    x12 = p1 * r2 - r1
    x21 = p2 * r1 - p1
    x13 = p1 * r3 - r2
    x31 = p3 * r1 - p2
    x22 = p2 * r2 - 3
    # Row k: the coefficients of x^(k-j) y^j, j = 0..k, of the degree-k terms.
    s = [
        [p1 / (6 * det), -r1 / 3],
        [(p2 / det - r1) / (30 * det), (1 - x11) / (30 * det), (3 * p1 / det + 2 * r2) / 60],
        [
            (4 * det + 17 * p3 - 15 * det * x11) / (2520 * det3),
            (9 * p1 + 10 * det * r2 - 6 * x21) / (420 * det2),
            ((6 * x12 - 100 * r1) * det + 53 * p2) / (2520 * det2),
            (15 - det * r3 - 2 * x11) / (630 * det),
        ],
        [
            (62 * p4 - 94 * det * x21 + 66 * det2 * r2 + 81 * det * p1) / (45360 * det4),
            (-77 * x31 + 75 * det * x12 + 214 * p2 - 240 * det * r1) / (22680 * det3),
            (26 * det * x22 + 55 * p3 + 204 * det - 50 * det2 * r3 - 59 * det * x11) / (7560 * det3),
            (137 * det * r2 - det * x13 + 3 * p1 - 69 * x21) / (11340 * det2),
            (2 * det2 * r4 + 5 * det * x12 - 171 * det * r1 + 159 * p2) / (45360 * det2),
        ],
    ]
    d = [
        [-1 / (3 * det), p1 / (6 * det)],
        [-p1 / (60 * det2), r1 / (10 * det) - p2 / (60 * det2), -(9 + x11) / (60 * det)],
        [
            (34 * det * r1 - 19 * p2) / (2520 * det3),
            (p3 + 2 * det * x11 - 85 * det) / (1260 * det3),
            (47 * p1 + 13 * x21 - 38 * det * r2) / (2520 * det2),
            (9 * det * r1 + det * x12 - 11 * p2) / (1260 * det2),
        ],
        [
            (60 * x11 * det - 61 * p3 - 247 * det) / (45360 * det4),
            (54 * det * p1 - p4 + 218 * det * x21 - 426 * det2 * r2) / (45360 * det4),
            (125 * det * r1 - 5 * x31 - 130 * p2 + 4 * det * x12) / (7560 * det3),
            (67 * p3 - 735 * det - 15 * det * x22 + 87 * det * x11 + 34 * det2 * r3) / (22680 * det3),
            (165 * p1 - det * x13 - 9 * x21 - 145 * det * r2) / (45360 * det2),
        ],
    ]

    # One barrier for all 28 coefficients: without it XLA copies their expression trees into every
    # consumer, and the reverse-mode program (derivatives in the moments) took minutes to compile.
    flat = stage(*(c for row in s + d for c in row))
    monomials = [x ** (degree - j) * y**j for degree in range(1, 5) for j in range(degree + 1)]
    half = len(monomials)
    s_terms = [c * mono for c, mono in zip(flat[:half], monomials, strict=True)]
    d_terms = [c * mono for c, mono in zip(flat[half:], monomials, strict=True)]
    # Sums of the terms' sizes, for the rounding error: for a needle (I₁ ≪ I₂ ≈ I₃) the terms grow
    # like (h²|m|²/I₁³...)^k and cancel to O(1), and the sums lose all their digits. They only
    # decide validity, so they carry no derivative: differentiated, their 28 |term| derivatives
    # (zeros, but not to XLA) were fused into the reverse pass's largest loop and doubled its
    # cost (measured: gradient of the "splitting" heavy top, 1000 bodies, 2.3 s → 1.2 s).
    size_s = sum(jnp.abs(lax.stop_gradient(term)) for term in s_terms)
    size_d = sum(jnp.abs(lax.stop_gradient(term)) for term in d_terms)
    return 1 + sum(s_terms), sum(d_terms), size_s, size_d


def _unit_residual(q):
    """``|q|² − 1`` without rounding the sum at 1 (where the float grid is lopsided).

    The larger pair sum is >= ~1/2, so subtracting 1 from it and adding the other are exact
    (Sterbenz); only the squares and the pair sums round, at their own scale.
    """
    qw, qx, qy, qz = q
    a = qw * qw + qx * qx
    b = qy * qy + qz * qz
    return jnp.where(a >= b, (a - 1) + b, (b - 1) + a)


def _rotate(q, v):
    """``q ⊗ (0, v) ⊗ q*``, as in `jaxrot.quaternion.rotate`, component by component."""
    qw, qx, qy, qz = q
    vx, vy, vz = v
    tx = 2 * (qy * vz - qz * vy)
    ty = 2 * (qz * vx - qx * vz)
    tz = 2 * (qx * vy - qy * vx)
    return (
        vx + qw * tx + qy * tz - qz * ty,
        vy + qw * ty + qz * tx - qx * tz,
        vz + qw * tz + qx * ty - qy * tx,
    )


def _turn(q, residual, v, *, inverse=False):
    """``v`` turned by the rotation of ``q / |q|`` (its inverse if ``inverse``), ``|q|² = 1 + residual``.

    For ``|q|² = 1 + δ`` the formula of `_rotate` gives ``(1 + δ) R v − δ v``: removing that to first
    order (``δ`` is round-off) keeps the normalisation's rounding out of the result.
    """
    if inverse:
        q = (q[0], -q[1], -q[2], -q[3])
    r = _rotate(q, v)
    return tuple(ri + residual * (vi - ri) for ri, vi in zip(r, v, strict=True))


def _sweep(b, w, f, g2):
    """One Gauss–Seidel sweep of ``b_i = (1 + g²|b|²) w_i + f_i b_j b_k``."""
    b1, b2, b3 = b
    alpha = 1 + g2 * (b1 * b1 + b2 * b2 + b3 * b3)
    b1 = alpha * w[0] + f[0] * b2 * b3
    b2 = alpha * w[1] + f[1] * b1 * b3
    b3 = alpha * w[2] + f[2] * b1 * b2
    return b1, b2, b3


def _newton(b, w, f, g2):
    """One Newton step on ``F(b) = b − (1 + g²|b|²) w − f ⊙ (b₂b₃, b₁b₃, b₁b₂)``; 3×3 by cofactors."""
    b1, b2, b3 = b
    w1, w2, w3 = w
    f1, f2, f3 = f
    alpha = 1 + g2 * (b1 * b1 + b2 * b2 + b3 * b3)
    r1 = b1 - alpha * w1 - f1 * b2 * b3
    r2 = b2 - alpha * w2 - f2 * b1 * b3
    r3 = b3 - alpha * w3 - f3 * b1 * b2
    k1, k2, k3 = 2 * g2 * w1, 2 * g2 * w2, 2 * g2 * w3
    j11 = 1 - k1 * b1
    j12 = -k1 * b2 - f1 * b3
    j13 = -k1 * b3 - f1 * b2
    j21 = -k2 * b1 - f2 * b3
    j22 = 1 - k2 * b2
    j23 = -k2 * b3 - f2 * b1
    j31 = -k3 * b1 - f3 * b2
    j32 = -k3 * b2 - f3 * b1
    j33 = 1 - k3 * b3
    a11 = j22 * j33 - j23 * j32
    a12 = j13 * j32 - j12 * j33
    a13 = j12 * j23 - j13 * j22
    a21 = j23 * j31 - j21 * j33
    a22 = j11 * j33 - j13 * j31
    a23 = j13 * j21 - j11 * j23
    a31 = j21 * j32 - j22 * j31
    a32 = j12 * j31 - j11 * j32
    a33 = j11 * j22 - j12 * j21
    scale = 1 / (j11 * a11 + j12 * a21 + j13 * a31)
    return (
        b1 - scale * (a11 * r1 + a12 * r2 + a13 * r3),
        b2 - scale * (a21 * r1 + a22 * r2 + a23 * r3),
        b3 - scale * (a31 * r1 + a32 * r2 + a33 * r3),
    )


def _invariants(u, moments):
    """``(|L|², 2E) = (Σ (I_j u_j)², Σ I_j u_j²)`` of the body-frame angular velocity ``u``."""
    l1, l2, l3 = (i * ui for i, ui in zip(moments, u, strict=True))
    return l1 * l1 + l2 * l2 + l3 * l3, moments[0] * u[0] * u[0] + moments[1] * u[1] * u[1] + moments[2] * u[
        2
    ] * u[2]


def _round_off_correction(q, residual, omega, moments, targets):
    """The world ``Δω`` (a few ulp) that gives ``(q, ω + Δω)`` the invariants ``targets``.

    ``targets = (|L|², 2E)`` as measured from the input; measured the same way here, their
    rounding errors have the same statistics and cancel, so round-off does not accumulate a bias
    from call to call. ``Δω`` is the smallest change that does it: in the body frame
    ``Δu = x I u + y d`` with ``d = I²u − (S₃/S₂) I u`` (``S_k = Σ I_j^k u_j²``, ``d ⊥ I u``): the
    energy changes by ``2x S₂``, ``|L|²`` by ``2x S₃ + 2y |d|²``. ``y`` is capped at 8 ulp of ``|u|``: near
    steady rotation or for a sphere ``d`` vanishes and ``|L|`` follows the energy anyway.
    """
    eps = jnp.finfo(residual.dtype).eps
    u = _turn(q, residual, omega, inverse=True)
    a1, b1 = _invariants(u, moments)
    a0, b0 = targets
    iu = tuple(i * ui for i, ui in zip(moments, u, strict=True))
    s3 = moments[0] * iu[0] * iu[0] + moments[1] * iu[1] * iu[1] + moments[2] * iu[2] * iu[2]
    positive = a1 > 0
    inv_a1 = 1 / jnp.where(positive, a1, 1)
    x = jnp.where(positive, 0.5 * (b0 - b1) * inv_a1, 0)
    ratio = s3 * inv_a1
    d = tuple(i * v - ratio * v for i, v in zip(moments, iu, strict=True))
    var = d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
    nonzero = var > 0
    inv_var = 1 / jnp.where(nonzero, var, 1)
    # (a0 − a1) − 2x s3, not a0 − a1 (1 + …): a sum rounded at 1 biases y by a fraction of an ulp.
    y = 0.5 * ((a0 - a1) - 2 * x * s3) * inv_var
    cap = 8 * eps * jnp.sqrt((u[0] * u[0] + u[1] * u[1] + u[2] * u[2]) * inv_var)
    y = jnp.where(nonzero, jnp.clip(y, -cap, cap), 0)
    return _turn(q, residual, tuple(x * v + y * di for v, di in zip(iu, d, strict=True)))


def _dmv_step(q, m, p, fad, f, g, g2, h):
    """One DMV10 step of length ``h`` on the component tuples ``q`` (4) and ``m`` (3)."""
    fixed = lax.stop_gradient
    w = tuple(mi * pi for mi, pi in zip(m, p, strict=True))
    # Iterate on stop-gradient copies; the last Newton step, differentiated, then carries the
    # implicit-function derivative of the converged b (Newton's map is stationary there).
    w_fixed, f_fixed, g2_fixed = tuple(map(fixed, w)), tuple(map(fixed, f)), fixed(g2)
    b = w_fixed
    for _ in range(_SWEEPS):
        b = _sweep(b, w_fixed, f_fixed, g2_fixed)
    for _ in range(_NEWTON - 1):
        b = _newton(b, w_fixed, f_fixed, g2_fixed)
    b1, b2, b3 = stage(*_newton(tuple(map(fixed, b)), w, f, g2))
    c1, c2, c3 = g * b1, g * b2, g * b3
    kick = h / (1 + c1 * c1 + c2 * c2 + c3 * c3)
    qw, qx, qy, qz = q
    # q ⊗ (1, c), left unnormalised until the end (|q| grows by √(1 + |c|²) per step).
    q = (
        qw - qx * c1 - qy * c2 - qz * c3,
        qx + qw * c1 + qy * c3 - qz * c2,
        qy + qw * c2 + qz * c1 - qx * c3,
        qz + qw * c3 + qx * c2 - qy * c1,
    )
    m = (m[0] + kick * fad[0] * b2 * b3, m[1] + kick * fad[1] * b1 * b3, m[2] + kick * fad[2] * b1 * b2)
    return q, m
