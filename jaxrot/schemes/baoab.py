"""BAOAB: the Langevin splitting over the exact free rotor and the exact Ornstein–Uhlenbeck step."""

from typing import ClassVar, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jax import lax

from .. import quaternion as quat
from .._core._fusion import stage
from .._free_body._rotor import free_rotor
from .._state import RotState
from ._base import world_torque
from ._langevin import AbstractLangevinScheme, LangevinCarry, body_flow_rotation, kick
from ._ou import Relaxation, bridge_spread, drift_factor, noise_scale, relax, relaxation_weights


# Both A steps through one traced rotor (a loop of two iterations), not two copies: the rotor is about
# half of a step's program (3.4k of 12.6k HLO instructions each, `benchmarks/baoab_one_rotor.py`), so
# jax_md's 1000-step loop compiled in 10.5 s instead of 13.4 s (7,981 instructions) at the same step
# speed (CPU time 1.00x free bodies, 0.98x interacting, float64). False: the two copies, for that A/B.
_ONE_ROTOR = True


class BAOAB(AbstractLangevinScheme):
    r"""BAOAB on the rotation group: weak order 2, one torque call per step, right at any ``ζΔt/I``.

    One step from ``(q, ω)`` at ``t``, with ``τ`` the applied torque carried from the last step, and per
    principal axis ``x_k = ζ_k Δt / I_k``, ``c_k = (Δt/2) f(x_k)``, ``f(x) = tanh(x/2)/(x/2)``
    (`jaxrot.schemes._ou.drift_factor`: 1 at ``x = 0``, ``2/x`` far out):

    1. B: kick ``u += (2 − f) ⊙ I⁻¹ τ_b Δt/2`` (body frame; with the ``f ⊙`` part of the last step's
       kick, which is in the returned ``ω``, a whole ``I⁻¹ τ_b Δt`` since the last A);
    2. A: free rotation by the exact rotor (`jaxrot._free_body._rotor.free_rotor`, the preprocessed
       discrete Moser–Veselov map) over ``s = min_k c_k``, after a turn ``q ⊗ exp((c − s) ⊙ u)``;
    3. O: the spin's exact Ornstein–Uhlenbeck flow over ``Δt`` towards the flow's rotation ``S``
       (`jaxrot.schemes._ou.spin_relaxation`), and the turn ``q ⊗ exp((Δt − 2c) ⊙ S + a Δt √W ⊙ ξ₂)``;
    4. A: the rotor over ``s``, then the turn ``q ⊗ exp((c − s) ⊙ u)``;
    5. B: ``τ₁ = T(t + Δt, q₁, ω̃)`` with ``ω̃ = u + f ⊙ I⁻¹ τ_b Δt/2`` (for a torque that depends on
       ``ω``), and the returned ``ω₁ = u + f ⊙ I⁻¹ τ₁,b Δt/2``; ``τ₁`` is carried.

    Why the A steps move by ``c``, not ``Δt/2``: for the linear OU process of a spin about an axis,
    the angle turned over the step is Gaussian given the spins at both ends, with mean
    ``(Δt − 2c) S + c (u₀ + u₁)`` and variance ``(a Δt)² W(x)`` (`jaxrot.schemes._ou`; ``a = √(kT ζ Δt)/I``).
    So A(c) O A(c) plus that turn is the exact A+O flow of a sphere, at any ``x``. At ``x = 0`` it is
    BAOAB's A(Δt/2) O A(Δt/2) (``c = Δt/2``, the turn vanishes), and for small ``x`` it differs
    from it by ``O(x²Δt)``: weak order 2 is kept. As ``x → ∞`` the A steps turn by ``(I/ζ) u``, the
    inertial spin's true share (``√(kT I)/ζ``, vanishing with ``I``), and the middle turn carries the
    Brownian displacement ``N(S Δt, 2 kT Δt/ζ)`` and, with step 1's kick, the drift ``τ Δt/ζ``: the
    step tends to the geometric Euler–Maruyama step of the overdamped model, with the right
    diffusion. Textbook BAOAB (A over ``Δt/2``) turns the body by ``√(kT/I) Δt/2`` there (tens of
    radians for a micron particle), diffuses ``ζΔt/(4I)`` times too fast, and its rotor runs out of
    range. The returned ``ω`` carries ``f`` of the last half kick and ``(1 − f) (S(q₁) − S(q_½))``
    (the O step relaxed the spin to the flow's rotation at the midpoint): BAOAB's at ``x = 0`` (both
    differ from it by ``O(x²Δt)``), the overdamped velocity ``S(q₁) + ζ⁻¹ τ_b(q₁)`` (within
    ``O(√(kT/I))`` noise) at ``x → ∞``.

    Exact properties kept: the rotor (over any time ``s``) and the O step preserve the Maxwell law,
    and the extra turns move ``q`` alone, so a torque-free body in a fluid at rest keeps
    ``⟨I_k ω_k²⟩ = kT`` at any step; where ``x`` is equal on all axes (``ζ ∝ I``) the turns
    ``(c − s) ⊙ u`` vanish and the world angular momentum of a torque-free body is the exact OU
    process. ``|q| = 1`` to round-off. With a torque the kicks are explicit: linearised about a
    minimum of stiffness ``K = |∂τ/∂θ|``, the step is stable while ``K Δt²/I ≤ 4`` (velocity Verlet's
    limit) or ``K Δt/ζ ≤ 2`` (the overdamped Euler step's), at every ``x`` (checked on a grid of
    ``x`` from 1e-4 to 1e7; `tests/test_thermal_stiffness.py` runs both sides of each edge).
    This is the ordering of `jax_md`'s rigid-body ``nvt_langevin``, with the exact rotor instead of
    NO_SQUISH's splitting of it.

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
    models: ClassVar[frozenset[str]] = frozenset({"fluid", "thermal"})
    torque_evals_per_step: ClassVar[int] = 1
    torque_evals_at_init: ClassVar[int] = 1
    normals_per_step: ClassVar[int] = 6
    rotor_substeps: int | None = eqx.field(default=None, static=True)

    def initial_torque(self, t0, state, torque, args):
        return None if torque is None else world_torque(torque, t0, *state, args)

    @staticmethod
    def _turn(q, omega, extra):
        """The turn ``q ⊗ exp(extra ⊙ u)`` (``u = R(q)ᵀ ω``, body frame) that moves an A step by ``c``."""
        return quat.multiply(q, quat.exp(extra * quat.rotate(quat.conjugate(q), omega)))

    def _drift(self, q, omega, moments, s, extra, first):
        """A: the rotor over ``s`` and the turn ``q ⊗ exp(extra ⊙ u)``, the turn first when ``first``."""
        if first:
            q = self._turn(q, omega, extra)
        q, omega = free_rotor(q, omega, moments, s, substeps=self.rotor_substeps)
        return (self._turn(q, omega, extra) if not first else q), omega

    def weights(self, friction, moments, kT, dt, noise: bool) -> "BAOABWeights":
        """The step's weights, per principal axis: functions of ``ζΔt/I``, ``kT`` and ``Δt`` alone.

        Staged (`jaxrot._core._fusion.stage`): computed once and kept, so where ``ζ``, ``I``, ``kT``
        and ``Δt`` are shared by the bodies (unbatched under `jax.vmap`) the φ-functions run once
        per step, not once per body (XLA would otherwise fuse them into each body's arithmetic)."""
        x = friction / moments * dt
        f = drift_factor(x)
        c = 0.5 * dt * f
        s = jnp.min(c)
        relaxation = relaxation_weights(friction, moments, kT, dt, noise)
        bridge = None
        if noise:
            bridge = noise_scale(kT, friction, dt, moments) * dt * bridge_spread(x)
        return stage(BAOABWeights(f, s, c - s, dt - 2 * c, bridge, relaxation))

    def advance(self, carry, t, dt, inertia, torque, args, fluid, normals):
        (q, omega), tau, step = carry
        moments = inertia.tensor
        w = self.weights(fluid.friction, moments, fluid.kT, dt, noise=normals is not None)
        half = 0.5 * dt
        if torque is not None:
            omega = omega + kick(q, (2 - w.f) / moments, half * tau)

        def middle(q, omega):
            """The O step and the middle turn, between the two A steps' rotors."""
            spin = quat.rotate(quat.conjugate(q), omega)
            slow = body_flow_rotation(q, fluid)
            turn = w.middle * slow
            rest = normals
            if normals is not None:
                turn = turn + w.bridge * normals[3:]
                rest = normals[:3]
            spin = relax(spin, slow, w.relaxation, rest)
            q = quat.multiply(q, quat.exp(turn))
            return q, quat.rotate(q, spin), jnp.broadcast_to(slow, jnp.shape(omega))

        if _ONE_ROTOR:
            q = self._turn(q, omega, w.extra)

            def a_step(k, carry):
                # Iteration 0: the first A step's rotor (its turn came before), then the O step;
                # iteration 1: the second A step's rotor, then its turn. The branch is chosen by the
                # unbatched counter, so under jax.vmap it stays a conditional.
                q, omega, slow = carry
                q, omega = free_rotor(q, omega, moments, w.s, substeps=self.rotor_substeps)
                return lax.cond(
                    k == 0,
                    lambda q, omega, slow: middle(q, omega),
                    lambda q, omega, slow: (self._turn(q, omega, w.extra), omega, slow),
                    q,
                    omega,
                    slow,
                )

            q, omega, slow = lax.fori_loop(0, 2, a_step, (q, omega, jnp.zeros_like(omega)))
        else:
            q, omega = self._drift(q, omega, moments, w.s, w.extra, first=True)
            q, omega, slow = middle(q, omega)
            q, omega = self._drift(q, omega, moments, w.s, w.extra, first=False)
        q = quat.normalize(q)
        if fluid.velocity_gradient is not None:  # the spin relaxed to S(q_½): (1 − f) of it moved to S(q₁)
            lag = (1 - w.f) * (body_flow_rotation(q, fluid) - slow)
            omega = omega + quat.rotate(q, lag)
        tau1 = None
        if torque is not None:
            predicted = omega + kick(q, w.f / moments, half * tau)
            tau1 = world_torque(torque, t + dt, q, predicted, args)
            omega = omega + kick(q, w.f / moments, half * tau1)
        return LangevinCarry(RotState(q, omega), tau1, step + 1)


class BAOABWeights(NamedTuple):
    """`BAOAB`'s weights of one step, per principal axis ``(3,)`` unless said: ``f`` the drift factor
    ``f(ζΔt/I)``; ``s`` ``()`` the rotor's time ``min_k c_k`` (``c = f Δt/2``); ``extra`` the turns
    ``c − s``; ``middle`` the flow's share ``Δt − 2c``; ``bridge`` the angle's spread given both spins,
    ``a Δt √W`` (None without noise); ``relaxation`` the O step's (`jaxrot.schemes._ou.Relaxation`)."""

    f: jax.Array
    s: jax.Array
    extra: jax.Array
    middle: jax.Array
    bridge: jax.Array | None
    relaxation: Relaxation
