r"""Exact torque-free rigid-body motion (Euler–Poinsot), for tests and splitting schemes.

`free_top` returns the exact orientation and angular velocity of a torque-free
rigid body with any inertia, at any times, to round-off: the symmetric top in
closed form, the asymmetric top with Jacobi elliptic functions and the
incomplete elliptic integral of the third kind (`jaxrot._elliptic`).
`free_motion` is the single-body core, in the principal frame, that
`jaxrot.schemes.splitting.Splitting` calls once per step.

Conventions are those of jaxrot: ``q`` scalar first ``[w, x, y, z]``, body →
world; ``omega`` in the world frame (rad per unit time); inertia in the body
frame, principal moments ``(3,)`` or a symmetric tensor ``(3, 3)`` (mass ×
length²). A tensor is diagonalised, ``I = R diag(I₁, I₂, I₃) Rᵀ`` with ``R`` a
proper rotation (``r`` its quaternion, principal → body), and the motion is
solved for the principal-frame orientation ``q ⊗ r``.

Cases (principal moments sorted ``I₁ <= I₂ <= I₃``, ``L_i = I_i ω_i``,
``L² = Σ L_i²``, ``2E = Σ I_i ω_i²``, body-frame ``ω``):

- **steady rotation** — spherical body, ``ω = 0``, or ``ω`` along a principal
  axis (``ω × Iω = 0``, including pure spin about the *intermediate* axis, an
  unstable but exact equilibrium): ``ω`` constant, ``q(t) = exp(ω t) ⊗ q₀``.
- **symmetric top** (``I₁ = I₂`` or ``I₂ = I₃`` exactly; symmetry axis ``a``,
  ``I⊥ = I₂``): ``q(t) = exp(L_w t / I⊥) ⊗ q₀ ⊗ exp(−λ t a)`` with
  ``λ = (I_a − I⊥) (ω·a) / I⊥`` (Landau & Lifshitz §33).
- **asymmetric, case A** ``L² > 2E I₂`` (the angular momentum circulates about
  body axis 3) and **case B** ``L² < 2E I₂`` (about axis 1): case B is solved as
  case A in the principal frame rotated so that its axes are ``(3, 2, −1)``,
  i.e. with the moments reversed. With ``u = ν t + u₀``,
  ``ω₁ = σ₁ A cn(u|m)``, ``ω₂ = ε σ₁ σ₃ B sn(u|m)``, ``ω₃ = σ₃ C dn(u|m)``, and the
  orientation as Euler angles ``R = R_z(φ) R_x(θ) R_z(ψ)`` of body → (frame with
  ``e_z ∥ L``), ``ψ = atan2(L₁, L₂)``, ``θ = atan2(√(L₁² + L₂²), L₃)``,
  ``σ₁ = sign ω₁(0)``, ``σ₃ = sign ω₃``, ``ε = sign(I₃ − I₂)`` (−1 in case B),
  ``φ(t) = |L| t / I₃ + |L| (I₃ − I₁) / (I₁ I₃ ν) [Π(n; am u|m) − Π(n; am u₀|m)]``,
  ``n = −I₃ (I₂ − I₁) / (I₁ (I₃ − I₂)) < 0`` (Landau & Lifshitz §37; the formulas
  of ``notes/peers.md`` §6, checked there against DOP853).
- **separatrix** ``L² = 2E I₂`` exactly (with ``ω₁ ω₃ ≠ 0``, ``I₁ < I₂ < I₃``):
  the ``m → 1`` limit, ``cn = dn = sech``, ``sn = tanh`` and the elementary
  integral ``∫ du / (1 − n tanh² u) = (u + a atan(a tanh u)) / (1 − n)``,
  ``a = √−n``: the body approaches pure spin about the intermediate axis
  asymptotically. In floating point this branch is taken only when
  ``L² − 2E I₂``, computed without cancellation from the body-frame ``ω``, is
  exactly zero. Near it the elliptic formulas are used with ``1 − m`` computed
  without cancellation, as ``(I₃ − I₁)(L² − 2E I₂) / ((I₃ − I₂)(L² − 2E I₁))``,
  and with ``cn u₀`` (not ``am u₀``) taken from the data, so a state close to the
  unstable intermediate axis keeps its small components' relative precision;
  the motion there is exponentially sensitive to the initial state, and the
  result is as accurate as the input's round-off allows.

The returned ``q(t)`` is the continuous path on the unit quaternions that
starts at ``q₀`` (``ψ`` is unwrapped), so it has no ``q → −q`` jumps in time or
between the cases as the inputs vary.

Gradients: every branch is evaluated, with safe stand-in inputs where it cannot
apply, and selected, so values *and* gradients are finite everywhere, including
at ``ω = 0`` (where the derivative is the exact one, that of ``exp(ω t) ⊗ q₀``).
For a symmetric top the value comes from the closed form and the derivatives
from the case-A formulas (valid there with ``m = n = 0``), so they include
perturbations of the inertia that break the symmetry. Three measure-zero sets
give finite but *not* the true derivatives: exactly steady rotation with
``|ω| > 0`` (pure spin about a principal axis: the derivative with respect to the
off-axis components of ``ω`` is that of the steady rotation, not of the wobble a
perturbation starts), a spherical body (no derivative with respect to an
anisotropy of the inertia: do not start an inertia fit from ``I₁ = I₂ = I₃``),
and the exact separatrix. Derivatives with respect to a full ``(3, 3)`` tensor go
through ``eigh`` and are not finite when two principal moments are equal; pass
principal moments ``(3,)`` to differentiate a symmetric body's inertia.

References:
    L. D. Landau and E. M. Lifshitz, *Mechanics*, 3rd ed., §§33, 35–37.
    E. Celledoni, F. Fassò, N. Säfström and A. Zanna, "The exact computation of
    the free rigid body motion and its use in splitting methods", SIAM J. Sci.
    Comput. 30(4), 2084–2112 (2008), doi:10.1137/070704393.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
from jax import lax

from . import _elliptic as ell, quaternion as quat
from ._particles import flatten_particles, unflatten_trajectory
from ._state import RotState, Trajectory
from ._validation import check_bodies, check_times


__all__ = ["free_motion", "free_top", "principal_axes"]


def principal_axes(inertia):
    """Ascending principal moments ``(3,)`` and the quaternion ``r`` (principal → body) of one body.

    ``inertia`` is ``(3,)`` principal moments (``r`` is then a signed axis
    permutation, the identity when the moments are already ascending) or a
    symmetric ``(3, 3)`` tensor (``jnp.linalg.eigh``). ``r`` is a proper rotation:
    ``I_body = R diag(moments) Rᵀ`` with ``R = to_matrix(r)``.
    """
    inertia = jnp.asarray(inertia)
    if inertia.ndim == 1:
        order = jnp.argsort(inertia)
        moments = inertia[order]
        rot = (jnp.arange(3)[:, None] == order[None, :]).astype(inertia.dtype)
    else:
        moments, rot = jnp.linalg.eigh(0.5 * (inertia + inertia.T))
    det = jnp.dot(rot[:, 0], jnp.cross(rot[:, 1], rot[:, 2]))
    sign = jnp.where(det < 0, -1, 1).astype(rot.dtype)
    rot = jnp.concatenate([sign * rot[:, :1], rot[:, 1:]], axis=1)
    return moments, quat.from_matrix(rot)


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
    # Each Cauchy product is one vectorised cross / quaternion product over stacked coefficients
    # (unrolled scalar products would make the HLO, and the compile time of gradients, ~5x larger).
    a = [w]
    b = [jnp.array(_IDENTITY, w.dtype)]
    scaled_moments = moments[None, :]
    for k in range(_TAYLOR_ORDER):
        head = jnp.stack(a)
        tail = head[::-1]
        a.append((t / (k + 1)) * jnp.sum(jnp.cross(scaled_moments * head, tail), axis=0) / moments)
        b.append((t / (2 * (k + 1))) * jnp.sum(quat.multiply(jnp.stack(b), quat.pure(tail)), axis=0))
    p = sum(reversed(b[1:])).at[0].add(1)  # the small terms first
    omega_t = sum(reversed(a[1:])) + a[0]
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

    # Asymmetric: choose the frame in which L circulates about axis 3. For a symmetric top the
    # case-A formulas (valid there with m = n = 0) are evaluated with stopped gradients except
    # along the symmetry-breaking inertia perturbation d, whose derivative they supply.
    standin = steady | short
    breaking = symmetric & ~standin
    d = jnp.where(axis3, jnp.array([1.0, -1.0, 0.0], dtype), jnp.array([0.0, 1.0, -1.0], dtype))
    fixed = lax.stop_gradient(moments)
    moments_a = jnp.where(breaking, fixed + d * (0.5 * jnp.dot(d, moments - fixed)), moments)
    w_a = jnp.where(breaking, lax.stop_gradient(w), w)
    q_a = jnp.where(breaking, lax.stop_gradient(q_principal), q_principal)
    t_a = jnp.where(breaking, lax.stop_gradient(t), t)
    reverse = s2 < 0
    frame_moments = jnp.where(reverse, moments_a[::-1], moments_a)
    frame_omega = jnp.where(reverse, jnp.stack([w_a[2], w_a[1], -w_a[0]]), w_a)
    to_frame = jnp.where(reverse, jnp.array(_TO_REVERSED, dtype), jnp.array(_IDENTITY, dtype))
    q_frame = quat.multiply(q_a, to_frame)
    q_asym, omega_asym = _asymmetric(
        q_frame,
        jnp.where(standin, jnp.array(_STANDIN_OMEGA, dtype), frame_omega),
        jnp.where(standin, jnp.array(_STANDIN_MOMENTS, dtype), frame_moments),
        t_a,
    )
    q_asym = quat.multiply(q_asym, quat.conjugate(to_frame))
    q_sym = jnp.where(breaking, q_sym + (q_asym - lax.stop_gradient(q_asym)), q_sym)
    omega_sym = jnp.where(breaking, omega_sym + (omega_asym - lax.stop_gradient(omega_asym)), omega_sym)

    q_out = jnp.where(closed_form, q_sym, q_asym)
    omega_out = jnp.where(closed_form, omega_sym, omega_asym)
    q_out = jnp.where(short, q_short, q_out)
    omega_out = jnp.where(short, quat.rotate(quat.normalize(q_short), w_short), omega_out)
    return quat.normalize(q_out), omega_out


# Up to this many (particle, time) pairs are evaluated one after the other (`lax.map`), which
# compiles about twice as fast as the batched (`vmap`) form; larger batches are vectorised.
_SEQUENTIAL_MAX = 4096


@eqx.filter_jit
def _free_top_flat(q, omega, inertia, per_particle, ts):
    """``(N, 4)``, ``(N, 3)`` states and ``(n,)`` times → ``(n, N, 4)``, ``(n, N, 3)``."""
    moments, r = jax.vmap(principal_axes)(inertia) if per_particle else principal_axes(inertia)
    r = jnp.broadcast_to(r, q.shape)
    moments = jnp.broadcast_to(moments, omega.shape)
    q_p = quat.multiply(q, r)
    elapsed = ts - ts[0]
    n_particles, n_times = q.shape[0], ts.shape[0]
    if n_particles * n_times <= _SEQUENTIAL_MAX:

        def repeat(x):
            return jnp.repeat(x, n_times, axis=0)

        pairs = (repeat(q_p), repeat(omega), repeat(moments), jnp.tile(elapsed, n_particles))
        q_t, omega_t = jax.lax.map(lambda args: free_motion(*args), pairs)
        q_t = q_t.reshape(n_particles, n_times, 4)
        omega_t = omega_t.reshape(n_particles, n_times, 3)
    else:
        at_times = jax.vmap(free_motion, in_axes=(None, None, None, 0))
        q_t, omega_t = jax.vmap(at_times, in_axes=(0, 0, 0, None))(q_p, omega, moments, elapsed)
    q_t = quat.multiply(q_t, quat.conjugate(r)[:, None, :])
    return jnp.swapaxes(q_t, 0, 1), jnp.swapaxes(omega_t, 0, 1)


def free_top(state: RotState, inertia, ts, *, normalize: bool = False) -> Trajectory:
    """Exact motion of torque-free rigid bodies at the times ``ts``.

    The state is given at ``ts[0]``, as in `jaxrot.reference_rollout`; since the
    solution is exact, ``ts`` may be in any order and steps of any size.

    Args:
        state: `jaxrot.RotState` with ``q`` ``(..., 4)`` (unit, scalar first, body
            → world) and world-frame ``omega`` ``(..., 3)`` (rad per unit time).
            Leading axes are particles.
        inertia: body-frame inertia (mass × length²): principal moments ``(3,)``
            or a symmetric tensor ``(3, 3)``, shared, or one per particle with the
            particle axes in front (as in `jaxrot.rollout`).
        ts: 1-D array of times ``(n,)``.
        normalize: normalise ``state.q`` instead of rejecting a non-unit one.

    Returns:
        `jaxrot.Trajectory` with ``t = ts`` ``(n,)``, ``q`` ``(n, ..., 4)`` and
        ``omega`` ``(n, ..., 3)``, in the dtype of ``state``.

    Raises:
        ValueError: wrong shapes, non-finite values, a non-unit ``q``, a
            non-physical inertia (checked as in `jaxrot.rollout`), or ``ts`` not
            a finite 1-D array of at least one time.

    Example:
        >>> import jax.numpy as jnp, jaxrot
        >>> from jaxrot import analytic, diagnostics
        >>> inertia = jnp.array([1.0, 2.0, 3.0])
        >>> state = jaxrot.RotState(jnp.array([1.0, 0, 0, 0]), jnp.array([0.3, 1.0, 0.2]))
        >>> traj = analytic.free_top(state, inertia, jnp.linspace(0.0, 10.0, 5))
        >>> traj.q.shape, traj.omega.shape
        ((5, 4), (5, 3))
        >>> print(traj.omega[-1].round(3).tolist())
        [0.352, 1.004, 0.162]
        >>> energy = diagnostics.kinetic_energy(traj.q, traj.omega, inertia)
        >>> print(bool(jnp.allclose(energy, energy[0], rtol=1e-5)))
        True
    """
    state, inertia, per_particle = check_bodies(state, inertia, normalize=normalize)
    ts = check_times(ts, state.q.dtype, ordered=False)
    flat, inertia = flatten_particles(state, inertia, per_particle)
    q_t, omega_t = _free_top_flat(flat.q, flat.omega, inertia, per_particle, ts)
    return unflatten_trajectory(Trajectory(ts, q_t, omega_t), state.q.shape[:-1])
