"""Dense output on the rotation group for the solvers of `jaxrot.solver`.

Within a step from ``(q0, L0)`` at ``t0`` to ``(q1, L1)`` at ``t1`` the orientation is
``q(t) = ψ(Θ(t)) ⊗ q0`` (``ψ`` the exponential, or the Cayley map of the RKMK schemes)
with ``Θ`` interpolated in the Lie algebra so(3) ≅ R³
(``Θ(t0) = 0``, ``Θ(t1) = Θ1``), so every interpolated ``q`` is a unit quaternion;
the world angular momentum ``L(t)`` is interpolated in R³ and
``ω(t) = R(t) I⁻¹ R(t)ᵀ L(t)``. Two interpolants of ``(Θ, L)``:

- **from the stages** of a Lie-group Runge–Kutta pair whose diffrax solver has a
  dense output (`rkmk_dopri5`: diffrax's `Dopri5` interpolant, order 4, local error
  O(h⁵); `rkmk_dopri8`: diffrax's `Dopri8` interpolant, order 7, local error O(h⁸)).
  RKMK is an ordinary RK method for ``Θ`` in the algebra, so the classical continuous
  extension applies there unchanged.
- **Hermite** for every other scheme: ``Θ`` cubic Hermite from the end slopes
  ``Θ̇(t0) = ω0`` and ``Θ̇(t1) = dexp⁻¹_{Θ1}(ω1)`` (local error O(h⁴)), ``L`` linear
  (local error O(h²) under a torque, exact for a free body, whose ``L`` is constant).
"""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp

from .. import quaternion as quat
from .._state import RotState


class GroupInterpolation(diffrax.AbstractLocalInterpolation):
    """``RotState(q(t), ω(t))`` inside one step, with ``q(t)`` on the unit sphere.

    Attributes:
        t0, t1: the step's start and end times.
        q0: orientation at ``t0`` ``(..., 4)``.
        rotation: interpolant of the rotation vector ``Θ(t)`` ``(..., 3)``, zero at ``t0``.
        momentum: interpolant of the world angular momentum ``L(t)`` ``(..., 3)``.
        inverse_inertia: body-frame ``I⁻¹`` as ``(..., 3, 3)`` matrices.
        chart: ``"exp"`` or ``"cayley"``: the map from ``Θ`` to the rotation, the one
            the step's ``Θ`` was built for (`jaxrot.schemes.AbstractLieRungeKutta.chart`).
    """

    t0: jax.Array
    t1: jax.Array
    q0: jax.Array
    rotation: diffrax.AbstractLocalInterpolation
    momentum: diffrax.AbstractLocalInterpolation
    inverse_inertia: jax.Array
    chart: str = eqx.field(default="exp", static=True)

    def evaluate(self, t0, t1=None, left=True):
        del left
        if t1 is not None:  # an increment; a difference of two states is all diffrax asks for
            return jax.tree_util.tree_map(lambda a, b: a - b, self.evaluate(t1), self.evaluate(t0))
        chart = quat.cayley if self.chart == "cayley" else quat.exp
        q = quat.normalize(quat.multiply(chart(self.rotation.evaluate(t0)), self.q0))
        momentum_body = quat.rotate(quat.conjugate(q), self.momentum.evaluate(t0))
        omega_body = jnp.einsum("...ij,...j->...i", self.inverse_inertia, momentum_body)
        return RotState(q, quat.rotate(q, omega_body))


def hermite_interpolation(*, t0, t1, q0, theta1, theta_slopes, momentum0, momentum1, inverse_inertia):
    """`GroupInterpolation` with cubic Hermite ``Θ`` and linear ``L`` (any scheme).

    ``theta_slopes`` ``(2, ..., 3)``: ``h ω0`` and ``h dexp⁻¹_{Θ1}(ω1)``, the increments of
    ``Θ`` per unit of normalised time at the two ends."""
    rotation = diffrax.ThirdOrderHermitePolynomialInterpolation.from_k(
        t0=t0, t1=t1, y0=jnp.zeros_like(theta1), y1=theta1, k=theta_slopes
    )
    momentum = diffrax.LocalLinearInterpolation(t0=t0, t1=t1, y0=momentum0, y1=momentum1)
    return GroupInterpolation(t0, t1, q0, rotation, momentum, inverse_inertia)


def stage_interpolation(
    algebra_interpolation,
    *,
    t0,
    t1,
    q0,
    theta1,
    theta_stages,
    momentum0,
    momentum1,
    momentum_stages,
    inverse_inertia,
    chart="exp",
):
    """`GroupInterpolation` from a Runge–Kutta pair's own continuous extension, applied in the algebra.

    ``algebra_interpolation`` is the diffrax solver's ``interpolation_cls`` (e.g.
    ``diffrax.Dopri5.interpolation_cls``); ``theta_stages`` and ``momentum_stages``
    ``(s, ..., 3)`` are the step's stage increments ``h K_i`` and ``h T_i``, in the
    scheme's ``chart``."""
    rotation = algebra_interpolation(t0=t0, t1=t1, y0=jnp.zeros_like(theta1), y1=theta1, k=theta_stages)
    momentum = algebra_interpolation(t0=t0, t1=t1, y0=momentum0, y1=momentum1, k=momentum_stages)
    return GroupInterpolation(t0, t1, q0, rotation, momentum, inverse_inertia, chart)
