"""Explicit Euler as in the Rockable DEM code (seed 004)."""

from typing import ClassVar

from .. import quaternion as quat
from .._inertia import body_inertia
from .._state import RotState
from ._base import AbstractScheme, body_torque


def _quaternion_rate(q, omega):
    """``Q̇ = ½ ω ⊗ Q`` for a world-frame ``ω`` (Rockable's ``quat::dot``)."""
    return 0.5 * quat.multiply(quat.pure(omega), q)


class Euler(AbstractScheme):
    r"""Rockable's explicit Euler: first order, one torque call per step.

    One step from ``(Q, ω)`` at time ``t`` (``ω`` world frame):

    1. ``ω̇ = Q (I⁻¹ (τ_b − ω_b × I ω_b)) Q*`` from the full Euler equations
       (gyroscopic term included), ``ω_b = Q* ω Q``, ``τ_b = Q* T(t, Q, ω) Q``;
    2. ``Q ← normalize(Q + Δt · ½ ω ⊗ Q)``;
    3. ``ω ← ω + Δt ω̇``.

    The renormalisation after each step is Rockable's; the scheme is only
    conditionally stable and first order, and serves as the DEM baseline. A
    velocity-driven body (`jaxrot.Drive`) moves by the same first-order formula
    with the imposed ``ω``, as in Rockable's ``velocityControlledDrive``.

    Reference:
        V. Richefeu et al., Rockable (github.com/richefeu/rockable),
        ``src/Core/Rockable.cpp`` ``EulerStep`` and the integration-scheme docs.

    Example:
        >>> import jax.numpy as jnp, jaxrot
        >>> s = jaxrot.RotState(jnp.array([1.0, 0, 0, 0]), jnp.array([0.0, 0, 1]))
        >>> s1 = jaxrot.SCHEMES["euler"].step(s, 0.0, 0.1, jnp.array([1.0, 2.0, 3.0]), None, None)
        >>> print([round(float(x), 4) for x in s1.q])
        [0.9988, 0.0, 0.0, 0.0499]
    """

    name: ClassVar[str] = "euler"
    order: ClassVar[int] = 1
    models: ClassVar[frozenset[str]] = frozenset({"vacuum"})
    torque_evals_per_step: ClassVar[int] = 1

    def step(self, carry, t, dt, inertia, torque, args):
        inertia = body_inertia(inertia)
        q, omega = carry
        omega_b = quat.rotate(quat.conjugate(q), omega)
        tau_b = body_torque(torque, t, q, omega, args)
        accel = quat.rotate(q, inertia.angular_acceleration(omega_b, tau_b))
        return RotState(self.driven_rotation(q, omega, dt), omega + dt * accel)

    def driven_rotation(self, q, omega, dt):
        return quat.normalize(q + dt * _quaternion_rate(q, omega))
