"""Exponential Lie-group Runge–Kutta schemes: a fluid's friction integrated exactly, any ζΔt/I.

In the body frame, with ``u = ω_b``, a body in a fluid (`jaxrot.Fluid`) obeys

    I u̇ = ζ ⊙ (S(t, q) − u) + (torque that is not in S) − u × I u,      q̇ = ½ q ⊗ (0, u),

where the *slow velocity* ``S`` is the angular velocity at which the fluid's torque balances: the
flow's ``ω_f`` (`jaxrot._fluid._flow`) plus ``ζ⁻¹ ⊙ τ_b`` when the applied torque ``τ`` does not
depend on ω. With ``L = ζ/I`` (principal moments: diagonal) and the deviation ``v = u − S``,

    v̇ = −L v + N(t, q, u),   N = I⁻¹(τ_b,ω-dependent − u × I u) − Ṡ,          (1)

and the only large term, ``−L v``, is linear: ``Ṡ`` (the flow's part written out,
`jaxrot._fluid._flow.body_flow`; the torque's part a `jax.jvp` along ``q̇``) and the gyroscopic term
stay bounded as ``L → ∞``. The rotation vector ``Θ`` of ``q = q_n ⊗ exp(Θ)``
obeys ``Θ̇ = v + [S + dexp⁻¹_{−Θ}(u) − u]``: the pair ``(v, Θ)`` is a semilinear system with the
linear part ``[[−L, 0], [1, 0]]`` and a bounded, smooth nonlinear part. An explicit exponential
Runge–Kutta method (Hochbruck & Ostermann, SIAM J. Numer. Anal. 43, 1069 (2005); Acta Numerica
19, 209 (2010)) applied to it takes the linear part exactly: the φ-functions of that matrix act on
``v`` as ``φ_k(−c h L)`` and on ``Θ`` as ``c h φ_{k+1}(−c h L)`` (the step-averaged ``v``), so

    V_i = e^{−c_i hL} v_n + h Σ_j a_ij(−hL) N_j,
    Θ_i = c_i h φ_1(−c_i hL) v_n + h² Σ_j ã_ij(−hL) N_j + h Σ_j a_ij(0) (K_j − V_j),
    K_j = dexp⁻¹_{−Θ_j}(S_j + V_j),   q_i = q_n ⊗ exp(Θ_i),

with ``ã_ij(z) = (a_ij(z) − a_ij(0))/z``: for a term ``φ_k(c z)`` of ``a_ij`` that is
``c φ_{k+1}(c z)``. Why the orders hold uniformly in ``L``: the error of each stage is the
variation-of-constants integral of the interpolation error of ``N``, ``∫ e^{−L(h−s)}(N − p)(s) ds``,
bounded by ``min(h, 1/L) · sup|N − p|``; ``N`` is bounded and smooth on the slow manifold, so a
tableau that satisfies the *stiff* order conditions keeps its order whatever ``hL`` (measured:
orders 2 and 4 from ``hL = 0`` to 4.5e7, ``benchmarks/fluid_orders.py``; in between, at ``hL`` of
about 5 to 30, ExpRK4's error constant has a hump). Written for ``u`` itself (``S = 0``) the
forcing would be ``L S`` — proportional to the stiffness — and the ``Θ``-stages would evaluate
``dexp⁻¹`` at extrapolated velocities: in a prototype of that form (not kept), the fourth-order
tableau dropped to order 3 for ``hL ≫ 1``, as it did when an ω-independent torque was left in
``N`` as ``I⁻¹ τ``. As ``hL → ∞`` the scheme tends to the tableau's classical method (``z = 0``)
applied to the overdamped model ``q̇ = ½ q ⊗ (0, S)``.

The start of a run off the slow manifold (a boundary layer of width ``I/ζ``) is taken in graded
substeps: `jaxrot.schemes._graded_start` has the mesh, the decision and their measurements.

Without a fluid (``L = 0``, ``S = 0``) every ``φ_k`` is ``1/k!`` and the scheme is the tableau's
classical Runge–Kutta method on ``(q, ω_b)``.
"""

import dataclasses
from typing import Any, ClassVar, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp

from .. import quaternion as quat
from .._core._fusion import stage
from .._fluid._flow import body_flow
from .._inertia import body_inertia
from .._state import RotState
from . import _graded_start
from ._base import AbstractScheme, world_torque
from ._exponential_tableau import ExponentialTableau, _combine, _weights
from ._lie_runge_kutta import CHARTS
from ._rkn_splitting import uses_omega


class FluidCarry(NamedTuple):
    """What an exponential scheme carries between steps in a fluid (one body).

    Attributes:
        state: the `RotState` ``(q (4,), omega (3,))``, world ω.
        slow: the slow velocity ``S`` ``(3,)`` (body frame) at the state: the next step's first stage.
        forcing: ``N`` ``(3,)`` of equation (1) at the state: the next step's first stage.
        layer: ``()`` float, rad: the turn ``λ`` of the boundary layer the body began its run in, 0 if it
            began on its slow manifold (`init`; the graded start's decision and the size of its
            substeps, kept for the run: `jaxrot.schemes._graded_start`), or None.
    """

    state: RotState
    slow: jax.Array
    forcing: jax.Array
    layer: jax.Array | None = None


class FluidArgs(NamedTuple):
    """The ``args`` of an exponential scheme in a fluid: the torque's own and one body's `jaxrot.Fluid`."""

    args: Any
    fluid: Any


class AbstractExponentialLieRK(AbstractScheme):
    """An exponential Lie-group Runge–Kutta scheme given by an `ExponentialTableau` (see the module).

    Without a fluid it is the tableau's classical method on ``(q, ω_b)`` (carry: `RotState`); the
    registered schemes declare the ``"fluid"`` model alone, so `jaxrot.rollout` runs them only with
    ``fluid=``, where `in_fluid` gives the same scheme reading ``args`` as a `FluidArgs` and
    carrying a `FluidCarry`. Any torque: one that does not depend on ω (read from its
    jaxpr, `jaxrot.schemes._rkn_splitting.uses_omega`) is folded into the slow velocity, where a
    stiff one costs no order; one that does is integrated as a force (``N``), fourth order only
    while ``I⁻¹ ∂τ/∂ω`` is not stiff.

    ``chart`` (static): ``"exp"`` (default) or ``"cayley"``, the coordinates of the stage rotations
    ``q_n ⊗ ψ(Θ)``, as in `jaxrot.schemes.AbstractLieRungeKutta`.
    """

    chart: str = eqx.field(default="exp", static=True)
    fluid: bool = eqx.field(default=False, static=True)
    graded_start: bool = eqx.field(default=True, static=True)
    tableau: eqx.AbstractClassVar[ExponentialTableau]
    models: ClassVar[frozenset[str]] = frozenset({"fluid"})

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        tableau = cls.__dict__.get("tableau")
        if tableau is not None:
            tableau.check()
            cls.torque_evals_per_step = tableau.num_stages

    def __check_init__(self):
        if self.chart not in CHARTS:
            raise ValueError(f"`chart` must be one of {sorted(CHARTS)}; got {self.chart!r}.")

    def in_fluid(self) -> "AbstractExponentialLieRK":
        """This scheme for `jaxrot.rollout`'s ``fluid=``: ``args`` a `FluidArgs`, the carry a `FluidCarry`."""
        return dataclasses.replace(self, fluid=True)

    @property
    def torque_evals_at_init(self) -> int:
        return 1 if self.fluid else 0

    @property
    def start_steps(self) -> int:
        return 1 if self.fluid and self.graded_start else 0

    def starting(self, carry, index, t, t0, dt, inertia, args):
        """Whether the step at ``t`` is graded (`jaxrot.schemes._graded_start.starting`)."""
        return _graded_start.starting(carry, t, t0, dt, _rates(inertia, args))

    def start_step(self, carry, t, dt, t0, inertia, torque, args):
        """A step of the start, in graded substeps (`jaxrot.schemes._graded_start`; in a fluid only)."""

        def step(carry, t, size):
            return self.step(carry, t, size, inertia, torque, args)

        return _graded_start.graded_step(step, carry, t, dt, t0, _rates(inertia, args))

    def state(self, carry):
        return carry.state if self.fluid else carry

    def with_state(self, carry, state, inertia):
        if self.fluid:
            raise NotImplementedError("drives are not supported in a fluid")
        return state

    def init(self, state, t0, inertia, torque, args):
        if not self.fluid:
            return RotState(*state)
        args, fluid = args
        inertia = _diagonal(inertia)
        q, omega = state
        u = quat.rotate(quat.conjugate(q), omega)
        slow, forcing, _ = self._evaluate(t0, q, inertia, torque, args, fluid, velocity=u)
        carry = FluidCarry(RotState(q, omega), slow, forcing)
        if not self.graded_start:
            return carry
        return carry._replace(layer=_graded_start.layer_turn(carry, fluid.friction * inertia.inverse))

    def step(self, carry, t, dt, inertia, torque, args):
        if self.fluid:
            args, fluid = args
            inertia = _diagonal(inertia)
            (q0, omega0), slow0, forcing0, layer = carry
            rate = fluid.friction * inertia.inverse
            z = -dt * rate

            def evaluate(t_i, q_i, deviation):
                return self._evaluate(t_i, q_i, inertia, torque, args, fluid, deviation=deviation)

        else:
            inertia = body_inertia(inertia)
            q0, omega0 = carry
            slow0 = None
            z = None

            def evaluate(t_i, q_i, deviation):
                return None, _plain_forcing(t_i, q_i, deviation, inertia, torque, args), deviation

            forcing0 = None
        u0 = quat.rotate(quat.conjugate(q0), omega0)
        deviation0 = u0 if slow0 is None else u0 - slow0
        if forcing0 is None:
            forcing0 = evaluate(t, q0, deviation0)[1]
        q1, u1, slow1, forcing1 = self._advance(q0, deviation0, forcing0, slow0, t, dt, z, evaluate)
        state1 = RotState(q1, quat.rotate(q1, u1))
        return FluidCarry(state1, slow1, forcing1, layer) if self.fluid else state1

    def _advance(self, q0, deviation0, forcing0, slow0, t, h, z, evaluate, stages=False):
        """One step of the stages in the module's docstring: ``(q1, u1, S1, N1)`` (``S1``, ``N1`` at the
        end point: the next step's first stage); with ``stages``, also ``(Θ1, V1, [N_j], [K_j − V_j])``
        for `step_with_error`'s embedded combination."""
        chart, inverse_differential = CHARTS[self.chart]
        forcings = [forcing0]
        # K_1 − V_1 = S_1: Θ_1 = 0, where dexp⁻¹ is the identity.
        rotation_terms = [jnp.zeros_like(deviation0) if slow0 is None else slow0]
        rows = _weights(self.tableau, z)
        for i, (row, (node, _)) in enumerate(zip(rows, self.tableau.rows(), strict=True)):
            theta, deviation = _combine(row, deviation0, forcings, rotation_terms, h)
            # Stage boundaries (`jaxrot._core._fusion`): without them XLA recomputes earlier stages later.
            theta, deviation = stage(theta, deviation)
            rotation, chart_scalar = stage(*chart(theta))
            q_i = stage(quat.multiply(q0, rotation))
            last = i == len(rows) - 1
            if last:
                q_i = quat.normalize(q_i)
            slow, forcing, u = stage(*evaluate(t + node * h, q_i, deviation))
            if last:
                if stages:
                    return q_i, u, slow, forcing, (theta, deviation, forcings, rotation_terms)
                return q_i, u, slow, forcing
            forcings.append(forcing)
            # Right-trivialised: Θ̇ = dψ⁻¹_{−Θ}(u) for q = q_n ⊗ ψ(Θ).
            rotation_terms.append(stage(inverse_differential(-theta, chart_scalar, u) - deviation))

    @property
    def has_error_estimate(self) -> bool:
        """Whether the tableau has embedded weights: `step_with_error` (in a fluid) then applies."""
        return self.tableau.b_embedded is not None

    def step_with_error(self, carry, t, dt, inertia, torque, args):
        """A step in a fluid and its error estimate: ``(carry, RotState(q1 − q̂1, R1 (V1 − V̂1)))``.

        ``q̂1 = q_n ⊗ ψ(Θ̂1)`` and ``V̂1`` are the embedded row (``b_embedded``) of the same stages, so
        the estimate costs no torque call: the error of the lower-order method in the orientation and in
        the deviation ``v = ω_b − S`` (rotated to the world frame), the two variables the scheme
        integrates (``S`` is a function of ``(t, q)``, whose error follows ``q``'s). ``args`` a
        `FluidArgs`, ``carry`` a `FluidCarry`: only `in_fluid`'s form has an estimate."""
        if not (self.fluid and self.has_error_estimate):
            raise ValueError(
                f"{self.name!r} has no error estimate here: it needs embedded weights and `in_fluid()`."
            )
        args, fluid = args
        inertia = _diagonal(inertia)
        # By field, and `_replace` below: whatever else the carry holds passes through unchanged.
        (q0, omega0), slow0, forcing0 = carry.state, carry.slow, carry.forcing
        z = -dt * fluid.friction * inertia.inverse

        def evaluate(t_i, q_i, deviation):
            return self._evaluate(t_i, q_i, inertia, torque, args, fluid, deviation=deviation)

        deviation0 = quat.rotate(quat.conjugate(q0), omega0) - slow0
        q1, u1, slow1, forcing1, (_, deviation1, forcings, rotation_terms) = self._advance(
            q0, deviation0, forcing0, slow0, t, dt, z, evaluate, stages=True
        )
        # The embedded row, combined as `_advance` combines a row (without an evaluation).
        (row,) = _weights(self.tableau.embedded(), z)
        theta_hat, deviation_hat = _combine(row, deviation0, forcings, rotation_terms, dt)
        chart, _ = CHARTS[self.chart]
        q_hat = quat.normalize(quat.multiply(q0, chart(theta_hat)[0]))
        error = RotState(q1 - q_hat, quat.rotate(q1, deviation1 - deviation_hat))
        return carry._replace(state=RotState(q1, quat.rotate(q1, u1)), slow=slow1, forcing=forcing1), error

    def _evaluate(self, t, q, inertia, torque, args, fluid, *, deviation=None, velocity=None):
        """``(S, N, u)`` of equation (1) at ``(t, q)`` and ``u = S + deviation`` (or ``velocity``)."""
        dtype = q.dtype
        force = torque is not None and uses_omega(torque, t, q, jnp.zeros(3, dtype), args)
        folded = torque is not None and not force
        flowing = fluid.velocity_gradient is not None

        def torque_velocity(t, q):  # ζ⁻¹ ⊙ τ_b: the part of S an ω-independent torque gives
            tau = world_torque(torque, t, q, jnp.zeros(3, dtype), args)
            return quat.rotate(quat.conjugate(q), tau) / fluid.friction

        slow = jnp.zeros(3, dtype)
        if folded:
            slow = slow + torque_velocity(t, q)
        if flowing:
            flow, flow_rate = body_flow(q, fluid.velocity_gradient, fluid.bretherton)
            slow = slow + flow
        u = slow + deviation if velocity is None else velocity
        forcing = -inertia.solve(jnp.cross(u, inertia.apply(u)))
        if flowing:
            forcing = forcing - flow_rate(u)
        if folded:
            q_dot = 0.5 * quat.multiply(q, quat.pure(u))
            forcing = forcing - jax.jvp(torque_velocity, (t, q), (jnp.ones((), jnp.result_type(t)), q_dot))[1]
        if force:
            tau = world_torque(torque, t, q, quat.rotate(q, u), args)
            forcing = forcing + inertia.solve(quat.rotate(quat.conjugate(q), tau))
        return slow, forcing, u


def _plain_forcing(t, q, u, inertia, torque, args):
    """Euler's equations ``I⁻¹(τ_b − u × I u)``: the forcing without a fluid."""
    tau_b = None
    if torque is not None:
        tau_b = quat.rotate(quat.conjugate(q), world_torque(torque, t, q, quat.rotate(q, u), args))
    return inertia.angular_acceleration(u, tau_b)


def _rates(inertia, args):
    """``L = ζ/I`` ``(3,)`` of one body (principal moments about the friction's axes)."""
    return args.fluid.friction * _diagonal(inertia).inverse


def _diagonal(inertia):
    inertia = body_inertia(inertia)
    if not inertia.is_diagonal:
        raise ValueError(
            "an exponential scheme in a fluid needs the inertia as principal moments (3,) about the "
            "friction's axes (body axes); a full (3, 3) tensor is not supported."
        )
    return inertia
