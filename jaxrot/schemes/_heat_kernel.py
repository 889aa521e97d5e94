r"""Free isotropic rotational diffusion over a time step, sampled exactly: the heat kernel of SO(3).

A body whose rotational diffusion is ``D`` about every axis (a sphere) turns in a time ``h`` by a
random rotation whose law is the heat kernel of SO(3) at ``s = D h``: its axis is uniform, and its
angle ``φ`` has the density (irreducible characters ``χ_j(φ) = sin((2j+1)φ/2)/sin(φ/2)``, Haar
measure ``(1 − cos φ)/π dφ`` on ``[0, π]``)

    p(φ) = (1 − cos φ)/π · Σ_j (2j + 1) e^{−j(j+1) s} χ_j(φ),     E[χ_j(φ)] = (2j + 1) e^{−j(j+1) s},

so ``⟨u(h)·u(0)⟩ = E[(1 + 2 cos φ)/3] = e^{−2Dh}`` and ``⟨P₂(u(h)·u(0))⟩ = e^{−6Dh}`` for any
body-fixed unit vector ``u`` (Favro, Phys. Rev. 119, 53 (1960)). In the half angle ``ψ = φ/2`` of
the quaternion ``(cos ψ, sin ψ n)``, on ``[0, π]`` (the three-sphere, where ``±q`` are one rotation),
with ``σ = s/4`` (the heat kernel of the unit three-sphere: ``k² − 1`` are its Laplacian's eigenvalues)

    p(ψ) = (2/π) Σ_{k≥1} k e^{−(k²−1)σ} sin(kψ) sin ψ,                            (spectral)
    p(ψ) = e^σ ψ sin ψ e^{−ψ²/(4σ)} / (2√π σ^{3/2})  + O(e^{−π²/(4σ)}),               (small σ)

the second the leading image of the three-sphere's heat kernel (its other images are below 1e-21
for ``σ ≤ 0.05``). In ``x = ψ/√(2σ)`` the small-σ law is the χ₃ law of ``|ξ|`` (``ξ`` a standard
normal 3-vector) weighted by ``sinc(√(2σ) x)``, and its distribution function is a short series
of regularised incomplete gamma functions:

    F(x) = e^σ Σ_{m≥0} (−σ)^m / m! · P(m + 3/2, x²/2).

`heat_kernel_rotation` maps a standard normal 3-vector ``ξ`` to a rotation with exactly that law:
axis ``ξ/|ξ|``, and the half angle whose distribution function equals the χ₃ law's at ``|ξ|`` (a
quantile transform, solved by Newton's method; the last iteration differentiated, so the pathwise
derivative in ``s`` is the implicit function's). As ``s → 0`` it is the Gaussian rotation
``exp(√(2s) ξ)`` of the Euler–Maruyama scheme, and it takes the same normals: a scheme built on it
is exact in law for free isotropic diffusion at any step (the variant of Höfling & Straube,
arXiv:2403.04501, section IV, which they outline for the orientation vector on the sphere; here
for the whole orientation).
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax


# Below this σ = s/4 the leading image is the law to round-off (e^{−π²/(4σ)} < 1e-21); above, the
# spectral series needs few terms (e^{−(k²−1)σ} below round-off from k = 28 in float64).
_SMALL_SIGMA = 0.05
SMALL_STEP = 4 * _SMALL_SIGMA  # the largest D h the small-σ branch alone covers
_GAMMA_TERMS = 10  # (0.05)^m / m! < 1e-17 from m = 9
_NEWTON_SMALL = 4  # F is within O(σ) of the χ₃ law there: Newton from x = |ξ| converges in 3
_NEWTON_SPECTRAL = 12  # safeguarded (bisection when a step leaves the bracket)


def _spectral_terms(dtype) -> int:
    eps = float(jnp.finfo(dtype).eps)
    return 1 + math.ceil(math.sqrt(1 + -math.log(eps / 8) / _SMALL_SIGMA))


def _lower_gamma_three_halves(y):
    """``P(3/2, y)``, the χ₃ distribution function at ``√(2y)``, to a few ulp for all ``y ≥ 0``.

    ``erf(√y) − 2√(y/π) e^{−y}`` cancels for small ``y`` (both ``≈ 2√(y/π)``): there the series
    ``y^{3/2} e^{−y} Σ yⁿ / Γ(n + 5/2)`` is used."""
    small = y < 1
    y_small = jnp.where(small, y, 0.5)
    y_large = jnp.where(small, 1.0, y)
    series = jnp.zeros_like(y)
    for n in reversed(range(20)):  # y < 1: the terms fall below 1e-18 of the first by n = 18
        series = series * y_small + 1 / math.gamma(n + 2.5)
    root = jnp.sqrt(y_small)
    near = y_small * root * jnp.exp(-y_small) * series
    root_large = jnp.sqrt(y_large)
    far = lax.erf(root_large) - (2 / math.sqrt(math.pi)) * root_large * jnp.exp(-y_large)
    return jnp.where(small, near, far)


def _upper_gamma_three_halves(y):
    """``Q(3/2, y) = 1 − P(3/2, y) = erfc(√y) + 2√(y/π) e^{−y}``: no cancellation at any ``y``."""
    root = jnp.sqrt(y)
    return lax.erfc(root) + (2 / math.sqrt(math.pi)) * root * jnp.exp(-y)


def _along_terms(values, like):
    """Constants ``(K,)`` as ``(1, …, 1, K)``: explicit broadcasting against ``like``'s ``(…, K)`` terms."""
    return jnp.asarray(values, like.dtype).reshape((1,) * like.ndim + (-1,))


def _gamma_series(x, sigma):
    """``(F(x), 1 − F(x), F'(x))`` of the small-σ law, ``x = ψ/√(2σ)``.

    With ``w_m = (−σ)^m/m!`` and ``P(m + 3/2, y) = P(3/2, y) − Σ_{j<m} t_j`` (``Q`` with ``+``),
    ``t_j = y^{3/2+j} e^{−y} / Γ(5/2 + j)``: ``Σ_m w_m P_m = P(3/2, y) Σ_m w_m − Σ_j t_j Σ_{m>j} w_m``.
    Written over an array axis of terms, not as a recurrence: XLA would copy a recurrence's
    expression tree into each of its two uses, doubling it at every term."""
    sigma = jnp.broadcast_to(sigma, x.shape)
    y = 0.5 * x * x
    signed = _along_terms([(-1) ** k / math.factorial(k) for k in range(_GAMMA_TERMS)], x)
    powers = jnp.cumprod(jnp.broadcast_to(sigma[..., None], (*sigma.shape, _GAMMA_TERMS - 1)), axis=-1)
    weights = jnp.concatenate([jnp.ones_like(sigma)[..., None], powers], axis=-1) * signed
    tails = jnp.cumsum(weights[..., ::-1], axis=-1)[..., ::-1] - weights  # Σ_{m>j} w_m
    inverse_gammas = _along_terms([1 / math.gamma(k + 2.5) for k in range(_GAMMA_TERMS)], x)
    y_powers = jnp.cumprod(jnp.broadcast_to(y[..., None], (*y.shape, _GAMMA_TERMS - 1)), axis=-1)
    y_powers = jnp.concatenate([jnp.ones_like(y)[..., None], y_powers], axis=-1)
    lead = y * jnp.sqrt(y) * jnp.exp(-y)  # y^{3/2} e^{−y}
    correction = lead * jnp.sum(y_powers * inverse_gammas * tails, axis=-1)
    total = jnp.sum(weights, axis=-1)
    scale = jnp.exp(sigma)
    lower = scale * (_lower_gamma_three_halves(y) * total - correction)
    upper = scale * (_upper_gamma_three_halves(y) * total + correction)
    angle = jnp.sqrt(2 * sigma) * x
    safe = jnp.where(angle > 0, angle, 1.0)
    sinc = jnp.where(angle > 0, jnp.sin(safe) / safe, 1.0)
    density = scale * math.sqrt(2 / math.pi) * x * x * sinc * jnp.exp(-y)
    return lower, upper, density


def _spectral(psi, sigma, terms):
    """``(F(ψ), 1 − F(ψ), p(ψ))`` by the spectral series, ``ψ ∈ [0, π]``; the terms over an array
    axis (see `_gamma_series`), ``sin((k ± 1)ψ)`` from ``sin kψ`` and ``cos kψ``."""
    sigma = jnp.broadcast_to(sigma, psi.shape)
    s, c = jnp.sin(psi), jnp.cos(psi)
    k = _along_terms(np.arange(2, terms + 1), psi)
    weights = k * jnp.exp(-(k * k - 1) * sigma[..., None])
    angles = k * psi[..., None]
    sin_k, cos_k = jnp.sin(angles), jnp.cos(angles)
    # sin((k−1)ψ)/(k−1) − sin((k+1)ψ)/(k+1) = sin kψ cos ψ · 2/(k²−1) − cos kψ sin ψ · 2k/(k²−1)
    parts = (2 / (k * k - 1)) * (sin_k * c[..., None] - k * cos_k * s[..., None])
    series = jnp.sum(weights * parts, axis=-1)
    lower = (psi - s * c + series) / jnp.pi
    upper = (jnp.pi - psi + s * c - series) / jnp.pi
    density = (2 / jnp.pi) * (s * s + s * jnp.sum(weights * sin_k, axis=-1))
    return lower, upper, density


def _solve(residual, x0, iterations, lower, upper_bound):
    """Safeguarded Newton on an increasing ``residual(x) -> (r, r')`` in ``[lower, upper_bound]``:
    bisection wherever a step would leave the bracket. The iterations carry no derivative; one last
    Newton step from the converged point gives the implicit function's."""

    def body(_, state):
        x, lo, hi = state
        r, slope = residual(x)
        lo = jnp.where(r < 0, x, lo)
        hi = jnp.where(r > 0, x, hi)
        step = x - r / jnp.where(slope > 0, slope, 1.0)
        # Closed bracket: a converged step lands on its end (r rounds to one side), not outside.
        inside = (slope > 0) & (step >= lo) & (step <= hi)
        return jnp.where(inside, step, 0.5 * (lo + hi)), lo, hi

    start = (x0, jnp.full_like(x0, lower), jnp.broadcast_to(upper_bound, x0.shape).astype(x0.dtype))
    x, _, _ = lax.fori_loop(0, iterations, body, jax.tree_util.tree_map(lax.stop_gradient, start))
    x = lax.stop_gradient(x)
    r, slope = residual(x)
    return x - r / lax.stop_gradient(jnp.where(slope > 0, slope, 1.0))


def heat_kernel_half_angle(radius, s, large_steps: bool = True):
    """The half angle ``ψ`` ``(...)`` of an exact free-diffusion rotation at ``s = D h ≥ 0``.

    ``radius = |ξ|`` of a standard normal 3-vector; ``ψ`` has the heat kernel's law (see the module)
    and is the quantile transform of ``radius``: ``≈ √(s/2) |ξ|`` for small ``s``, 0 at ``s = 0``.
    ``large_steps=False`` (static) leaves out the spectral branch, for a caller that knows
    ``s <= 4 · 0.05`` everywhere (`SMALL_STEP`): under ``vmap`` both branches would be computed.
    """
    dtype = radius.dtype
    target_y = 0.5 * radius * radius
    use_upper = target_y > 1.2  # the χ₃ median: the tail on the far side keeps its digits
    target_lower = _lower_gamma_three_halves(target_y)
    target_upper = _upper_gamma_three_halves(target_y)
    sigma = 0.25 * s
    positive = sigma > 0
    sigma_safe = jnp.where(positive, sigma, 1.0)

    # σ <= 0.05, in x = ψ/√(2σ): the χ₃ quantile |ξ| is within O(σ) of the answer.
    small = sigma_safe <= _SMALL_SIGMA
    sigma_small = jnp.where(small, sigma_safe, _SMALL_SIGMA)

    def small_residual(x):
        lower_f, upper_f, density = _gamma_series(x, sigma_small)
        return jnp.where(use_upper, target_upper - upper_f, lower_f - target_lower), density

    x_max = jnp.pi / jnp.sqrt(2 * sigma_small)
    x = _solve(small_residual, jnp.minimum(radius, 0.999 * x_max), _NEWTON_SMALL, 0.0, x_max)
    psi_small = jnp.sqrt(2 * sigma_small) * x
    if not large_steps:
        return jnp.where(positive, psi_small, 0.0)

    # σ > 0.05, in ψ ∈ [0, π], by the spectral series.
    sigma_large = jnp.where(small, 1.0, sigma_safe)
    terms = _spectral_terms(dtype)

    def spectral_residual(psi):
        lower_f, upper_f, density = _spectral(psi, sigma_large, terms)
        return jnp.where(use_upper, target_upper - upper_f, lower_f - target_lower), density

    start = jnp.clip(jnp.sqrt(2 * sigma_large) * radius, 0.05, jnp.pi - 0.05)
    psi_large = _solve(spectral_residual, start, _NEWTON_SPECTRAL, 0.0, jnp.pi)
    psi = jnp.where(small, psi_small, psi_large)
    return jnp.where(positive, psi, 0.0)


def heat_kernel_rotation(normals, s, large_steps: bool = True):
    """A unit quaternion ``(4,)`` with the law of free isotropic diffusion at ``s = D h`` (see the module).

    ``normals`` ``(3,)``: a standard normal 3-vector (its direction is the axis); ``s ≥ 0`` scalar;
    ``large_steps`` as in `heat_kernel_half_angle`.

    Example:
        >>> import jax, jax.numpy as jnp
        >>> from jaxrot.schemes._heat_kernel import heat_kernel_rotation
        >>> xi = jax.random.normal(jax.random.key(0), (20000, 3))
        >>> q = jax.jit(jax.vmap(heat_kernel_rotation, (0, None)))(xi, 0.5)  # s = D h = 0.5
        >>> cos_angle = 2 * q[:, 0] ** 2 - 1
        >>> round(float(jnp.mean(1 + 2 * cos_angle) / 3), 2), round(float(jnp.exp(-2 * 0.5)), 2)
        (0.37, 0.37)
    """
    normals = jnp.asarray(normals)
    radius_sq = jnp.sum(normals * normals, axis=-1)
    nonzero = radius_sq > 0
    radius = jnp.sqrt(jnp.where(nonzero, radius_sq, 1.0))
    psi = heat_kernel_half_angle(jnp.where(nonzero, radius, 0.0), jnp.asarray(s, normals.dtype), large_steps)
    axis = jnp.where(nonzero[..., None], normals / radius[..., None], 0.0)
    return jnp.concatenate([jnp.cos(psi)[..., None], jnp.sin(psi)[..., None] * axis], axis=-1)
