"""NO_SQUISH (Miller et al. 2002): the symplectic splitting of jax_md, HOOMD-blue and LAMMPS."""

from typing import ClassVar, NamedTuple

import jax
import jax.numpy as jnp

from .. import quaternion as quat
from .._core._fusion import stage
from .._core._trig import sincos
from .._free_body._principal_axes import principal_axes
from .._inertia import BodyInertia, body_inertia
from .._state import RotState
from ._base import AbstractScheme, world_torque


class NoSquishCarry(NamedTuple):
    """What `NoSquish` carries between steps (one body), in the principal frame.

    Attributes:
        q_principal: principal-axes → world quaternion ``(4,)``.
        momentum: conjugate quaternion momentum ``p = 2 q ⊗ (0, I ω_p)`` ``(4,)``.
        torque: world torque at the current state, reused by the next step.
        moments: principal moments ``(3,)``.
        principal_to_body: quaternion of the principal axes in the body frame
            ``(4,)``, or None when the inertia is already diagonal.
        state: `RotState` in the user's body frame.
    """

    q_principal: jax.Array
    momentum: jax.Array
    torque: jax.Array
    moments: jax.Array
    principal_to_body: jax.Array | None
    state: RotState


def _permute(k, x):
    """Miller's ``P_k`` (k = 1, 2, 3): ``P_k q = q ⊗ e_k`` for the unit pure quaternion ``e_k``."""
    w, a, b, c = x[0], x[1], x[2], x[3]
    rows = {
        1: (-a, w, c, -b),
        2: (-b, -c, w, a),
        3: (-c, b, -a, w),
    }[k]
    return jnp.stack(rows)


def _inverse_moments(moments):
    """``1/I_k``, and 0 for ``I_k = 0`` (HOOMD/LAMMPS guard: that axis carries no rotation)."""
    positive = moments > 0
    return jnp.where(positive, 1 / jnp.where(positive, moments, 1), 0)


def _free_rotor(k, delta, q, p, inv_moments):
    """Exact rotation about principal axis k for time ``delta``: ``ζ = δ (p·P_k q) / (4 I_k)``."""
    pk_q = _permute(k, q)
    # An explicit sum, not jnp.dot: XLA:CPU fuses a reduction with its whole producer chain.
    zeta = (
        delta * (p[0] * pk_q[0] + p[1] * pk_q[1] + p[2] * pk_q[2] + p[3] * pk_q[3]) * inv_moments[k - 1] / 4
    )
    # x ← cos ζ x + sin ζ P_k x, written as x + (small increment) with cos ζ − 1 = −2 sin²(ζ/2):
    # the O(1) part is not re-rounded each substep (float32 drift on the heavy top measured 14× lower).
    # One sine–cosine pair of ζ/2 gives both (sin ζ = 2 sin(ζ/2) cos(ζ/2)).
    sin_half, cos_half = stage(*sincos(0.5 * zeta))
    sin, cos_minus_one = 2 * sin_half * cos_half, -2 * sin_half * sin_half
    return stage(q + (cos_minus_one * q + sin * pk_q), p + (cos_minus_one * p + sin * _permute(k, p)))


def _principal_frame(inertia: BodyInertia):
    """Principal moments and principal → body quaternion (None for diagonal inertia)."""
    if inertia.is_diagonal:
        return inertia.tensor, None
    return principal_axes(inertia.tensor)


class NoSquish(AbstractScheme):
    r"""Symplectic, time-reversible splitting of Miller et al.: second order, one torque call per step.

    The state is the principal-frame quaternion ``q`` and its conjugate momentum
    ``p = 2 q ⊗ (0, I ω_p)`` (4-vectors). One step:

    1. half kick ``p += (Δt/2) · 2 q ⊗ (0, τ_p)`` (``τ_p`` torque in the principal frame);
    2. free rotor ``R3(Δt/2) R2(Δt/2) R1(Δt) R2(Δt/2) R3(Δt/2)``, each
       ``R_k(δ)``: ``ζ = δ (p·P_k q)/(4 I_k)``, ``q ← cos ζ q + sin ζ P_k q``,
       ``p ← cos ζ p + sin ζ P_k p`` (exact rotations: ``|q|`` is preserved; it is
       renormalised against round-off, as in HOOMD-blue);
    3. torque at the new orientation (reused by the next step's first kick);
    4. half kick.

    A full inertia tensor is diagonalised once (in `init`) and the scheme runs in
    the principal frame (``q_p = q ⊗ r``); its gradient with respect to a full
    tensor is undefined for a symmetric body (repeated eigenvalues), as for any
    eigendecomposition. A principal moment equal to zero is guarded as in HOOMD
    and LAMMPS: that axis neither rotates nor takes torque (`jaxrot.rollout`
    still rejects it as non-physical; the guard serves traced inputs).

    A velocity-dependent torque is called with the half-kicked ``ω``, as in any
    velocity Verlet; such torques lose the second order.

    Reference:
        T. F. Miller III, M. Eleftheriou, P. Pattnaik, A. Ndirango, D. Newns and
        G. J. Martyna, "Symplectic quaternion scheme for biophysical molecular
        dynamics", J. Chem. Phys. 116, 8649 (2002). As in jax_md
        ``rigid_body.py``, HOOMD-blue ``TwoStepConstantVolume`` and LAMMPS
        ``MathExtra::no_squish_rotate``.

    Example:
        >>> import jax.numpy as jnp, jaxrot
        >>> s = jaxrot.RotState(jnp.array([1.0, 0, 0, 0]), jnp.array([0.3, 1.0, 0.2]))
        >>> traj = jaxrot.rollout("no_squish", s, jnp.array([1.0, 2.0, 3.0]), 0.01, 100)
        >>> print(abs(float(jnp.linalg.norm(traj.q[-1])) - 1) < 1e-6)
        True
    """

    name: ClassVar[str] = "no_squish"
    order: ClassVar[int] = 2
    models: ClassVar[frozenset[str]] = frozenset({"vacuum"})
    torque_evals_per_step: ClassVar[int] = 1
    torque_evals_at_init: ClassVar[int] = 1

    def init(self, state, t0, inertia, torque, args):
        inertia = body_inertia(inertia)
        moments, principal_to_body = _principal_frame(inertia)
        q, omega = state
        torque_world = jnp.zeros_like(omega) if torque is None else world_torque(torque, t0, q, omega, args)
        return self._carry(state, moments, principal_to_body, torque_world)

    @staticmethod
    def _carry(state, moments, principal_to_body, torque_world):
        q, omega = state
        q_p = q if principal_to_body is None else quat.multiply(q, principal_to_body)
        l_p = moments * quat.rotate(quat.conjugate(q_p), omega)
        momentum = 2 * quat.multiply(q_p, quat.pure(l_p))
        return NoSquishCarry(q_p, momentum, torque_world, moments, principal_to_body, state)

    @staticmethod
    def _kick(q_p, p, torque_world, moments, duration):
        """``p += duration · ṗ`` with ``ṗ = 2 q ⊗ (0, τ_p)``; no torque on a massless axis."""
        tau_p = quat.rotate(quat.conjugate(q_p), torque_world)
        tau_p = jnp.where(moments > 0, tau_p, 0)
        return p + (2 * duration) * quat.multiply(q_p, quat.pure(tau_p))

    @staticmethod
    def _state(q_p, p, moments, principal_to_body):
        l_p = 0.5 * quat.multiply(quat.conjugate(q_p), p)[1:]
        omega = quat.rotate(q_p, l_p * _inverse_moments(moments))
        q = q_p if principal_to_body is None else quat.multiply(q_p, quat.conjugate(principal_to_body))
        return RotState(q, omega)

    def step(self, carry, t, dt, inertia, torque, args):
        moments, r = carry.moments, carry.principal_to_body
        inv_moments = _inverse_moments(moments)
        half = 0.5 * dt
        # Stage boundaries (`jaxrot._core._fusion`): see `_free_rotor`.
        q, p = (
            carry.q_principal,
            stage(self._kick(carry.q_principal, carry.momentum, carry.torque, moments, half)),
        )
        for k, delta in ((3, half), (2, half), (1, dt), (2, half), (3, half)):
            q, p = _free_rotor(k, delta, q, p, inv_moments)
        q = stage(quat.normalize(q))  # against round-off only, as HOOMD-blue does
        if torque is None:
            torque_world = carry.torque
        else:
            end = self._state(q, p, moments, r)
            torque_world = stage(world_torque(torque, t + dt, end.q, end.omega, args))
        p = self._kick(q, p, torque_world, moments, half)
        return NoSquishCarry(q, p, torque_world, moments, r, self._state(q, p, moments, r))

    def state(self, carry):
        return carry.state

    def with_state(self, carry, state, inertia):
        return self._carry(state, carry.moments, carry.principal_to_body, carry.torque)
