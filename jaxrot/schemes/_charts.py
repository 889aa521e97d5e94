"""Charts of the rotation group for the Lie-group Runge–Kutta schemes: ``ψ`` and ``dψ⁻¹`` on so(3) ≅ R³.

A chart ``ψ`` with ``ψ(0) = I`` and ``dψ_0 = I`` maps a rotation vector ``Θ`` to a rotation; a
Lie-group Runge–Kutta method keeps its tableau's order with any such chart and its inverse
differential ``dψ⁻¹`` (Iserles, Munthe-Kaas, Nørsett and Zanna, Acta Numerica 9 (2000), section 8).
"""

import jax.numpy as jnp

from .._core._math import taylor_threshold
from .._core._trig import sincos
from ..quaternion import cayley


def exp_and_dexpinv(theta, w):
    """``(exp(Θ), dexp⁻¹_Θ(w))`` for a rotation vector ``Θ`` ``(3,)`` and ``w`` ``(3,)``.

    ``exp(Θ)`` is the unit quaternion of the rotation vector (as `jaxrot.quaternion.exp`)
    and ``dexp⁻¹_Θ(w) = w − ½ Θ × w + c(θ) Θ × (Θ × w)`` with ``θ = |Θ|`` and
    ``c(θ) = (1 − (θ/2) cot(θ/2)) / θ²``. One sine–cosine pair serves both. Below
    ``θ² < √eps`` both use their Taylor series behind a double ``where``, so values
    and gradients are finite and exact at ``Θ = 0``.

    Example:
        >>> import jax.numpy as jnp
        >>> q, v = exp_and_dexpinv(jnp.zeros(3), jnp.array([1.0, 2.0, 3.0]))
        >>> q.tolist(), v.tolist()
        ([1.0, 0.0, 0.0, 0.0], [1.0, 2.0, 3.0])
    """
    rotation, c = _exp_and_coefficient(theta)
    return rotation, _dexpinv(theta, c, w)


def _exp_and_coefficient(theta):
    """``exp(Θ)`` ``(4,)`` and the scalar ``c(θ)`` of `dexp⁻¹`, from one sine–cosine pair."""
    theta_sq = jnp.sum(theta * theta)
    small = theta_sq < taylor_threshold(theta.dtype)
    angle = jnp.sqrt(jnp.where(small, 1, theta_sq))
    sin_half, cos_half = sincos(0.5 * angle)
    real = jnp.where(small, 1 - theta_sq / 8 + theta_sq**2 / 384, cos_half)
    imag = jnp.where(small, 0.5 - theta_sq / 48 + theta_sq**2 / 3840, sin_half / angle)
    # 1 − x cot x loses digits as x → 0, but it is divided by θ² and multiplies a term of size
    # θ² |w|: its absolute error stays ~eps |w| down to the Taylor switch.
    safe_sin = jnp.where(small, 1, sin_half)
    c = jnp.where(small, 1 / 12 + theta_sq / 720, (1 - 0.5 * angle * cos_half / safe_sin) / angle**2)
    return jnp.concatenate([real[None], imag * theta]), c


def _dexpinv(theta, c, w):
    theta_cross_w = jnp.cross(theta, w)
    return w - 0.5 * theta_cross_w + c * jnp.cross(theta, theta_cross_w)


def cayley_and_dcayinv(theta, w):
    """``(cay(Θ), dcay⁻¹_Θ(w))``: the Cayley chart's counterpart of `exp_and_dexpinv`.

    ``cay(Θ)`` is `jaxrot.quaternion.cayley` and ``dcay⁻¹_Θ(w) = w − ½ Θ × w + ¼ Θ (Θ · w)``
    (Iserles, Munthe-Kaas, Nørsett and Zanna, Acta Numerica 9 (2000), section 8.3),
    computed as ``(1 + |Θ|²/4) w − ½ Θ × w + ¼ Θ × (Θ × w)``. Polynomial but for one
    reciprocal square root: finite and exact in value and gradient at any ``Θ``.

    Example:
        >>> import jax.numpy as jnp
        >>> q, v = cayley_and_dcayinv(jnp.zeros(3), jnp.array([1.0, 2.0, 3.0]))
        >>> q.tolist(), v.tolist()
        ([1.0, 0.0, 0.0, 0.0], [1.0, 2.0, 3.0])
    """
    rotation, quarter_sq = _cayley_and_coefficient(theta)
    return rotation, _dcayinv(theta, quarter_sq, w)


def _cayley_and_coefficient(theta):
    """``cay(Θ)`` ``(4,)`` and ``|Θ|²/4``, which `_dcayinv` reuses."""
    half = 0.5 * theta  # |Θ/2|², the expression `cayley` computes: XLA merges the two
    return cayley(theta), jnp.sum(half * half)


def _dcayinv(theta, quarter_sq, w):
    # Θ (Θ · w) written with cross products: a dot product broadcast back over the components
    # made XLA:CPU's RKMK-Dopri8 step 2.5x slower (measured), the cross form 1.5x faster than exp.
    theta_cross_w = jnp.cross(theta, w)
    return (1 + quarter_sq) * w - 0.5 * theta_cross_w + 0.25 * jnp.cross(theta, theta_cross_w)


# The charts of so(3) a scheme can use: (chart and the scalar its inverse differential reuses, the
# inverse differential). Any chart ψ with ψ(0) = I and dψ_0 = I keeps the tableau's order.
CHARTS = {
    "cayley": (_cayley_and_coefficient, _dcayinv),
    "exp": (_exp_and_coefficient, _dexpinv),
}
