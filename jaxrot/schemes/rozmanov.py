"""Rozmanov & Kusalik (2010) quaternion velocity Verlet, as implemented in RMPCDMD."""

from typing import ClassVar, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .. import quaternion as quat
from .._inertia import body_inertia
from .._state import RotState
from ._base import AbstractScheme, world_torque


class RozmanovCarry(NamedTuple):
    """What `Rozmanov` carries between steps (one body).

    Attributes:
        state: `RotState` (``q`` body → world, world ``omega``).
        angular_momentum: world-frame ``L`` ``(3,)``.
        torque: world torque at the current state, reused by the next step.
        iterations: half-step iterations used by the last step (int32).
        max_iterations: the most iterations any step used so far.
        unconverged_steps: steps that reached ``max_iter`` without meeting ``tol``.
    """

    state: RotState
    angular_momentum: jax.Array
    torque: jax.Array
    iterations: jax.Array
    max_iterations: jax.Array
    unconverged_steps: jax.Array


def _world_omega(q, angular_momentum, inertia):
    return quat.rotate(q, inertia.solve(quat.rotate(quat.conjugate(q), angular_momentum)))


def _world_angular_momentum(q, omega, inertia):
    return quat.rotate(q, inertia.apply(quat.rotate(quat.conjugate(q), omega)))


def _world_torque(torque, t, q, omega, args):
    return jnp.zeros_like(omega) if torque is None else world_torque(torque, t, q, omega, args)


class Rozmanov(AbstractScheme):
    r"""Quaternion velocity Verlet of Rozmanov & Kusalik: second order, one torque call per step.

    The lab-frame angular momentum ``L`` is carried; ``h = Δt``; ``x^B = q* x q``.

    vv1: ``L½ = L + h/2 T(0)``. Predict ``L^B½ = L^B + h/2 (T^B − ω^B × L^B)``,
    ``q½ = normalize(q + h/2 · ½ q ⊗ (0, I⁻¹L^B½))``; then iterate
    ``ω^B = I⁻¹ (q½* L½ q½)``, ``q½ ← normalize(q + h/2 · ½ q½ ⊗ (0, ω^B))`` until
    ``|Δq½| < tol`` or ``max_iter`` iterations; ``q(h) = normalize(q + h · ½ q½ ⊗ (0, ω^B))``.
    vv2: ``T(h)`` at ``q(h)``, ``L(h) = L½ + h/2 T(h)``; ``T(h)`` is reused by the next
    step, so after the one call in `init` each step calls the torque once.

    Unlike RMPCDMD (whose loop has no cap and can hang in float32), the iteration
    runs a fixed ``max_iter`` times and freezes once converged, so it is
    differentiable with ``jax.grad``; the iterations used are in the carry
    (`RozmanovCarry`, ``rollout(..., return_carry=True)``), and an eager `rollout`
    warns when some step did not converge.

    A velocity-dependent torque is called at ``q(h)`` with the angular velocity of
    ``L½`` (the end-of-step ``ω`` needs the torque first), as in any velocity
    Verlet; such torques lose the second order.

    Args:
        max_iter: cap on half-step iterations per step.
        tol: convergence threshold on ``|Δq½|`` (4-vector 2-norm); None means
            1e-13 in float64 (RMPCDMD's value) and 1e-6 in float32.

    Reference:
        I. P. Rozmanov and P. G. Kusalik, "Robust rotational-velocity-Verlet
        integration methods", Phys. Rev. E 81, 056706 (2010); RMPCDMD
        (github.com/pdebuyl-lab/RMPCDMD) ``src/md.f90`` ``rigid_body_vv1/vv2``.

    Example:
        >>> import jax.numpy as jnp, jaxrot
        >>> s = jaxrot.RotState(jnp.array([1.0, 0, 0, 0]), jnp.array([0.3, 1.0, 0.2]))
        >>> traj, carry = jaxrot.rollout("rozmanov", s, jnp.array([1.0, 2.0, 3.0]), 0.01, 100,
        ...                              return_carry=True)
        >>> int(carry.max_iterations[0]) <= 8, int(carry.unconverged_steps[0])
        (True, 0)
    """

    name: ClassVar[str] = "rozmanov"
    order: ClassVar[int] = 2
    models: ClassVar[frozenset[str]] = frozenset({"vacuum"})
    torque_evals_per_step: ClassVar[int] = 1
    torque_evals_at_init: ClassVar[int] = 1
    max_iter: int = 8
    tol: float | None = None

    def __check_init__(self):
        if (
            isinstance(self.max_iter, bool)
            or not isinstance(self.max_iter, (int, np.integer))
            or self.max_iter < 1
        ):
            raise ValueError(f"`max_iter` must be a Python int >= 1; got {self.max_iter!r}.")
        if self.tol is not None and (
            isinstance(self.tol, bool)
            or not isinstance(self.tol, (int, float, np.floating))
            or not np.isfinite(self.tol)
            or self.tol <= 0
        ):
            raise ValueError(f"`tol` must be None or a finite float > 0; got {self.tol!r}.")

    def _tol(self, dtype):
        if self.tol is not None:
            return self.tol
        return 1e-13 if jnp.finfo(dtype).bits == 64 else 1e-6

    def init(self, state, t0, inertia, torque, args):
        inertia = body_inertia(inertia)
        q, omega = state
        angular_momentum = _world_angular_momentum(q, omega, inertia)
        zero = jnp.zeros((), jnp.int32)
        return RozmanovCarry(
            state, angular_momentum, _world_torque(torque, t0, q, omega, args), zero, zero, zero
        )

    def step(self, carry, t, dt, inertia, torque, args):
        inertia = body_inertia(inertia)
        q0 = carry.state.q
        to_body = quat.conjugate(q0)
        half = 0.5 * dt
        free = torque is None  # a torque-free body skips the (zero) kicks altogether
        l_half = carry.angular_momentum if free else carry.angular_momentum + half * carry.torque

        l_body = quat.rotate(to_body, carry.angular_momentum)
        omega_body = inertia.solve(l_body)
        l_body_rate = -jnp.cross(omega_body, l_body)
        if not free:
            l_body_rate = l_body_rate + quat.rotate(to_body, carry.torque)
        l_body_half = l_body + half * l_body_rate
        q_half = quat.normalize(q0 + half * 0.5 * quat.multiply(q0, quat.pure(inertia.solve(l_body_half))))

        def rate_at(q_h):
            omega_b = inertia.solve(quat.rotate(quat.conjugate(q_h), l_half))
            return 0.5 * quat.multiply(q_h, quat.pure(omega_b))

        tol = self._tol(q0.dtype)

        def iterate(loop, _):
            q_h, converged, count = loop
            q_new = quat.normalize(q0 + half * rate_at(q_h))
            now_converged = converged | (jnp.linalg.norm(q_new - q_h) < tol)
            # Frozen once converged: later iterations change nothing, value or gradient.
            q_h = jnp.where(converged, q_h, q_new)
            return (q_h, now_converged, count + jnp.where(converged, 0, 1).astype(jnp.int32)), None

        start = (q_half, jnp.zeros((), bool), jnp.zeros((), jnp.int32))
        (q_half, converged, count), _ = jax.lax.scan(iterate, start, None, length=self.max_iter)

        q1 = quat.normalize(q0 + dt * rate_at(q_half))
        omega_pred = _world_omega(q1, l_half, inertia)
        t1 = _world_torque(torque, t + dt, q1, omega_pred, args)
        l1 = l_half if free else l_half + half * t1
        return RozmanovCarry(
            RotState(q1, _world_omega(q1, l1, inertia)),
            l1,
            t1,
            count,
            jnp.maximum(carry.max_iterations, count),
            carry.unconverged_steps + jnp.where(converged, 0, 1).astype(jnp.int32),
        )

    def state(self, carry):
        return carry.state

    def with_state(self, carry, state, inertia):
        angular_momentum = _world_angular_momentum(state.q, state.omega, body_inertia(inertia))
        return carry._replace(state=state, angular_momentum=angular_momentum)

    def summarize(self, carry):
        return jnp.sum(carry.unconverged_steps)

    def report(self, summary):
        unconverged = int(summary)
        if unconverged == 0:
            return None
        return (
            f"rozmanov: the half-step quaternion iteration did not reach tol={self.tol or 'default'} "
            f"within max_iter={self.max_iter} on {unconverged} particle-step(s); the result is less "
            "accurate than the scheme's order promises. Raise max_iter, loosen tol, or reduce dt."
        )
