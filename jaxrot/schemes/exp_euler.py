"""ExpEuler: the exponential Euler scheme of the rotational Langevin equation, exact for its linear part."""

from typing import ClassVar

from .. import quaternion as quat
from .._state import RotState
from ._base import world_torque
from ._langevin import AbstractLangevinScheme, LangevinCarry, body_flow_rotation
from ._ou import integrated_spin


class ExpEuler(AbstractLangevinScheme):
    r"""The stochastic exponential Euler scheme: weak order 1, one torque call per step, uniform in ``ζΔt/I``.

    With the applied torque frozen at the start of the step, each principal axis's spin is an
    Ornstein–Uhlenbeck process around the slow velocity ``S = g(q) + ζ⁻¹ ⊙ τ_b``, and the spin together
    with the angle it turns through is Gaussian with a known mean and covariance
    (`jaxrot.schemes._ou.integrated_spin`): the step draws both, exactly, and turns the body by that
    angle, ``q₁ = q ⊗ exp(θ)``. The gyroscopic term ``−u × I u`` is the turning of the body frame
    under a momentum fixed in the world: the momentum ``I u₁`` drawn in the frame of ``q`` is read in
    the frame of ``q₁``, ``u₁ ← I⁻¹ exp(θ)ᵀ I u₁``, a rotation of it. (Frozen into ``S`` as
    ``−ζ⁻¹ u × I u``, as before, an explicit quadratic term, thermal spins of a triaxial body ran
    away: 1 of 4000 dipoles at ``ζ = 1``, ``I = (1, 2, 3)``, ``Δt = 0.5`` reached 1e50.)

    Stability with a torque: linearised about a minimum of stiffness ``K = |∂τ/∂θ|`` the step is
    stable for ``K Δt / ζ ≤ 2`` at every ``ζΔt/I`` (the overdamped Euler step's limit; a little more
    for ``ζΔt/I`` between 0.1 and 30; ``ζ`` the smallest friction), and a bounded torque (a dipole
    in a field) never makes it non-finite, only inaccurate beyond that step. So the friction's
    relaxation and the noise it balances are exact at any ``ζΔt/I``: as ``ζΔt/I → ∞`` the step
    becomes the geometric Euler–Maruyama step of the overdamped model (`jaxrot.overdamped_rollout`'s
    ``"brownian_euler"``), with the right diffusion ``kT/ζ``, where a Langevin splitting
    (`BAOAB`) would diffuse too fast. Without a temperature it is the exponential Euler method
    (Hochbruck & Ostermann, Acta Numerica 19, 209 (2010)), order 1. Cheap: no rotor, six normals.
    ``|q| = 1`` to round-off (normalised after each step).

    Reference:
        W. F. van Gunsteren and H. J. C. Berendsen, "Algorithms for Brownian dynamics", Mol. Phys. 45,
        637 (1982) (the joint Gaussian of velocity and displacement, for translation);
        M. Hochbruck and A. Ostermann, "Exponential integrators", Acta Numerica 19, 209–286 (2010).

    Example:
        >>> import jax, jax.numpy as jnp, jaxrot
        >>> fluid = jaxrot.Fluid(jnp.array([1e3, 1e3, 1e3]), kT=100.0)  # ζΔt/I = 100: overdamped
        >>> s = jaxrot.RotState(jnp.tile(jnp.array([1.0, 0, 0, 0]), (4000, 1)), jnp.zeros((4000, 3)))
        >>> traj = jaxrot.rollout("exp_euler", s, jnp.ones(3), 0.1, 10, fluid=fluid,
        ...                       key=jax.random.key(1), save_every=10)
        >>> axis = jaxrot.quaternion.rotate(traj.q[-1], jnp.array([0.0, 0, 1]))
        >>> D = 100.0 / 1e3  # kT / ζ: ⟨u(t)·u(0)⟩ = exp(−2 D t), 0.819 at t = 1 (± 0.005 here)
        >>> bool(abs(axis[:, 2].mean() - jnp.exp(-2 * D)) < 0.02)
        True
    """

    name: ClassVar[str] = "exp_euler"
    order: ClassVar[int] = 1
    models: ClassVar[frozenset[str]] = frozenset({"fluid", "thermal"})
    torque_evals_per_step: ClassVar[int] = 1
    normals_per_step: ClassVar[int] = 6

    def advance(self, carry, t, dt, inertia, torque, args, fluid, normals):
        (q, omega), _, step = carry
        moments = inertia.tensor
        spin = quat.rotate(quat.conjugate(q), omega)
        slow = body_flow_rotation(q, fluid)
        if torque is not None:
            torque_body = quat.rotate(quat.conjugate(q), world_torque(torque, t, q, omega, args))
            slow = slow + torque_body / fluid.friction
        spin, theta = integrated_spin(spin, slow, fluid.friction, moments, fluid.kT, dt, normals)
        turn = quat.exp(theta)
        # The gyroscopic term is the frame's turn: the momentum I u, kept in the world, read in the new
        # body frame (a rotation: |I u| is kept, so no spin can run away).
        spin = quat.rotate(quat.conjugate(turn), moments * spin) / moments
        q1 = quat.normalize(quat.multiply(q, turn))
        return LangevinCarry(RotState(q1, quat.rotate(q1, spin)), None, step + 1)
