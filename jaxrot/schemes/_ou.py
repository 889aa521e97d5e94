r"""The Ornstein–Uhlenbeck flow of a body's spin in a fluid at a temperature, solved exactly.

About each principal axis ``k`` (body frame, the friction's axes), with the applied and gyroscopic
torques held fixed over the step, the spin obeys

    I_k du_k = ζ_k (S_k − u_k) dt + √(2 kT ζ_k) dW_k,      dθ_k = u_k dt,

with ``S`` the *slow velocity*, the spin at which the fluid's torque balances the rest: the flow's
rotation plus ``ζ⁻¹`` times the other torques. With ``x = γ h``, ``γ = ζ_k / I_k``, over a step
``h`` it is a Gaussian (Gardiner, Handbook of Stochastic Methods, section 3.8.4):

    u(h) = S + e^{−x} (u − S) + a √(2 φ₁(−2x)) ξ₁,
    θ(h) = S h + h φ₁(−x) (u − S) + a h [φ₁(−x)² / √(2 φ₁(−2x)) ξ₁ + √W(x) ξ₂],

``a = √(kT ζ h) / I``, ``φ₁(z) = (e^z − 1)/z``, ``V(x) = (2x − 3 + 4e^{−x} − e^{−2x}) / x³`` and
``W(x) = V(x) − φ₁(−x)⁴ / (2 φ₁(−2x))`` (the variance of ``θ`` given ``u(h)``: ``ξ₂`` is independent
of it): the spin's variance
``(kT/I)(1 − e^{−2x})``, the angle's ``(kT/I) h² x V(x)`` and their covariance ``(kT/I) h x φ₁(−x)²``.
Given both ends, ``θ(h) = (h − 2c) S + c (u + u(h)) + a h √W(x) ξ₂`` with ``c = (h/2) tanh(x/2)/(x/2)``
(`drift_factor`): the regression of ``θ`` on the two spins has equal weights, ``c``, because the
OU process is reversible; `jaxrot.schemes.BAOAB` moves its A steps by exactly that.
As ``x → ∞`` the angle's law becomes Brownian, ``N(S h, 2 kT h / ζ)``, and the spin's the
Maxwell law ``N(S, kT/I)``; as ``x → 0``, ballistic. The spin alone (``θ`` dropped) is the exact
"O" step of the Langevin splittings (Davidchack, Ouldridge & Tretyakov, J. Chem. Phys. 142, 144114
(2015); Leimkuhler & Matthews, Appl. Math. Res. Express 2013, 34).

Finite in value and gradient at ``x = 0`` (Taylor branch of ``V``), at ``x → ∞`` and at ``kT = 0``
(the noise amplitude's derivative in ``kT`` there, ``∝ 1/√kT``, is returned as 0).
"""

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp

from ._phi import phi_functions


def _v_series_terms(dtype) -> int:
    eps = float(jnp.finfo(dtype).eps)
    n = 3
    while 2.0**n / math.factorial(n) > eps / 16:  # the terms of V at x = 1, against V(1) ≈ 0.34
        n += 1
    return n


def _angle_variance_factor(x):
    """``V(x) = (2x − 3 + 4e^{−x} − e^{−2x}) / x³`` (``2/3`` at 0, ``≈ 2/x²`` far out), ``x ≥ 0``.

    The numerator cancels to ``2x³/3`` near 0: there (``x ≤ 1``) its Taylor series
    ``Σ_{n≥3} (−1)ⁿ (4 − 2ⁿ) x^{n−3} / n!`` is summed."""
    near = x <= 1
    x_near = jnp.where(near, x, 0.0)
    x_far = jnp.where(near, 2.0, x)
    series = jnp.zeros_like(x)
    for n in reversed(range(3, _v_series_terms(x.dtype))):
        series = series * x_near + (-1) ** n * (4 - 2.0**n) / math.factorial(n)
    # (2 + (4 expm1(−x) − expm1(−2x))/x) / x², divided one x at a time: finite to x ~ 1e38 in float32.
    far = ((2 + (4 * jnp.expm1(-x_far) - jnp.expm1(-2 * x_far)) / x_far) / x_far) / x_far
    return jnp.where(near, series, far)


def drift_factor(x):
    """``f(x) = tanh(x/2) / (x/2)`` (1 at 0, ``≈ 2/x`` far out), ``x ≥ 0``, finite in value and gradient.

    Given the spin at both ends of an OU step of ``x = ζh/I`` (deviations ``v₀``, ``v₁`` from the slow
    velocity), the angle's conditional mean is ``(h/2) f(x) (v₀ + v₁)`` (module docstring): the
    weight of each end's spin, ``h/2`` at ``x = 0`` (BAOAB's A steps), ``I/ζ`` as ``x → ∞``.
    Near 0 (``x ≤ 0.02``) the series ``1 − y²/3 + 2y⁴/15 − 17y⁶/315``, ``y = x/2``, whose next term
    is below 1e-18."""
    near = x <= 0.02
    y_near = jnp.where(near, 0.5 * x, 0.0)
    y_far = jnp.where(near, 1.0, 0.5 * x)
    y2 = y_near * y_near
    series = 1 + y2 * (-1 / 3 + y2 * (2 / 15 - y2 * 17 / 315))
    return jnp.where(near, series, jnp.tanh(y_far) / y_far)


def bridge_spread(x):
    """``√W(x)``: the standard deviation of the angle given the spin at both ends of the step, in
    units of ``a h`` (module docstring); ``√(1/6)`` at ``x = 0``, ``≈ √2/x`` far out, finite in value
    and gradient (0 where rounding makes ``W`` non-positive)."""
    _, phi = phi_functions(-x, 1)
    _, phi_double = phi_functions(-2 * x, 1)
    conditional = _angle_variance_factor(x) - phi**4 / (2 * phi_double)
    positive = conditional > 0
    return jnp.where(positive, jnp.sqrt(jnp.where(positive, conditional, 1.0)), 0.0)


def noise_scale(kT, friction, h, inertia):
    """``a = √(kT ζ h) / I`` per axis, 0 (value and gradient) where ``kT = 0``."""
    variance = kT * friction * h
    positive = variance > 0
    return jnp.where(positive, jnp.sqrt(jnp.where(positive, variance, 1.0)), 0.0) / inertia


class Relaxation(NamedTuple):
    """The weights of the exact O step over ``h``, per axis ``(3,)``: ``u₁ = decay u + pull S + spread ξ``.

    ``decay = e^{−x}``, ``pull = 1 − e^{−x} = x φ₁(−x)``, ``spread = a √(2 φ₁(−2x))`` (None without
    noise), ``x = ζh/I``. They depend on ``ζ``, ``I``, ``kT`` and ``h`` only: a scheme computes them
    once per step, not once per body, where those are shared (`relaxation_weights`)."""

    decay: jax.Array
    pull: jax.Array
    spread: jax.Array | None


def relaxation_weights(friction, inertia, kT, h, noise=True) -> Relaxation:
    """`Relaxation` of the O step over ``h``; ``noise`` (static) False leaves ``spread`` None."""
    x = friction / inertia * h
    decay, phi = phi_functions(-x, 1)
    spread = None
    if noise:
        _, phi_double = phi_functions(-2 * x, 1)
        spread = noise_scale(kT, friction, h, inertia) * jnp.sqrt(2 * phi_double)
    return Relaxation(decay, x * phi, spread)


def relax(u, slow, weights: Relaxation, normals=None):
    """The O step of `spin_relaxation` with its weights given (``normals`` None: no noise)."""
    u1 = weights.decay * u + weights.pull * slow  # not slow + decay (u − slow): see `integrated_spin`
    if normals is not None:
        u1 = u1 + weights.spread * normals
    return u1


def spin_relaxation(u, slow, friction, inertia, kT, h, normals=None):
    """The exact O step: body spin ``u`` ``(3,)`` relaxed towards ``slow`` over ``h`` with the noise
    of ``normals`` ``(3,)`` (standard normals; None: no noise). Per axis: friction, inertia ``(3,)``."""
    weights = relaxation_weights(friction, inertia, kT, h, noise=normals is not None)
    return relax(u, slow, weights, normals)


def integrated_spin(u, slow, friction, inertia, kT, h, normals=None):
    """``(u(h), θ(h))`` of the module's Gaussian step: spin and body rotation vector ``(3,)`` each.

    ``normals`` ``(6,)``: ``ξ₁`` then ``ξ₂`` per axis (None: no noise)."""
    x = friction / inertia * h
    decay, phi, phi2 = phi_functions(-x, 2)
    # The means written without u − S: a torque frozen into S = ζ⁻¹ τ is huge where ζ is small, and
    # u − S, S + e^{−x}(u − S) would lose u to rounding (float32, ζΔt/I = 1e-8: all of it). Here
    # 1 − e^{−x} = x φ₁(−x) and 1 − φ₁(−x) = x φ₂(−x): x S = h τ / I at any x.
    u1 = decay * u + (x * phi) * slow
    theta = (h * phi) * u + (h * x * phi2) * slow
    if normals is not None:
        _, phi_double = phi_functions(-2 * x, 1)
        a = noise_scale(kT, friction, h, inertia)
        root = jnp.sqrt(2 * phi_double)
        first, second = normals[:3], normals[3:]
        u1 = u1 + (a * root) * first
        theta = theta + (a * h) * ((phi * phi / root) * first + bridge_spread(x) * second)
    return u1, theta
