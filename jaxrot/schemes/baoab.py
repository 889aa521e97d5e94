"""BAOAB: the Langevin splitting over the exact free rotor and the exact Ornstein–Uhlenbeck step."""

from typing import ClassVar

import equinox as eqx

from .. import quaternion as quat
from .._free_body._rotor import free_rotor
from .._state import RotState
from ._base import world_torque
from ._langevin import AbstractLangevinScheme, LangevinCarry, body_flow_rotation, kick
from ._ou import spin_relaxation


class BAOAB(AbstractLangevinScheme):
    r"""BAOAB on the rotation group: weak order 2, one torque call per step, any ``ζΔt/I``.

    One step from ``(q, ω)`` at ``t``, with ``τ`` the applied torque carried from the last step:

    1. B: half kick, world ``L += Δt/2 · τ``;
    2. A: free rotation over ``Δt/2`` by the exact rotor (`jaxrot._free_body._rotor.free_rotor`,
       the preprocessed discrete Moser–Veselov map: exact to round-off);
    3. O: the spin's exact Ornstein–Uhlenbeck flow over ``Δt`` at fixed orientation, about each
       principal axis (`jaxrot.schemes._ou.spin_relaxation`): relaxed towards the flow's rotation at
       ``exp(−ζ_k Δt / I_k)`` with the noise that keeps ``⟨I_k ω_k²⟩ = kT``;
    4. A: free rotation over ``Δt/2``;
    5. B: ``τ₁ = T(t + Δt, q₁, ω̃)`` (``ω̃`` after a predictor half kick by ``τ``, so that a torque
       that depends on ``ω`` sees an ``O(Δt²)``-accurate velocity), half kick by ``τ₁``; ``τ₁`` is
       carried.

    A symmetric splitting of the generator, so weak order 2 for ensemble averages at a fixed time
    and for the stationary law (Leimkuhler & Matthews); the free rotor and the O step preserve the
    Maxwell law exactly, so a torque-free body keeps ``⟨I_k ω_k²⟩ = kT`` at any step. ``|q| = 1`` to
    round-off (the rotor's unit quaternions). Stable at any ``ζΔt/I``, but the A steps move the
    body with its inertial spin: when ``ζΔt/I ≫ 1`` the orientation diffuses at a wrong rate
    (a factor ``≈ ζΔt/(4I)``), as every Langevin splitting does; there take `ExpEuler` (exact in
    that limit) or `jaxrot.overdamped_rollout`. This is the ordering of `jax_md`'s rigid-body
    ``nvt_langevin``, with the exact rotor instead of NO_SQUISH's splitting of it.

    References:
        R. L. Davidchack, T. E. Ouldridge and M. V. Tretyakov, "New Langevin and gradient thermostats
        for rigid body dynamics", J. Chem. Phys. 142, 144114 (2015), arXiv:1412.5813;
        B. Leimkuhler and C. Matthews, "Rational construction of stochastic numerical methods for
        molecular sampling", Appl. Math. Res. Express 2013, 34–56.

    Example:
        >>> import jax, jax.numpy as jnp, jaxrot
        >>> fluid = jaxrot.Fluid(jnp.array([2.0, 2.0, 2.0]), kT=0.5)
        >>> q0 = jnp.tile(jnp.array([1.0, 0, 0, 0]), (4000, 1))
        >>> s = jaxrot.RotState(q0, jnp.zeros((4000, 3)))  # at rest: kT/I_k per axis after 1/ζ
        >>> inertia = jnp.array([1.0, 2.0, 3.0])
        >>> traj = jaxrot.rollout("baoab", s, inertia, 0.2, 20, fluid=fluid, key=jax.random.key(0),
        ...                       save_every=20)
        >>> spin = jaxrot.quaternion.rotate(jaxrot.quaternion.conjugate(traj.q[-1]), traj.omega[-1])
        >>> [round(float(e), 1) for e in inertia * jnp.mean(spin**2, axis=0)]  # kT on every axis
        [0.5, 0.5, 0.5]
    """

    name: ClassVar[str] = "baoab"
    order: ClassVar[int] = 2
    models: ClassVar[frozenset[str]] = frozenset({"thermal"})
    torque_evals_per_step: ClassVar[int] = 1
    torque_evals_at_init: ClassVar[int] = 1
    normals_per_step: ClassVar[int] = 3
    rotor_substeps: int | None = eqx.field(default=None, static=True)

    def initial_torque(self, t0, state, torque, args):
        return None if torque is None else world_torque(torque, t0, *state, args)

    def _rotate_freely(self, q, omega, moments, t):
        return free_rotor(q, omega, moments, t, substeps=self.rotor_substeps)

    def advance(self, carry, t, dt, inertia, torque, args, fluid, normals):
        (q, omega), tau, step = carry
        moments = inertia.tensor
        half = 0.5 * dt
        if torque is not None:
            omega = omega + kick(q, moments, half * tau)
        q, omega = self._rotate_freely(q, omega, moments, half)
        spin = quat.rotate(quat.conjugate(q), omega)
        spin = spin_relaxation(
            spin, body_flow_rotation(q, fluid), fluid.friction, moments, fluid.kT, dt, normals
        )
        q, omega = self._rotate_freely(q, quat.rotate(q, spin), moments, half)
        tau1 = None
        if torque is not None:
            predicted = omega + kick(q, moments, half * tau)
            tau1 = world_torque(torque, t + dt, q, predicted, args)
            omega = omega + kick(q, moments, half * tau1)
        return LangevinCarry(RotState(q, omega), tau1, step + 1)
