"""The linearised torque-free motions that give `jaxrot._free_body._free_motion.free_motion` true
derivatives where its closed forms' are not: a symmetric top perturbed along the inertia that breaks
its symmetry (`_symmetry_breaking`), and an asymmetric body near steady rotation about a principal axis
(`_near_steady`). Both have a ``custom_jvp`` whose value costs nothing; the matrix exponential of the
variational equations (`_expm`) is evaluated only when differentiating.
"""

import jax
import jax.numpy as jnp
from jax import lax

from .. import quaternion as quat


# Matrix exponential with a fixed amount of work (vmap/scan/transpose-safe): scaled so that
# ‖A / 2^s‖₁ <= 1, Taylor series to order 18 (remainder < 1/19! ~ 8e-18), then s squarings.
_EXPM_ORDER = 18
_EXPM_MAX_SQUARINGS = 48


def _expm(a):
    norm = jnp.max(jnp.sum(jnp.abs(a), axis=0))
    s = jnp.clip(jnp.ceil(jnp.log2(jnp.maximum(norm, 1))), 0, _EXPM_MAX_SQUARINGS)
    scaled = a * jnp.exp2(-s)
    eye = jnp.eye(a.shape[0], dtype=a.dtype)

    def horner(i, x):  # I + A/1 (I + A/2 (I + ...)), from the innermost term
        return eye + (scaled @ x) / (_EXPM_ORDER - i).astype(a.dtype)

    result = lax.fori_loop(0, _EXPM_ORDER, horner, eye)

    def square(i, x):
        return jnp.where(i < s, x @ x, x)

    return lax.fori_loop(0, _EXPM_MAX_SQUARINGS, square, result)


def _hat(v):
    """Cross-product matrix: ``_hat(v) @ x = v × x``."""
    zero = jnp.zeros_like(v[0])
    return jnp.stack(
        [jnp.stack([zero, -v[2], v[1]]), jnp.stack([v[2], zero, -v[0]]), jnp.stack([-v[1], v[0], zero])]
    )


def _symmetry_breaking_tangent(w, moments, t, axis3):
    """First-order change of a symmetric top's motion when its inertia becomes ``I + δ D``.

    ``D = diag(1, −1, 0)`` in a frame whose third axis is the symmetry axis (``e₃`` if
    ``axis3``, else ``e₁``, with the cyclic frame ``(e₂, e₃, e₁)``). Returns ``(ξ, η)``:
    ``∂ω_b(t)/∂δ = ξ`` and ``∂p(t)/∂δ = p(t) ⊗ (0, η/2)`` (body frame, ``q(t) = q₀ ⊗ p(t)``).

    Linearising Euler's equations and ``ṗ = ½ p ⊗ (0, ω_b)`` about the symmetric motion
    ``ω_b(t) = R(λt) ω_b(0)`` gives ``ξ̇ = J(ω_b) ξ + I⁻¹((D ω_b) × ω_b − D ω̇_b)``,
    ``η̇ = η × ω_b + ξ``, ``ξ(0) = η(0) = 0``, with ``J(ω) ξ = I⁻¹((Iξ) × ω + (Iω) × ξ)``. In the
    frame turning with ``ω_b`` (``ξ = R(λt) x``, ``η = R(λt) y``) the coefficients are constant
    and the forcing is ``cos(2λt) g(D) + sin(2λt) g(E)`` (``Rᵀ D R`` turns at ``2λ``); with
    ``(cos 2λt, sin 2λt)`` as two more states the whole system is ``Ẋ = M X``, solved exactly
    by one 8×8 matrix exponential (which has no trouble with resonances, or with the
    exponential growth of a perturbed spin about the would-be intermediate axis).
    """
    dtype = w.dtype
    wp = jnp.where(axis3, w, jnp.roll(w, -1))
    mp = jnp.where(axis3, moments, jnp.roll(moments, -1))
    i_perp = 0.5 * (mp[0] + mp[1])
    inertia = jnp.stack([i_perp, i_perp, mp[2]])
    lam = (mp[2] - i_perp) * wp[2] / i_perp
    e3 = jnp.array([0.0, 0.0, 1.0], dtype)
    wdot = lam * jnp.cross(e3, wp)
    jac = (_hat(inertia * wp) - _hat(wp) * inertia[None, :]) / inertia[:, None]
    d_diag = jnp.array([1.0, -1.0, 0.0], dtype)
    e_mat = jnp.array([[0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 0.0]], dtype)
    g_d = (jnp.cross(d_diag * wp, wp) - d_diag * wdot) / inertia
    g_e = (jnp.cross(e_mat @ wp, wp) - e_mat @ wdot) / inertia
    turn = lam * _hat(e3)
    zeros = jnp.zeros((3, 3), dtype)
    two_lam = jnp.stack([jnp.zeros_like(lam), -2 * lam])
    m = jnp.concatenate(
        [
            jnp.concatenate([jac - turn, zeros, g_d[:, None], g_e[:, None]], axis=1),
            jnp.concatenate([jnp.eye(3, dtype=dtype), -_hat(wp) - turn, jnp.zeros((3, 2), dtype)], axis=1),
            jnp.concatenate([jnp.zeros((2, 6), dtype), jnp.stack([two_lam, -two_lam[::-1]])], axis=1),
        ]
    )
    x = _expm(m * t)[:, 6]
    rot = quat.exp(lam * t * e3)
    xi, eta = quat.rotate(rot, x[:3]), quat.rotate(rot, x[3:6])
    xi, eta = (jnp.where(axis3, v, jnp.roll(v, 1)) for v in (xi, eta))
    finite = jnp.all(jnp.isfinite(xi)) & jnp.all(jnp.isfinite(eta))  # overflow after very long times
    return jnp.where(finite, xi, 0), jnp.where(finite, eta, 0)


def _steady_tangent(w, moments, t):
    """``∂(ω_b(t), η(t))/∂ω_b(0)``, ``(6, 3)``, about the steady rotation ``ω_b ≡ w`` (``w × Iw = 0``).

    About a constant ``w`` the variational equations ``ξ̇ = J(w) ξ``, ``η̇ = η × w + ξ``
    (notation of `_symmetry_breaking_tangent`; ``∂p(t) = p(t) ⊗ (0, η/2)``) have constant
    coefficients: one 6×6 matrix exponential. A perturbation of the inertia moves a steady
    rotation only at second order.
    """
    jac = (_hat(moments * w) - _hat(w) * moments[None, :]) / moments[:, None]
    m = jnp.concatenate(
        [
            jnp.concatenate([jac, jnp.zeros((3, 3), w.dtype)], axis=1),
            jnp.concatenate([jnp.eye(3, dtype=w.dtype), -_hat(w)], axis=1),
        ]
    )
    tangent = _expm(m * t)[:, :3]
    return jnp.where(jnp.all(jnp.isfinite(tangent)), tangent, 0)  # overflow after very long times


@jax.custom_jvp
def _symmetry_breaking(w, moments, t, q_t):
    """Zeros ``(4,)``, ``(3,)`` whose derivative is a symmetric top's along the symmetry-breaking inertia.

    The value is zero and costs nothing; the 8×8 matrix exponential of
    `_symmetry_breaking_tangent` is evaluated only when differentiating.
    """
    return 0 * q_t, 0 * w


@_symmetry_breaking.defjvp
def _symmetry_breaking_jvp(primals, tangents):
    w, moments, t, q_t = primals
    d_moments = tangents[1]
    dtype = w.dtype
    axis3 = moments[0] == moments[1]
    symmetric = axis3 | (moments[1] == moments[2])
    d = jnp.where(axis3, jnp.array([1.0, -1.0, 0.0], dtype), jnp.array([0.0, 1.0, -1.0], dtype))
    breaking = jnp.where(symmetric, 0.5 * jnp.dot(d, d_moments), 0)
    xi, eta = _symmetry_breaking_tangent(w, moments, t, axis3)
    e_axis = jnp.where(axis3, jnp.array([0.0, 0.0, 1.0], dtype), jnp.array([1.0, 0.0, 0.0], dtype))
    i_axis = jnp.where(axis3, moments[2], moments[0])
    i_perp = jnp.where(axis3, 0.5 * (moments[0] + moments[1]), 0.5 * (moments[1] + moments[2]))
    lam = (i_axis - i_perp) * jnp.dot(w, e_axis) / i_perp
    w_t = quat.rotate(quat.exp(lam * t * e_axis), w)
    dq = breaking * quat.multiply(q_t, quat.pure(0.5 * eta))
    domega = breaking * quat.rotate(q_t, xi + jnp.cross(eta, w_t))
    return (0 * q_t, 0 * w), (dq, domega)


@jax.custom_jvp
def _near_steady(q_principal, w, t, q_t, omega_t, moments):
    """``(q_t, omega_t)`` with the derivatives w.r.t. ``q_principal``, ``w``, ``t`` of the motion
    linearised about the steady rotation ``w_k e_k`` (see `_steady_tangent`), those w.r.t. ``q_t``,
    ``omega_t`` passed through. The matrix exponential is evaluated only when differentiating."""
    return q_t, omega_t


@_near_steady.defjvp
def _near_steady_jvp(primals, tangents):
    q_principal, w, t, q_t, omega_t, moments = primals
    dq_principal, dw, dt, dq_t, domega_t, _ = tangents
    on_axis = jnp.arange(3) == jnp.argmax(jnp.abs(w))
    tangent = _steady_tangent(jnp.where(on_axis, w, 0), moments, t)
    xi, eta = tangent[:3] @ dw, tangent[3:] @ dw
    w_t = quat.rotate(quat.conjugate(q_t), omega_t)  # ω_b(t)
    xi = xi + dt * jnp.cross(moments * w_t, w_t) / moments  # + ω̇_b(t) dt
    # q(t) = q0 ⊗ p: dq = dq0 ⊗ q0* ⊗ q(t) + q(t) ⊗ (0, (η + ω_b dt) / 2); ω = q(t) ω_b q(t)*.
    dq = quat.multiply(dq_principal, quat.multiply(quat.conjugate(q_principal), q_t))
    dq = dq + quat.multiply(q_t, quat.pure(0.5 * (eta + dt * w_t)))
    domega = jax.jvp(lambda q: quat.rotate(q, w_t), (q_t,), (dq,))[1] + quat.rotate(q_t, xi)
    return (q_t, omega_t), (dq + dq_t, domega + domega_t)
