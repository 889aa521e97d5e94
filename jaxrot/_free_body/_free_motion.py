"""Exact torque-free motion of one body in its principal frame: the core of `jaxrot.analytic`.

`free_motion` advances one body by a time ``t`` exactly (Euler–Poinsot): the
short-flight Taylor series, the symmetric top in closed form, the asymmetric top
with Jacobi elliptic functions and the incomplete elliptic integral of the third
kind (`jaxrot._free_body._elliptic`), and the linearised motions that give true derivatives
where the closed forms' are not (`jaxrot._free_body._linearised`). The cases, their formulas and
the derivatives are described in `jaxrot.analytic`, which re-exports `free_motion` and runs it for
many bodies and times (`jaxrot.analytic.free_top`); the splitting schemes call it once per step.

References:
    L. D. Landau and E. M. Lifshitz, *Mechanics*, 3rd ed., §§33, 35–37.
    E. Celledoni, F. Fassò, N. Säfström and A. Zanna, "The exact computation of
    the free rigid body motion and its use in splitting methods", SIAM J. Sci.
    Comput. 30(4), 2084–2112 (2008), doi:10.1137/070704393.
"""

import jax.numpy as jnp
from jax import lax

from .. import quaternion as quat
from . import _elliptic as ell
from ._linearised import _near_steady, _symmetry_breaking


def _qz(angle):
    half = 0.5 * angle
    zero = jnp.zeros_like(half)
    return jnp.stack([jnp.cos(half), zero, zero, jnp.sin(half)])


def _qx(angle):
    half = 0.5 * angle
    zero = jnp.zeros_like(half)
    return jnp.stack([jnp.cos(half), jnp.sin(half), zero, zero])


def _tilt(l_body, psi_estimate):
    """Quaternion of ``R_x(θ) R_z(ψ)``, which turns the body vector ``l_body`` onto ``+e_z``.

    ``ψ = atan2(L₁, L₂)`` is unwrapped to the branch within ``π`` of
    ``psi_estimate``, so the quaternion is continuous in time (no ``q → −q``
    jumps when ``L`` crosses the branch cut).
    """
    l1, l2, l3 = l_body[0], l_body[1], l_body[2]
    theta = jnp.arctan2(jnp.sqrt(l1 * l1 + l2 * l2), l3)
    psi = jnp.arctan2(l1, l2)
    psi = psi + (2 * jnp.pi) * jnp.round((psi_estimate - psi) / (2 * jnp.pi))
    return quat.multiply(_qx(theta), _qz(psi))


def _asymmetric(q_frame, v, moments, t):
    """Case-A motion of an asymmetric body in a frame where L circulates about axis 3.

    ``moments`` ``(J₁, J₂, J₃)`` with ``J₂`` strictly between ``J₁`` and ``J₃``
    (ascending for case A, descending for case B), ``v`` the body angular
    velocity in that frame with ``L² − 2E J₂`` of the sign of ``J₃ − J₂`` or zero
    (the separatrix). Returns the frame orientation and the world angular
    velocity at time ``t``.
    """
    j1, j2, j3 = moments[0], moments[1], moments[2]
    v1, v2, v3 = v[0], v[1], v[2]
    l_body0 = moments * v
    l_norm = jnp.sqrt(jnp.sum(l_body0 * l_body0))
    # 2E J3 − L², L² − 2E J1 and L² − 2E J2 as sums without cancellation.
    d3 = j1 * (j3 - j1) * v1 * v1 + j2 * (j3 - j2) * v2 * v2
    d1 = j2 * (j2 - j1) * v2 * v2 + j3 * (j3 - j1) * v3 * v3
    s2 = j3 * (j3 - j2) * v3 * v3 - j1 * (j2 - j1) * v1 * v1
    amp_a = jnp.sqrt(d3 / (j1 * (j3 - j1)))
    amp_b = jnp.sqrt(d3 / (j2 * (j3 - j2)))
    amp_c = jnp.sqrt(d1 / (j3 * (j3 - j1)))
    nu = jnp.sqrt((j3 - j2) * d1 / (j1 * j2 * j3))
    n = -j3 * (j2 - j1) / (j1 * (j3 - j2))
    one = jnp.ones_like(v1)
    sig1 = jnp.where(v1 >= 0, one, -one)
    sig3 = jnp.where(v3 >= 0, one, -one)
    sig2 = jnp.where(j3 > j2, one, -one) * sig1 * sig3

    # Elliptic case, m < 1 (with a stand-in m on the separatrix).
    m = (j2 - j1) * d3 / ((j3 - j2) * d1)
    mc = (j3 - j1) * s2 / ((j3 - j2) * d1)
    separatrix = mc == 0
    mc = jnp.where(separatrix, 0.5, mc)
    # Keep whichever of m, 1 − m is small to full relative precision.
    use_m = m <= 0.5
    m, mc = jnp.where(use_m, m, 1 - mc), jnp.where(use_m, 1 - m, mc)
    # (cn u0, sn u0) = (σ1 v1 / A, σ2 v2 / B): am u0 in [−π/2, π/2], passed as (sin, cos).
    cos0 = sig1 * v1 * jnp.sqrt(jnp.abs(j1 * (j3 - j1)))
    sin0 = sig2 * v2 * jnp.sqrt(jnp.abs(j2 * (j3 - j2)))
    norm0 = jnp.sqrt(cos0 * cos0 + sin0 * sin0)  # = sqrt(|d3|) up to round-off
    cos0, sin0 = cos0 / norm0, sin0 / norm0
    phi0 = jnp.arctan2(sin0, cos0)
    sn, cn, dn, am, d_pi = ell._amplitude_and_pi(n, sin0, cos0, nu * t, m, mc)

    # Separatrix, m = 1: cn = dn = sech, sn = tanh, and ∫ du/(1 − n tanh²u) in closed form.
    a = jnp.sqrt(jnp.where(n < 0, -n, 1)) * jnp.where(n < 0, 1, 0)  # n = 0 only for a symmetric top
    u0_sep = jnp.arcsinh(sig2 * v2 * amp_c / (amp_b * jnp.abs(v3)))
    u_sep = nu * t + u0_sep
    e = jnp.exp(-jnp.abs(u_sep))
    sech = 2 * e / (1 + e * e)
    tanh = jnp.tanh(u_sep)
    d_pi_sep = (u_sep - u0_sep + a * (jnp.arctan(a * tanh) - jnp.arctan(a * jnp.tanh(u0_sep)))) / (1 - n)

    sn = jnp.where(separatrix, tanh, sn)
    cn = jnp.where(separatrix, sech, cn)
    dn = jnp.where(separatrix, sech, dn)
    d_pi = jnp.where(separatrix, d_pi_sep, d_pi)
    am = jnp.where(separatrix, jnp.arctan2(tanh, sech), am)
    omega_body = jnp.stack([sig1 * amp_a * cn, sig2 * amp_b * sn, sig3 * amp_c * dn])
    precession = l_norm * t / j3 + l_norm * (j3 - j1) / (j1 * j3 * nu) * d_pi

    # (L1, L2) = σ1 (a cos y, b sin y) with y = σ1 σ2 am, a, b > 0: its angle from the L1 axis
    # is within π/2 of y (+ π if σ1 < 0), which fixes the branch of ψ = atan2(L1, L2).
    def psi_estimate(amplitude):
        return 0.5 * jnp.pi - sig1 * sig2 * amplitude - jnp.where(sig1 < 0, jnp.pi, 0)

    rho = quat.multiply(_qz(precession), _tilt(moments * omega_body, psi_estimate(am)))
    tilt0 = _tilt(l_body0, psi_estimate(phi0))
    q_t = quat.normalize(quat.multiply(quat.multiply(q_frame, quat.conjugate(tilt0)), rho))
    return q_t, quat.rotate(q_t, omega_body)


_IDENTITY = (1.0, 0.0, 0.0, 0.0)
# Principal frame → case-B frame with axes (e3, e2, −e1): rotation by −π/2 about e2.
_TO_REVERSED = (0.5**0.5, 0.0, -(0.5**0.5), 0.0)
# Stand-in inputs for branches that are not selected (finite values and gradients).
_STANDIN_MOMENTS = (1.0, 2.0, 3.0)
_STANDIN_OMEGA = (1.0, 0.5, 2.0)

# Short flights, θ = max(1, κ) |ω| |t| < _TAYLOR_MAX with κ = max |I_j − I_k| / I_i (<= 1 for a physical
# body), are taken from the Taylor series in t to order _TAYLOR_ORDER. The coefficients of ω_b(t)
# and of the body-frame rotation p(t) are bounded by majorants that grow like (1.5 θ)^k, so the
# truncation error is below (1.5 θ)^(N+1) ~ 7e-20 < eps · θ: exact to round-off, relative to the
# small rotation too. Its derivatives are those of a polynomial, with none of the amplitude/phase
# singularities of the elliptic formulas near ω = 0 and near steady rotation.
_TAYLOR_ORDER = 8
_TAYLOR_MAX = 5e-3


def _taylor(w, moments, t):
    """``(p(t), ω_b(t))`` by their Taylor series: ``q(t) = q₀ ⊗ p(t)``, body-frame ``ω_b``.

    Euler's equations ``ω̇_b = I⁻¹ (I ω_b × ω_b)`` and ``ṗ = ½ p ⊗ (0, ω_b)`` with
    ``p(0) = 1`` are quadratic, so the coefficients (scaled by ``t^k``) follow from
    Cauchy products: ``a_{k+1} = t/(k+1) I⁻¹ Σ I a_i × a_{k−i}``,
    ``b_{k+1} = t/(2(k+1)) Σ b_i ⊗ (0, a_{k−i})``.
    """
    # A fixed-length loop over the orders, with the coefficients in fixed-size buffers: the HLO, and
    # the compile time of gradients through a scheme that calls this every step, do not grow with N.
    size = _TAYLOR_ORDER + 1
    index = jnp.arange(size)
    a0 = jnp.zeros((size, 3), w.dtype).at[0].set(w)
    b0 = jnp.zeros((size, 4), w.dtype).at[0, 0].set(1)

    def order(k, coefficients):
        a, b = coefficients
        # tail[i] = a[k − i] for i <= k, else 0: the Cauchy product's partner.
        tail = jnp.where((index <= k)[:, None], a[jnp.clip(k - index, 0, size - 1)], 0)
        da = jnp.sum(jnp.cross(moments[None, :] * a, tail), axis=0) / moments
        db = 0.5 * jnp.sum(quat.multiply(b, quat.pure(tail)), axis=0)
        scale = t / (k + 1).astype(w.dtype)
        return a.at[k + 1].set(scale * da), b.at[k + 1].set(scale * db)

    a, b = lax.fori_loop(0, _TAYLOR_ORDER, order, (a0, b0))
    p = jnp.sum(b[:0:-1], axis=0).at[0].add(1)  # the small terms first
    omega_t = jnp.sum(a[:0:-1], axis=0) + w
    return p, omega_t


def free_motion(q_principal, omega, moments, t):
    """Exact torque-free motion of one body over a time ``t``, in its principal frame.

    Args:
        q_principal: ``(4,)`` unit quaternion, principal frame → world.
        omega: ``(3,)`` world-frame angular velocity.
        moments: ``(3,)`` principal moments, **ascending** (see `principal_axes`).
        t: scalar time elapsed (any sign).

    Returns:
        ``(q_principal(t), omega(t))``, shapes ``(4,)`` and ``(3,)``.
    """
    dtype = q_principal.dtype
    t = jnp.asarray(t).astype(dtype)
    # Renormalised on the way in and out: a scheme that calls this every step would otherwise
    # let |q| drift by ~1e-16 per step, and a non-unit q scales ω in every frame change.
    q_principal = quat.normalize(q_principal)
    i1, i2, i3 = moments[0], moments[1], moments[2]
    w = quat.rotate(quat.conjugate(q_principal), omega)
    w1, w2, w3 = w[0], w[1], w[2]
    d3 = i1 * (i3 - i1) * w1 * w1 + i2 * (i3 - i2) * w2 * w2  # 2E I3 − L²
    d1 = i2 * (i2 - i1) * w2 * w2 + i3 * (i3 - i1) * w3 * w3  # L² − 2E I1
    s2 = i3 * (i3 - i2) * w3 * w3 - i1 * (i2 - i1) * w1 * w1  # L² − 2E I2
    # Steady: ω along a principal axis (ω × Iω = 0), or an underflowed d1, d3.
    gyro_free = ((i3 - i2) * w2 * w3 == 0) & ((i3 - i1) * w3 * w1 == 0) & ((i2 - i1) * w1 * w2 == 0)
    steady = gyro_free | (d1 == 0) | (d3 == 0)
    symmetric = (i1 == i2) | (i2 == i3)
    closed_form = steady | symmetric

    # Short flight (|ω| t small, ω = 0 included): the Taylor series, behind a double where.
    kappa = jnp.max(jnp.abs(moments[jnp.array([1, 2, 0])] - moments[jnp.array([2, 0, 1])]) / moments)
    theta = jnp.maximum(kappa, 1) * jnp.sqrt(jnp.sum(w * w)) * jnp.abs(t)
    short = theta < _TAYLOR_MAX
    p_short, w_short = _taylor(w, moments, jnp.where(short, t, 0))
    q_short = quat.multiply(q_principal, p_short)

    # Symmetric top (and steady rotation of an asymmetric body, λ = 0, Ω = ω), one formula:
    # q(t) = exp(t Ω) ⊗ q0 ⊗ exp(−λ t a), Ω = L_w / I⊥ = ω + λ a_w, λ = (I_a − I⊥)(ω·a) / I⊥.
    # Written with I⊥ the mean of the two equal moments, so that its derivatives are those along
    # the inertia perturbations that keep the symmetry (the others are added below).
    steady_asym = steady & ~symmetric
    axis3 = i1 == i2
    e_axis = jnp.where(axis3, jnp.array([0.0, 0.0, 1.0], dtype), jnp.array([1.0, 0.0, 0.0], dtype))
    i_axis = jnp.where(axis3, i3, i1)
    i_perp = jnp.where(axis3, 0.5 * (i1 + i2), 0.5 * (i2 + i3))
    lam = jnp.where(steady_asym, 0, (i_axis - i_perp) * jnp.dot(w, e_axis) / i_perp)
    spin = jnp.where(steady_asym, omega, quat.rotate(q_principal, w + lam * e_axis))
    precess = quat.normalize(quat.multiply(quat.exp(t * spin), q_principal))
    q_sym = quat.multiply(precess, quat.exp(-lam * t * e_axis))
    omega_sym = jnp.where(steady_asym, omega, quat.rotate(precess, w))

    # A symmetric top's closed form has no derivative along the inertia perturbation d that breaks
    # the symmetry: it is added from the linearised motion, with a zero value.
    fixed = lax.stop_gradient
    q_break, omega_break = _symmetry_breaking(fixed(w), moments, fixed(t), fixed(q_sym))
    q_sym = q_sym + q_break
    omega_sym = omega_sym + omega_break

    # Asymmetric: choose the frame in which L circulates about axis 3.
    standin = closed_form | short
    # Near steady rotation about axis k (ε = |ω⊥| / |ω| <= 1e-8, or 5e-6 about the intermediate axis,
    # where the elliptic derivatives are worse; both are ~ the error of the linearisation there).
    k = jnp.argmax(jnp.abs(w))
    on_axis = jnp.arange(3) == k
    off_axis = jnp.sqrt(jnp.sum(jnp.where(on_axis, 0, w) ** 2))
    w_norm = jnp.sqrt(jnp.sum(w * w))
    near_limit = jnp.where(k == 1, 5e-6, 1e-8).astype(dtype)
    near = (steady | (off_axis <= near_limit * w_norm)) & ~symmetric & ~short
    reverse = s2 < 0
    frame_moments = jnp.where(reverse, moments[::-1], moments)
    frame_omega = jnp.where(reverse, jnp.stack([w3, w2, -w1]), w)
    to_frame = jnp.where(reverse, jnp.array(_TO_REVERSED, dtype), jnp.array(_IDENTITY, dtype))
    q_frame = quat.multiply(q_principal, to_frame)
    # Close to steady rotation (below) the value and the inertia derivative come from here.
    frame_omega = jnp.where(near, lax.stop_gradient(frame_omega), frame_omega)
    q_asym, omega_asym = _asymmetric(
        jnp.where(near, lax.stop_gradient(q_frame), q_frame),
        jnp.where(standin, jnp.array(_STANDIN_OMEGA, dtype), frame_omega),
        jnp.where(standin, jnp.array(_STANDIN_MOMENTS, dtype), frame_moments),
        jnp.where(near, lax.stop_gradient(t), t),
    )
    q_asym = quat.multiply(q_asym, quat.conjugate(to_frame))

    q_out = jnp.where(closed_form, q_sym, q_asym)
    omega_out = jnp.where(closed_form, omega_sym, omega_asym)
    # Near steady rotation of an asymmetric body the elliptic formulas' derivatives lose accuracy
    # (relative error ~eps/ε about the major and minor axes, eps/ε² about the intermediate one,
    # ε = |ω⊥| / |ω|): the derivatives with respect to q, ω and t there are those of the linearised
    # motion about the steady rotation w_k e_k (exact at ε = 0, error O(ε) otherwise); the value and
    # the inertia derivative (O(ε), with a small absolute error) are the elliptic formulas'.
    q_base = jnp.where(closed_form, lax.stop_gradient(q_sym), q_asym)
    omega_base = jnp.where(closed_form, lax.stop_gradient(omega_sym), omega_asym)
    q_near, omega_near = _near_steady(q_principal, w, t, q_base, omega_base, lax.stop_gradient(moments))
    q_out = jnp.where(near, q_near, q_out)
    omega_out = jnp.where(near, omega_near, omega_out)
    q_out = jnp.where(short, q_short, q_out)
    omega_out = jnp.where(short, quat.rotate(quat.normalize(q_short), w_short), omega_out)
    return quat.normalize(q_out), omega_out
