r"""A fast free rotor: the torque-free rigid body by the preprocessed discrete Moser–Veselov method.

`free_rotor` has the contract of `jaxrot.analytic.free_motion` (the exact solution by elliptic
functions), at about 1.2× the cost of one torque-free `"zhao"` step in float64 (3× in float32)
instead of ~120× (N = 10⁴ bodies, 2 CPU cores, XLA's YNN fusions off, `benchmarks/rotor.py`), for
splitting schemes that call a rotor many times per step.

Method (Hairer & Vilmart 2006). One step of length ``h`` of the discrete Moser–Veselov (DMV)
algorithm, written with the body-frame angular momentum ``m`` and the quaternion, is
``q ← q ⊗ (1, c)/√(1 + |c|²)``, ``m ← m + (h / (1 + |c|²)) (Ĩ₂ − Ĩ₃, Ĩ₃ − Ĩ₁, Ĩ₁ − Ĩ₂) ⊙ (b₂b₃, b₁b₃, b₁b₂)``
with ``c = (h/2) b`` the solution of the implicit equations

    b_i = (1 + |c|²) m_i / Ĩ_i + (h/2) ((Ĩ_j − Ĩ_k) / Ĩ_i) b_j b_k      (i, j, k cyclic).

It maps ``m`` by the rotation ``(1, c)*``, so the world angular momentum ``q m q*`` is conserved
exactly, and it conserves ``|m|`` and ``Σ m_i² / Ĩ_i``. Hairer and Vilmart replace the moments by
the modified moments ``1/Ĩ_j = (1/I_j) S(x, y) + D(x, y)``, where ``S = 1 + …`` and ``D`` are
polynomials in ``x = h²|m|²/2`` and ``y = h² E`` (``E = Σ m_j²/(2 I_j)`` the kinetic energy) whose
coefficients are rational functions of ``I₁, I₂, I₃``; with the terms to degree 4 (their DMV10)
the step approximates the exact flow to order 10, in ``m`` and in the orientation. ``S`` and ``D``
depend on conserved quantities only, so ``Ĩ`` is fixed during a step, and since ``S ≠ 0`` the
exact energy ``E`` is conserved too.

Here the time ``t`` is covered by ``n = ⌈|ω| |t| / a⌉`` equal DMV10 steps, chosen per body
(`substeps_for`: ``a = 0.2`` rad in float64, 0.5 in float32, at least 2, at most 64): local
error ``O(a¹¹)`` per step, so round-off at any ``|ω| |t|`` up to 10 rad. The steps use the
scaling symmetry of the flow and of the DMV map (both functions of ``h m``): ``n`` steps of
``t/n`` with the momentum ``m`` are computed as ``n`` steps of ``t/2`` with ``(2/n) m``, so the
step length stays one scalar. The first two steps are a static loop; the rest a while loop
that a body in the common range never enters (under `jax.vmap`, one loop over the batch with a
scalar counter, by a batching rule of our own), whose derivative rule carries the steps'
Jacobian (JAX cannot reverse-differentiate a while loop). Traced for a GPU, the loop takes 4
steps per iteration and each body's count past the first two is rounded up to a multiple of 4
(`LOOP_BATCH`): there every iteration waits on a host read of its condition. Measured against `free_motion`
(largest orientation error in rad, or ω error relative to ``|ω|``; float64; bodies ``(1, 2,
3)``, ``(2, 2, 2)``, ``(1, 1, 1.9)``, ``(0.1, 1, 1.05)``)::

    |ω| |t|                    0.01    0.3     1       3       10
    (1, 2, 3)                  6e-16   8e-16   2e-14   6e-14   2e-13
    sphere (2, 2, 2)           2e-16   3e-16   1e-15   3e-15   1e-14
    (1, 1, 1.9)                3e-16   2e-16   3e-15   7e-15   2e-14
    flat (0.1, 1, 1.05)        1e-15   8e-16   5e-14   1e-13   4e-13

With a fixed count (``substeps=2``, the default before) the error was 7e-13 at 0.5, 1e-9 at
1, 3e-6 at 1.9 and NaN from 2. The choice costs 3-6% per call in the common range
(|ω| t = 0.3, N = 10⁴, 2 CPU cores, float64 and float32, the rotor and the ``"splitting"`` step,
median of 31 interleaved rounds: `benchmarks/rotor.py`, the closing note of issue 32 has the
table); with JAX's own batching of the while loop it cost 10-14%.

Limits, where the result is NaN rather than wrong: one DMV step may turn by at most 1 rad
(near π/2 the DMV equation has no solution any more: ``|ω| |t| > 64`` by default, ``> n`` with
a fixed ``substeps``), and the rounding error of the modified moments, whose polynomial's terms cancel
for a needle (``I₁ ≪ I₂ ≈ I₃``), estimated from the terms' sizes, must stay below 1e-12 or 100 ulp,
whichever is more (measured with ``n = 2``, float64: ``I = (1e-2, 1, 1)`` valid to ``|ω| t = 1.5``;
``(1e-3, 1, 1)`` exact to 1e-13 up to 0.3, 7e-13 at 0.5 and NaN from 0.7; ``(1e-4, 1, 1)`` NaN from
0.3, ``(1e-6, 1, 1)`` from 0.05; float32: ``(1e-3, 1, 1)`` NaN from 0.4). A stable form of the
modified moments for needles (the coefficients rewritten without the cancellation) would lift
this limit.

Round-off. ``q`` and ``ω`` are converted between frames with ``q`` normalised and its residual
``δ = |q|² − 1`` (computed without the rounding at 1) taken out to first order, so a conversion
has no bias from how ``q`` was normalised (measured: the usual normalise-then-rotate biases the
float32 energy by ~0.3 ulp per call, which over 10⁴ calls drifted ``|L|`` by 1e-3). The output
``ω`` is then corrected, by a few ulp, so that the invariants ``|L|`` and ``E`` measured from it
equal those measured from the input: what is left is an unbiased random walk (measured over 10⁴
calls of ``|ω| t = 0.05``, 64 bodies, with the principal-frame round trip of a splitting between
calls: float32 max 5e-5 in ``|L|``, 1e-4 in ``E``, against 1e-3 and 2e-3 for `free_motion`;
float64 1.6e-13 and 3e-13, against 3e-12 and 6e-12).

Derivatives are those of the DMV map: the Newton iterations run on stop-gradient copies and
only the last Newton step is differentiated, which gives the implicit-function derivative of
the converged solution; the round-off correction has no derivative. They are finite at
``ω = 0``, ``t = 0``, for symmetric bodies and the sphere (no branch anywhere), and agree with
central differences and with `free_motion`'s derivatives.

Reference:
    E. Hairer and G. Vilmart, "Preprocessed discrete Moser–Veselov algorithm for the full
    dynamics of a rigid body", J. Phys. A: Math. Gen. 39, 13225–13235 (2006),
    doi:10.1088/0305-4470/39/42/003.
"""

import functools
import math

import jax
import jax.numpy as jnp
from jax import lax

from .._fusion import stage, stage_stacked, tracing_for_cpu


__all__ = ["free_rotor", "free_rotor_momentum"]

# DMV10 steps per call. By default each body takes its own number, n = ceil(|ω| |t| / a) with the
# largest angle per DMV step a below, at least 2 and at most _MAX_SUBSTEPS. Two is the least: the
# common range |ω| t <= 0.3 (float64) then costs what a fixed two did; the first two steps are a
# static loop, the rest a while loop that such calls never enter.
_MIN_SUBSTEPS = 2
_MAX_SUBSTEPS = 64
# Largest angle of one DMV step chosen by the rule, per dtype: the local error grows like a¹¹, so
# 0.2 keeps float64 within ~1e-13 of the exact flow at any |ω| t (measured: 2 steps at 0.5 rad
# gave 7e-13, 3 at 0.6 gave 1e-13), and 0.5 keeps float32 ~100× below its resolution (1e-9 for
# two steps of 0.5 rad, in float64 arithmetic). Both leave |ω| t <= 0.3 on two steps.
_STEP_ANGLE = {8: 0.2, 4: 0.5}
# Largest angle |ω| |t| / n of one DMV step: near π/2 the DMV equation has no solution any more.
# Reached only past _MAX_SUBSTEPS steps (|ω| t > 64) or with a fixed `substeps`.
_MAX_ANGLE = 1.0
_SWEEPS = 2
_NEWTON = 2
# Largest rounding error allowed from the modified moments' cancellation: 100 ulp, or 1e-12 where
# that is more (float64: ~4500 ulp, which keeps needles of I₁/I₂ = 1e-3 valid to |ω| t ≈ 0.8).
_MAX_ROUNDING = 1e-12
_MAX_ROUNDING_ULP = 100
_SCAN = True
LOOP_BATCH = None
"""DMV steps per iteration of the rotor's while loop: ``None`` (default) is 1 when tracing for CPU
and `_GPU_LOOP_BATCH` otherwise; an int sets it. Private: benchmarks set it before anything is
traced, in a process of their own. On a GPU each while iteration is a few kernel launches and a
host read of the loop predicate, so with long flows (a race's few long steps) the rotor's cost is
that latency times the iterations, whatever the batch size; taking k steps per iteration divides
it by k. Each body's count beyond the first two steps is then rounded up to a multiple of k
(more, shorter DMV steps: never less accurate). On the CPU a body's extra steps cost compute, so
there it stays 1. Measured on an H200 (N = 1000, float64, dipole scene, `benchmarks/rotor_loop.py`,
docs/performance.md): 4 per iteration ran splitting, srkn6b and srkn14a 2.5×, 2.35×, 1.9× faster at
8 steps per run and cost at most 9% where a body needs one extra step and now takes four; 8 cost
20% there, 2 gained less (1.5-1.8× at 8 steps). On the CPU (N = 1000, 2 cores) 4 and 8 ranged
0.68-1.13×."""
_GPU_LOOP_BATCH = 4


def _loop_batch() -> int:
    if LOOP_BATCH is not None:
        return LOOP_BATCH
    return 1 if tracing_for_cpu() else _GPU_LOOP_BATCH


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


def _split(a):
    return tuple(a[..., k] for k in range(a.shape[-1]))


def _gather(group):
    """A state group of one body as an array: a tuple of scalar components stacked, an array as is."""
    return jnp.stack(group) if isinstance(group, tuple) else group


def _scatter(array, like):
    """`_gather` undone on the leading axis: back to components where ``like`` is a tuple."""
    return tuple(array[k] for k in range(len(like))) if isinstance(like, tuple) else array


def _repeat(step, n, state, params, *, first=0, batch=1, custom=True):
    """``step(params, state)`` applied ``first + n`` times to one body (``n`` a multiple of ``batch``).

    ``state`` is a tuple of groups, each a tuple of scalar components or an array; ``step`` sees
    each group as an array (components stacked). The ``first`` steps are a static loop, the ``n``
    more a while loop. One body: a loop on its own count. Under `jax.vmap` (a custom rule, not
    JAX's): one loop over the batch with a scalar counter up to the largest count, each body's state
    kept once its own count is done, and every group component-major (the batch axis last, so the
    components of a tuple group are contiguous rows). JAX's rule counted per body, reduced the
    batched predicate in every iteration and carried ``(N, 4)`` rows that XLA:CPU transposed on the
    way in and out: the loop cost ~8% of a rotor call where no body entered it (|ω| t = 0.3,
    N = 10⁴). ``custom=False`` keeps JAX's rule (the derivative rule's Jacobian loop, where ours
    made gradients 9-18% slower). Each iteration of the while loop applies ``step`` ``batch``
    times (`LOOP_BATCH`).
    """

    def iterate(step_once, s):
        if batch == 1:
            return step_once(s)
        for _ in range(batch):
            # Unbarriered, XLA fused the chain of steps and recomputed each step in every consumer
            # (measured on the CPU: 30x slower at 8 per iteration).
            s = lax.optimization_barrier(step_once(s))
        return s

    def loops(step_once, n, s, top, mask):
        if first:
            s = lax.fori_loop(0, first, lambda _, s: step_once(s), s)

        def body(c):
            i, s = c
            new = iterate(step_once, s)
            if mask:  # bodies past their own count keep their state (n broadcasts on the last axis)
                new = jax.tree_util.tree_map(lambda a, b: jnp.where(i < n, a, b), new, s)
            return i + batch, new

        return lax.while_loop(lambda c: c[0] < top, body, (jnp.zeros((), n.dtype), s))[1]

    def run(n, state, params):
        s = loops(lambda s: step(params, s), n, tuple(map(_gather, state)), n, mask=False)
        return tuple(map(_scatter, s, state))

    if not custom:
        return run(n, state, params)
    run = jax.custom_batching.custom_vmap(run)

    @run.def_vmap
    def run_batched(axis_size, in_batched, n, state, params):
        n_batched, state_batched, params_batched = in_batched
        state = jax.tree_util.tree_map(
            lambda x, b: x if b else jnp.broadcast_to(x, (axis_size, *jnp.shape(x))), state, state_batched
        )
        # Tuple groups stack their (N,) components to (k, N); arrays move the batch axis last.
        s = tuple(_gather(g) if isinstance(g, tuple) else jnp.moveaxis(g, 0, -1) for g in state)
        params_axes = jax.tree_util.tree_map(lambda b: 0 if b else None, params_batched)
        step_all = jax.vmap(step, in_axes=(params_axes, -1), out_axes=-1)
        top = jnp.max(n) if n_batched else n
        s = loops(lambda s: step_all(params, s), n, s, top, mask=n_batched)
        out = tuple(
            _scatter(x, g) if isinstance(g, tuple) else jnp.moveaxis(x, -1, 0)
            for x, g in zip(s, state, strict=True)
        )
        return out, jax.tree_util.tree_map(lambda _: True, out)

    return run(n, state, params)


def _per_body(fn, batch, *args):
    """``fn`` of one body, mapped over the leading axes ``batch`` of ``args`` (leaves broadcast to them)."""
    if not batch:
        return fn(*args)
    size = math.prod(batch)

    def flatten(x):
        x = jnp.asarray(x)
        core = x.shape[len(batch) :] if x.ndim >= len(batch) and x.shape[: len(batch)] == batch else x.shape
        return jnp.broadcast_to(x, batch + core).reshape((size, *core))

    out = jax.vmap(fn)(*jax.tree_util.tree_map(flatten, args))
    return jax.tree_util.tree_map(lambda y: y.reshape(batch + y.shape[1:]), out)


def _step_with(p, fad, h):
    """One DMV step ``(q, m) → (q, m)`` on 4- and 3-tuples of components, parameters ``p``, ``fad``, ``h``."""
    g = 0.5 * h
    f = tuple(g * fi * pi for fi, pi in zip(fad, p, strict=True))
    return lambda s: _dmv_step(s[0], s[1], p, fad, f, g, g * g, h)


def _stacked_step(p, fad, h):
    """`_step_with` on the arrays ``q`` ``(…, 4)`` and ``m`` ``(…, 3)``: the form loops carry."""
    step = _step_with(p, fad, h)

    def stacked(carry):
        q, m = step((_split(carry[0]), _split(carry[1])))
        return jnp.stack(q, axis=-1), jnp.stack(m, axis=-1)

    return stacked


def _first_steps(q, m, p, fad, h):
    """The first `_MIN_SUBSTEPS` DMV steps of one body (``q`` ``(4,)``, ``m`` ``(3,)``), a static loop."""
    step = _stacked_step(p, fad, h)
    return lax.fori_loop(0, _MIN_SUBSTEPS, lambda _, carry: step(carry), (q, m))


def _primal_step(params, s):
    return _stacked_step(*params)(s)


@jax.custom_jvp
def _dmv_steps(q, m, p, fad, h, n):
    """``n >= _MIN_SUBSTEPS`` DMV steps of one body: component tuples ``q`` (4) and ``m`` (3) → the same.

    The first `_MIN_SUBSTEPS` in a static loop, the rest in a while loop that a body in the common
    range never enters (`_repeat`). JAX cannot reverse-differentiate a while loop, so the derivative
    rule carries the extra steps' Jacobian as a value: the tangent is the static steps' derivative
    followed by a product with that Jacobian, which reverse mode can transpose.
    """
    return _repeat(
        _primal_step, n - _MIN_SUBSTEPS, (q, m), (p, fad, h), first=_MIN_SUBSTEPS, batch=_loop_batch()
    )


@_dmv_steps.defjvp
def _dmv_steps_jvp(primals, tangents):
    q, m, p, fad, h, n = primals
    dq, dm, dp, dfad, dh, _ = tangents
    s, ds = jax.jvp(
        _first_steps,
        (jnp.stack(q), jnp.stack(m), p, fad, h),
        (jnp.stack(dq), jnp.stack(dm), dp, dfad, dh),
    )
    state = jnp.concatenate(s)
    theta = jnp.stack((*p, *fad, h))
    z_tangent = jnp.concatenate([*ds, jnp.stack((*dp, *dfad, dh))])
    n_s, size = state.shape[0], state.shape[0] + theta.shape[0]

    def flat(z):
        step = _step_with(_split(z[n_s : n_s + 3]), _split(z[n_s + 3 : n_s + 6]), z[n_s + 6])
        q, m = step((_split(z[:4]), _split(z[4:n_s])))
        return jnp.stack(q + m)

    def with_value(z):
        value = flat(z)
        return value, value

    def step(theta, carry):
        state, jac = carry  # (7,) and its Jacobian in (state, θ) after the first steps, (7, 14)
        # ∂ step / ∂ (state, θ): (7, 14), and the step's value from the same trace (jacfwd's primal).
        d, state = jax.jacfwd(with_value, has_aux=True)(jnp.concatenate([state, theta]))
        jac = d[:, :n_s] @ jac + jnp.concatenate([jnp.zeros_like(d[:, :n_s]), d[:, n_s:]], axis=1)
        return state, jac

    state, jac = _repeat(
        step,
        n - _MIN_SUBSTEPS,
        (state, jnp.eye(n_s, size, dtype=state.dtype)),
        theta,
        batch=_loop_batch(),
        custom=False,
    )
    d_state = jac @ z_tangent
    return (_split(state[:4]), _split(state[4:])), (_split(d_state[:4]), _split(d_state[4:]))


def substeps_for(angle, dtype):
    """DMV10 steps the rotor takes for a flow of ``angle = |ω| |t|`` rad (per body) in ``dtype``."""
    per_step = _STEP_ANGLE[jnp.dtype(dtype).itemsize]
    n = jnp.ceil(angle / per_step)
    return jnp.clip(jnp.where(jnp.isfinite(n), n, _MAX_SUBSTEPS), _MIN_SUBSTEPS, _MAX_SUBSTEPS).astype(
        jnp.int32
    )


def _dmv_flow(q, m, inertia, inverse, targets, total_angle, t, substeps, dtype):
    """The DMV10 flow over ``t`` of one body's unit ``q`` (4 components, principal → world) and body
    momentum ``m`` (3): ``(q, m, valid, targets)``, ``q`` normalised, ``targets`` (``(|m|², 2E)``)
    behind the flow's first stage barrier; ``valid`` False where the result must be NaN."""
    if substeps is None:
        # n steps of t/n for the momentum m are 2 steps' worth of t/2 for the momentum (2/n) m, then
        # scaled back: the flow, and the DMV map (a function of h m), are invariant under h → h/k,
        # m → k m. So h stays a scalar and only m and its invariants are scaled, per body.
        count = substeps_for(total_angle, dtype)
        k = _loop_batch()
        if k > 1:  # the while loop's steps a multiple of the steps per iteration (never fewer)
            count = _MIN_SUBSTEPS + (count - _MIN_SUBSTEPS + k - 1) // k * k
        n_ref = _MIN_SUBSTEPS
        scale = n_ref / count.astype(dtype)
        m = tuple(mi * scale for mi in m)
        sizes = (targets[0] * scale * scale, targets[1] * scale * scale)
    else:
        count, n_ref, sizes = substeps, substeps, targets
    h = t / n_ref
    g = 0.5 * h
    g2 = g * g
    angle = total_angle / jnp.asarray(count).astype(dtype)  # of one DMV step
    # Stage boundaries (`jaxrot._fusion`): without them XLA recomputes the earlier stages inside
    # every later one (measured 8x slower), and in the derivative programs too.
    staged = stage(*q, *m, *targets, *sizes, angle)
    q, m, targets, sizes, angle = staged[:4], staged[4:7], staged[7:9], staged[9:11], staged[11]
    valid = angle <= _MAX_ANGLE

    scale_s, shift_d, size_s, size_d = _modification(
        inertia, (0.5 * h * h) * sizes[0], (0.5 * h * h) * sizes[1]
    )
    # One loop for the four sums (XLA:CPU otherwise recomputed them in each of six consumers).
    scale_s, shift_d, size_s, size_d = stage_stacked(scale_s, shift_d, size_s, size_d)
    p = tuple(scale_s * v + shift_d for v in inverse)  # modified inverse moments 1/Ĩ
    # The terms of S and D can be far larger than their sums: for a needle (I₁ ≪ I₂ ≈ I₃) they grow
    # like (h²|m|²/I₁²…)^k and cancel to O(1), so 1/Ĩ_j keeps only ~eps · cond of relative accuracy,
    # and the result ~eps · cond · angle. Beyond the bound the result is NaN, not noise.
    eps = float(jnp.finfo(dtype).eps)
    max_cond = max(_MAX_ROUNDING_ULP, _MAX_ROUNDING / eps)
    for pj, v in zip(p, inverse, strict=True):
        cond = (size_s * v + size_d) / jnp.abs(pj)
        valid = valid & (cond * angle <= max_cond)
    e1, e2, e3 = (1 / pi for pi in p)
    fad = (e2 - e3, e3 - e1, e1 - e2)
    f = tuple(g * fi * pi for fi, pi in zip(fad, p, strict=True))
    staged = stage(*p, *fad, *f)
    p, fad, f = staged[:3], staged[3:6], staged[6:]

    def substep(_, carry):
        q, m = _dmv_step(_split(carry[0]), _split(carry[1]), p, fad, f, g, g2, h)
        return jnp.stack(q, axis=-1), jnp.stack(m, axis=-1)

    # The loop carries q and m as (…, 4) and (…, 3) arrays: XLA:CPU then updates each in one loop,
    # where seven separate arrays took seven loops and seven copies per substep (measured: the
    # "splitting" step 10% faster, float64, N = 10⁴).
    if substeps is None:
        batch = jnp.broadcast_shapes(count.shape, jnp.shape(h))
        q, m = _per_body(_dmv_steps, batch, q, m, p, fad, h, count)
    else:
        carry = (jnp.stack(q, axis=-1), jnp.stack(m, axis=-1))
        if _SCAN:
            carry = lax.fori_loop(0, substeps, substep, carry)
        else:
            for i in range(substeps):
                carry = substep(i, carry)
        q, m = _split(carry[0]), _split(carry[1])
    if substeps is None:
        m = tuple(mi / scale for mi in m)

    norm = lax.rsqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return tuple(c * norm for c in q), m, valid, targets


# Jitted so that an eager call compiles once, not primitive by primitive (inlined under an outer jit).
@functools.partial(jax.jit, static_argnames="substeps")
def free_rotor(q_principal, omega, moments, t, *, substeps=None):
    """Torque-free motion of one body over a time ``t``, in its principal frame: DMV10, near-exact.

    The contract of `jaxrot.analytic.free_motion`, at a fraction of its cost (see the module
    docstring for the method, the measured error and the limits).

    Args:
        q_principal: ``(4,)`` unit quaternion, scalar first, principal frame → world
            (renormalised on the way in).
        omega: ``(3,)`` world-frame angular velocity (rad per unit time).
        moments: ``(3,)`` principal moments of inertia (mass × length²), ascending as
            `jaxrot.analytic.principal_axes` returns them (any order works here).
        t: scalar time elapsed, any sign (``t = 0`` returns the input, renormalised).
        substeps: DMV10 steps covering ``t`` (a Python int), or None (default): each body
            takes ``ceil(|ω| |t| / a)`` steps, at least 2 and at most 64, with ``a = 0.2`` rad
            in float64 and 0.5 in float32 (`substeps_for`; traced for a GPU, the steps past
            the first two rounded up to a multiple of 4, `LOOP_BATCH`). A fixed count is valid while
            ``|ω| |t| / substeps <= 1``; beyond, the result is NaN.

    Returns:
        ``(q_principal(t), omega(t))``, shapes ``(4,)`` and ``(3,)``, in the dtype of
        ``q_principal``. Leading axes of the arguments broadcast, as under `jax.vmap`.

    Example:
        >>> import jax.numpy as jnp
        >>> from jaxrot import quaternion as quat
        >>> from jaxrot._free_body._rotor import free_rotor
        >>> q0, w0 = jnp.array([1.0, 0.0, 0.0, 0.0]), jnp.array([0.3, 1.0, 0.2])
        >>> moments = jnp.array([1.0, 2.0, 3.0])
        >>> q1, w1 = free_rotor(q0, w0, moments, 0.4)  # exact: ω(0.4) = (0.221306, 1.017589, 0.180718)
        >>> print(q1.shape, w1.shape, ", ".join(f"{x:.6f}" for x in w1))
        (4,) (3,) 0.221306, 1.017589, 0.180718
        >>> energy = lambda q, w: jnp.sum(moments * quat.rotate(quat.conjugate(q), w) ** 2)
        >>> print(bool(jnp.abs(energy(q1, w1) / energy(q0, w0) - 1) < 1e-6))
        True
        >>> q2, w2 = free_rotor(q0, jnp.array([300.0, -230.0, 80.0]), jnp.ones(3), 0.03)  # 11.6 rad
        >>> print(bool(jnp.all(jnp.isfinite(q2))))
        True
    """
    dtype = jnp.asarray(q_principal).dtype
    if substeps is not None and (not isinstance(substeps, int) or substeps < 1):
        raise ValueError(f"`substeps` must be None or a Python int >= 1; got {substeps!r}.")
    q_principal = jnp.asarray(q_principal, dtype)
    omega = jnp.asarray(omega).astype(dtype)
    moments = jnp.asarray(moments).astype(dtype)
    t = jnp.asarray(t).astype(dtype)
    fixed = lax.stop_gradient

    inertia = tuple(moments[..., k] for k in range(3))
    inverse = tuple(1 / i for i in inertia)
    q = tuple(q_principal[..., k] for k in range(4))
    norm = lax.rsqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    q = tuple(c * norm for c in q)
    w_body = _turn(q, _unit_residual(q), tuple(omega[..., k] for k in range(3)), inverse=True)
    targets = _invariants(w_body, inertia)
    m = tuple(i * w for i, w in zip(inertia, w_body, strict=True))
    # |ω| from the world frame (a rotation keeps it): from w_body, XLA:CPU recomputed the rotation
    # in one more pass over the bodies, for the step count alone.
    w_world = tuple(omega[..., k] for k in range(3))
    total_angle = fixed(jnp.abs(t) * jnp.sqrt(w_world[0] ** 2 + w_world[1] ** 2 + w_world[2] ** 2))
    q, m, valid, targets = _dmv_flow(q, m, inertia, inverse, targets, total_angle, t, substeps, dtype)
    residual = _unit_residual(q)
    omega_t = _turn(q, residual, tuple(mi * vi for mi, vi in zip(m, inverse, strict=True)))
    staged = stage(*q, residual, *omega_t)
    q, residual, omega_t = staged[:4], staged[4], staged[5:]
    correction = _round_off_correction(q, residual, omega_t, inertia, targets)
    omega_t = tuple(o + fixed(c) for o, c in zip(omega_t, correction, strict=True))

    nan = jnp.asarray(jnp.nan, dtype)
    q_out = jnp.where(valid[..., None], jnp.stack(q, axis=-1), nan)
    omega_out = jnp.where(valid[..., None], jnp.stack(omega_t, axis=-1), nan)
    return q_out, omega_out


@functools.partial(jax.jit, static_argnames="substeps")
def free_rotor_momentum(q_principal, momentum, moments, t, *, substeps=None):
    """`free_rotor` on the principal-frame angular momentum ``m = I ω_p`` instead of the world ``ω``.

    No frame conversion: the flow of ``(q, m)`` itself, so a scheme that carries ``m`` between
    calls adds no conversion round-off to it (`free_rotor` turns ``ω`` into the body frame and back
    in each call, each a rounding of ``|ω|`` relative size: in float32 a random walk of the
    world angular momentum that tilts the precession axis). Round-off left: that of the DMV steps,
    whose momentum update is of size ``|ω| t |m|``, and of ``q``, which only rotates the whole
    state rigidly (a symmetry of the free motion: it does not grow).

    Args:
        q_principal: ``(4,)`` unit quaternion, principal frame → world (renormalised on the way in).
        momentum: ``(3,)`` angular momentum in the principal frame (``I ω_p``).
        moments, t, substeps: as for `free_rotor`.

    Returns:
        ``(q_principal(t), momentum(t))``, shapes ``(4,)`` and ``(3,)``; NaN where `free_rotor`'s
        would be.

    Example:
        >>> import jax.numpy as jnp
        >>> from jaxrot import quaternion as quat
        >>> from jaxrot._free_body._rotor import free_rotor, free_rotor_momentum
        >>> q0, w0 = jnp.array([1.0, 0, 0, 0]), jnp.array([0.3, 1.0, 0.2])  # q0 = 1: body = world
        >>> moments = jnp.array([1.0, 2.0, 3.0])
        >>> q1, m1 = free_rotor_momentum(q0, moments * w0, moments, 0.4)
        >>> q2, w2 = free_rotor(q0, w0, moments, 0.4)
        >>> w2_body = quat.rotate(quat.conjugate(q2), w2)
        >>> print(bool(jnp.allclose(q1, q2)), bool(jnp.allclose(m1 / moments, w2_body)))
        True True
    """
    dtype = jnp.asarray(q_principal).dtype
    if substeps is not None and (not isinstance(substeps, int) or substeps < 1):
        raise ValueError(f"`substeps` must be None or a Python int >= 1; got {substeps!r}.")
    moments = jnp.asarray(moments).astype(dtype)
    momentum = jnp.asarray(momentum).astype(dtype)
    t = jnp.asarray(t).astype(dtype)
    inertia = tuple(moments[..., k] for k in range(3))
    inverse = tuple(1 / i for i in inertia)
    q = tuple(jnp.asarray(q_principal, dtype)[..., k] for k in range(4))
    norm = lax.rsqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    q = tuple(c * norm for c in q)
    m = tuple(momentum[..., k] for k in range(3))
    w = tuple(mi * v for mi, v in zip(m, inverse, strict=True))
    targets = (m[0] * m[0] + m[1] * m[1] + m[2] * m[2], m[0] * w[0] + m[1] * w[1] + m[2] * w[2])
    total_angle = lax.stop_gradient(jnp.abs(t) * jnp.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]))
    q, m, valid, _ = _dmv_flow(q, m, inertia, inverse, targets, total_angle, t, substeps, dtype)
    nan = jnp.asarray(jnp.nan, dtype)
    return (
        jnp.where(valid[..., None], jnp.stack(q, axis=-1), nan),
        jnp.where(valid[..., None], jnp.stack(m, axis=-1), nan),
    )
