"""Runge–Kutta–Munthe-Kaas: any explicit Butcher tableau lifted to SO(3) × R³.

The state is the orientation ``R`` (the quaternion ``q``) and the world angular
momentum ``L = R I Rᵀ ω``; with ``ω(R, L) = R I⁻¹ Rᵀ L`` and ``τ`` the world torque,
one step of length ``h`` from ``(q_n, L_n)`` at time ``t`` is, for stages ``i``:

    Θ_i = h Σ_j a_ij K_j,     q_i = exp(Θ_i) ⊗ q_n,     L_i = L_n + h Σ_j a_ij T_j,
    ω_i = ω(q_i, L_i),        K_i = dexp⁻¹_{Θ_i}(ω_i),  T_i = τ(t + c_i h, q_i, ω_i),
    q_{n+1} = exp(h Σ_j b_j K_j) ⊗ q_n,                L_{n+1} = L_n + h Σ_j b_j T_j.

**The frame of the momentum** (`AbstractLieRungeKutta.momentum_frame`). The variable the
tableau advances beside ``Θ`` can instead be the body angular momentum ``m = Rᵀ L = I ω_b``
(``"body"``), with Euler's equations ``ṁ = m × I⁻¹m + Rᵀτ`` as its rate in place of ``T_i``:
``m_i = m_n + h Σ_j a_ij M_j``, ``ω_i = R_i I⁻¹ m_i``. (Whether the stage rotations act on the
left in world coordinates or on the right in body coordinates does not matter: the two RKMK
methods are conjugate by the constant ``q_n`` and give the same step.) Torque-free, ``m`` then
follows Euler's equations alone and the stage orientations no longer feed back into the
velocities; measured on free bodies and the heavy top (``benchmarks/order4.py``), the error
constant of the RK4 tableau is 2.6–11× smaller than with ``L``, the form of MuJoCo 4.0's ``RK4``
integrator. The price: ``L`` of a torque-free body is no longer constant by construction, but
accurate to the method's order.

The rotation part lives in the Lie algebra so(3) ≅ R³, where the tableau acts on
plain vectors; ``dexp⁻¹`` (closed form on so(3)) makes the method keep exactly the
classical order of the tableau, and ``q`` stays unit up to round-off at any step
size. Without ``dexp⁻¹`` any tableau drops to order 2. The exponential may be
replaced by any chart ``ψ`` of the group with ``ψ(0) = I``, ``dψ_0 = I`` and its own
``dψ⁻¹``: the Cayley map, whose ``dcay⁻¹`` is a polynomial, is the other choice
(the ``chart`` field of `AbstractLieRungeKutta`).

Reference:
    H. Munthe-Kaas, "High order Runge–Kutta methods on manifolds", Appl. Numer.
    Math. 29, 115–127 (1999); "Runge–Kutta methods on Lie groups", BIT 38, 92–111
    (1998). E. Hairer, C. Lubich and G. Wanner, Geometric Numerical Integration,
    2nd ed., Springer (2006), section IV.8.
"""

import functools
import operator
from typing import Any, ClassVar, NamedTuple

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._core._fusion import stage
from .._inertia import body_inertia
from .._state import RotState
from ..quaternion import conjugate, multiply, normalize, rotate
from ._base import AbstractScheme, world_torque
from ._charts import CHARTS, cayley_and_dcayinv as cayley_and_dcayinv, exp_and_dexpinv as exp_and_dexpinv


def _combination(dt, weights, vectors):
    """``dt · Σ_j weights[j] · vectors[j]`` over the nonzero (static) weights; None if all are zero."""
    # dt scales each scalar weight, not the sum: with dt a runtime value (a user's jit taking dt, the
    # race's one program per scheme) ``dt * Σ`` compiled to 2.5x more broadcasts and transposes and ran
    # rkmk_dopri8 2.6x slower than with dt a constant (100 bodies, heavy top: 10 vs 3.8 ms); this form
    # runs both at 3.8-4.0 ms.
    return add_terms([(float(w) * dt) * v for w, v in zip(weights, vectors, strict=False) if w != 0])


def add_terms(terms):
    """``terms[0] + terms[1] + …`` in that order, or None for no terms."""
    return functools.reduce(operator.add, terms) if terms else None


def _no_barrier(*values):
    """`stage`'s signature without its barrier (inside a loop, whose body is one already)."""
    return values[0] if len(values) == 1 else values


def _last_needed_stage(tableau: diffrax.ButcherTableau, with_error: bool) -> int:
    """Number of leading stages that the solution (and error estimate) reads."""
    weights = np.abs(tableau.b_sol) + (np.abs(tableau.b_error) if with_error else 0)
    return int(np.max(np.nonzero(weights)[0])) + 1


class LieRungeKuttaCarry(NamedTuple):
    """What a Lie-group RK scheme carries between steps (one body).

    Attributes:
        state: the `RotState` ``(q (4,), omega (3,))``.
        momentum: the angular momentum ``(3,)`` the scheme integrates, in the frame of its
            ``momentum_frame``: world ``L = R I Rᵀ ω`` or body ``m = I Rᵀ ω``. Carried rather than
            rebuilt from ``ω`` each step, so its rounding does not accumulate (a world ``L``
            rebuilt each step drifted 1.2e-2 in 10⁵ float32 steps; carried, a torque-free body
            keeps it exactly).
    """

    state: RotState
    momentum: jax.Array


def _momentum(state, inertia, frame="world"):
    """The angular momentum of ``state`` in ``frame``: world ``L`` or body ``m = I ω_b``."""
    q, omega = state
    if frame == "body":  # q normalised: |q|² = 1 + δ would scale m, and every later ω, by 1 + δ
        return inertia.apply(rotate(conjugate(normalize(q)), omega))
    return rotate(q, inertia.apply(rotate(conjugate(q), omega)))


MOMENTUM_FRAMES = ("world", "body")


class AbstractLieRungeKutta(AbstractScheme):
    """A Runge–Kutta–Munthe-Kaas scheme driven by a `diffrax.ButcherTableau`.

    Subclasses set ``name``, ``order``, ``tableau`` (explicit) and, for an embedded
    pair, ``has_error_estimate = True``. ``torque_evals_per_step`` follows from the
    tableau: stages after the last nonzero weight of ``b_sol`` are not evaluated.
    The carry is a `LieRungeKuttaCarry`; any torque is supported (time-,
    orientation- and velocity-dependent, coupled bodies, drives).

    ``chart`` (static): the coordinates of the stage rotations, ``q_i = ψ(Θ_i) ⊗ q_n``.
    ``"exp"`` (default): the exponential and ``dexp⁻¹`` (`exp_and_dexpinv`);
    ``"cayley"``: `jaxrot.quaternion.cayley` and its polynomial ``dcay⁻¹``
    (`cayley_and_dcayinv`), no trigonometry. Both keep the tableau's order (tests).
    Measured on RKMK-Dopri8 (N = 1000 bodies, float64, 2 CPU cores): the Cayley step
    takes two thirds of the time of the exponential one; at equal steps its errors
    are 1.6–4.6× larger on the tests' problems (gravity, rotating field, drag) and
    1.3× smaller on the ``viscous_drag`` race scene. At steps far past any accuracy
    (``|ω| Δt ≈ 9``: no digit left with either chart) its polynomial ``dcay⁻¹`` lets the
    stages overflow to NaN where ``"exp"`` stays finite. Example: ``RKMKDopri8(chart="cayley")``.

    ``momentum_frame`` (static): the frame of the angular momentum the tableau advances (module
    docstring): ``"world"`` (default of the family), ``L``, constant for a free body;
    ``"body"`` (default of `RKMK4`), ``m = I ω_b`` under Euler's equations, 2.6–11× smaller errors
    with the RK4 tableau on the measured problems. The adaptive solver of `jaxrot.solver` takes
    ``"world"`` only (its dense output interpolates ``L``). Example: ``RKMK4(momentum_frame="world")``.

    ``loop_stages`` (static, default False): evaluate the stages in one loop over the
    tableau's rows, as diffrax does, instead of unrolled, everywhere. On XLA:CPU a forward step
    then runs 4–9× slower (N = 1 and 1000 bodies; XLA does not fuse across the loop's
    iterations), so the default keeps the unrolled stages for values and loops only in
    derivatives (below). Example: ``RKMKDopri8(loop_stages=True)``.

    ``loop_derivative_stages`` (static, default True): keep the unrolled stages for the values
    and differentiate the looped ones: a `jax.custom_jvp` whose rule is the looped stages' JVP,
    so forward and reverse mode both see one stage in a loop. A rollout that is not
    differentiated runs the unrolled program, the same bits; under differentiation the values
    are the looped stages', which differ from the unrolled ones by the order of each stage's
    sums (round-off). A torque that closes over traced values is closure-converted
    (`jax.closure_convert`), so derivatives with respect to them still flow. Measured
    (`benchmarks/compile.py`, 2 CPU cores, jax 0.10.2, heavy top, 200 steps, one body): the
    gradient of ``RKMKDopri8()`` compiles in 5.3 s and runs in 73 ms; with
    ``loop_derivative_stages=False`` (the unrolled stages differentiated) in 44 s and 58 ms:
    the looped derivatives run about 1.3× longer than the unrolled ones (70 against 54 ms in
    one process, with ``loop_stages=True`` at 70 ms too), and compile 8× faster.
    """

    chart: str = eqx.field(default="exp", static=True)
    momentum_frame: str = eqx.field(default="world", static=True)
    loop_stages: bool = eqx.field(default=False, static=True)
    loop_derivative_stages: bool = eqx.field(default=True, static=True)
    tableau: eqx.AbstractClassVar[diffrax.ButcherTableau]
    has_error_estimate: ClassVar[bool] = False
    # The continuous extension of the tableau (a diffrax ``interpolation_cls``), used by
    # `jaxrot.solver`'s dense output in the Lie algebra; None when the tableau has none.
    dense_output: ClassVar[Any] = None

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        tableau = cls.__dict__.get("tableau")
        if tableau is None:
            return
        if not isinstance(tableau, diffrax.ButcherTableau) or tableau.implicit:
            raise TypeError(f"{cls.__name__}.tableau must be an explicit diffrax.ButcherTableau.")
        if cls.__dict__.get("has_error_estimate") and not np.any(tableau.b_error):
            raise TypeError(f"{cls.__name__} claims an error estimate but its tableau's b_error is zero.")
        cls.torque_evals_per_step = _last_needed_stage(tableau, with_error=False)

    def __check_init__(self):
        if self.chart not in CHARTS:
            raise ValueError(f"`chart` must be one of {sorted(CHARTS)}; got {self.chart!r}.")
        if self.momentum_frame not in MOMENTUM_FRAMES:
            raise ValueError(
                f"`momentum_frame` must be one of {list(MOMENTUM_FRAMES)}; got {self.momentum_frame!r}."
            )

    def init(self, state, t0, inertia, torque, args):
        return LieRungeKuttaCarry(state, _momentum(state, body_inertia(inertia), self.momentum_frame))

    def state(self, carry):
        return carry.state

    def with_state(self, carry, state, inertia):
        return LieRungeKuttaCarry(state, _momentum(state, body_inertia(inertia), self.momentum_frame))

    def step(self, carry, t, dt, inertia, torque, args):
        n_stages = _last_needed_stage(self.tableau, with_error=False)
        ks, taus = self.stages(carry, t, dt, inertia, torque, args, n_stages)
        return self.combine(carry, dt, inertia, ks, taus, self.tableau.b_sol)

    def step_with_error(self, carry, t, dt, inertia, torque, args):
        """``(new carry, (Θ_err (3,), L_err (3,)))``: the step and the embedded error estimate.

        The error lives in the Lie algebra (``h Σ (b_j − b̂_j) K_j``, a rotation vector,
        radians) and in the angular momentum, in the frame of ``momentum_frame``
        (``h Σ (b_j − b̂_j) T_j``; zeros for a torque-free body's world ``L``)."""
        if not self.has_error_estimate:
            raise ValueError(f"{self.name} has no embedded error estimate.")
        n_stages = _last_needed_stage(self.tableau, with_error=True)
        ks, rates = self.stages(carry, t, dt, inertia, torque, args, n_stages)
        return self.combine(carry, dt, inertia, ks, rates, self.tableau.b_sol), self.error(dt, ks, rates)

    def error(self, dt, ks, rates):
        """The embedded error estimate ``(Θ_err (3,), L_err (3,))`` of a step's stages."""
        theta_err = _combination(dt, self.tableau.b_error, ks)
        momentum_err = None if not rates else _combination(dt, self.tableau.b_error, rates)
        return theta_err, jnp.zeros_like(theta_err) if momentum_err is None else momentum_err

    def stages(self, carry, t, dt, inertia, torque, args, n_stages, first_torque=None):
        """The first ``n_stages`` stage slopes ``(K_i, T_i)`` of a step, as two lists of ``(3,)``.

        ``K_i`` is the stage's rotation-vector rate (``dψ⁻¹_{Θ_i}(ω_i)`` in the ``chart`` ψ, world,
        rad / time) and ``T_i`` the rate of the momentum in ``momentum_frame``: the world torque
        (an empty list when torque-free), or the body rate ``m_i × ω_b,i + R_iᵀ τ_i``.
        ``first_torque``, when given, is used as the first stage's world torque instead of calling
        the torque: the last stage of a first-same-as-last tableau, reused by the adaptive solver."""
        if self.loop_stages:
            return self._looped_stages(carry, t, dt, inertia, torque, args, n_stages, first_torque)
        if not self.loop_derivative_stages:
            return self._unrolled_stages(carry, t, dt, inertia, torque, args, n_stages, first_torque)
        consts = ()
        if torque is not None:
            (q0, omega0), _ = carry
            # Only the array leaves of `args` can be example arguments: the converted torque takes
            # them as its `args` and holds the rest, so only they go on to the stages.
            args, static = eqx.partition(args, eqx.is_array)
            user_torque = torque
            torque, consts = jax.closure_convert(
                lambda t, q, omega, dynamic: user_torque(t, q, omega, eqx.combine(dynamic, static)),
                t, q0, omega0, args,
            )  # fmt: skip
        return _stages_with_looped_derivatives(
            carry, t, dt, inertia, args, first_torque, consts, scheme=self, torque=torque, n_stages=n_stages
        )

    def _first_rate(self, carry, t, inertia, torque, args, first_torque):
        """The first stage's momentum rate (at the step's start), or None if the momentum is constant."""
        (q0, omega0), momentum0 = carry
        tau = None
        if torque is not None:
            tau = world_torque(torque, t, q0, omega0, args) if first_torque is None else first_torque
        if self.momentum_frame == "world":
            return tau
        return self._body_rate(q0, momentum0, inertia.solve(momentum0), tau)

    @staticmethod
    def _body_rate(q, momentum, omega_body, tau):
        """Euler's equations for the body momentum: ``m × ω_b + Rᵀ τ`` (``τ`` world, or None)."""
        rate = jnp.cross(momentum, omega_body)
        return rate if tau is None else rate + rotate(conjugate(q), tau)

    def _unrolled_stages(self, carry, t, dt, inertia, torque, args, n_stages, first_torque):
        """`stages`, one stage after another in the program (each behind a `stage` barrier)."""
        inertia = body_inertia(inertia)
        (q0, omega0), momentum0 = carry
        c = np.concatenate([[0.0], self.tableau.c])
        ks, rates = [omega0], []
        first = self._first_rate(carry, t, inertia, torque, args, first_torque)
        if first is not None:
            rates.append(stage(first))
        for i in range(1, n_stages):
            a_row = self.tableau.a_lower[i - 1]
            theta = _combination(dt, a_row, ks)
            if theta is None:  # a stage at the start point (a zero row)
                theta = jnp.zeros_like(omega0)
            impulse = None if not rates else _combination(dt, a_row, rates)
            momentum = momentum0 if impulse is None else momentum0 + impulse
            k_i, rate_i = self._slopes(
                theta, momentum, q0, t + float(c[i]) * dt, inertia, torque, args, stage
            )
            ks.append(k_i)
            if rate_i is not None:
                rates.append(rate_i)
        return ks, rates

    def _slopes(self, theta, momentum, q0, t_i, inertia, torque, args, barrier):
        """One stage's ``(K_i, T_i)`` at ``Θ_i`` and the momentum (``T_i`` None for a torque-free world L).

        ``barrier`` is `stage` in the unrolled stages and `_no_barrier` inside the stage loop."""
        chart, inverse_differential = CHARTS[self.chart]
        rotation, c_theta = barrier(*chart(theta))
        q_i = barrier(multiply(rotation, q0))
        if self.momentum_frame == "world":
            omega_i = barrier(_omega(q_i, momentum, inertia))
        else:
            omega_body = inertia.solve(momentum)
            omega_i = barrier(rotate(q_i, omega_body))
        k_i = barrier(inverse_differential(theta, c_theta, omega_i))
        tau_i = None if torque is None else barrier(world_torque(torque, t_i, q_i, omega_i, args))
        if self.momentum_frame == "world":
            return k_i, tau_i
        return k_i, barrier(self._body_rate(q_i, momentum, omega_body, tau_i))

    def _looped_stages(self, carry, t, dt, inertia, torque, args, n_stages, first_torque):
        """`stages` as one loop over the tableau's rows, as diffrax evaluates its stages.

        The program holds one stage instead of ``n_stages``: its gradient compiles in a
        fraction of the unrolled one's time. Each stage sums over the full (zero-padded) row."""
        inertia = body_inertia(inertia)
        (q0, omega0), momentum0 = carry
        dtype = omega0.dtype
        a = np.zeros((n_stages, n_stages))
        for i in range(1, n_stages):
            row = np.asarray(self.tableau.a_lower[i - 1])[:n_stages]
            a[i, : len(row)] = row
        a = jnp.asarray(a, dtype)
        c = jnp.asarray(np.concatenate([[0.0], self.tableau.c])[:n_stages], dtype)
        ks = jnp.zeros((n_stages, *omega0.shape), dtype).at[0].set(omega0)
        rates = None
        first = self._first_rate(carry, t, inertia, torque, args, first_torque)
        if first is not None:
            rates = jnp.zeros((n_stages, *omega0.shape), dtype).at[0].set(first)

        def one_stage(i, slopes):
            ks, rates = slopes
            # Weighted sums as products and a sum, not a dot: XLA:CPU runs small batched dots slowly.
            theta = dt * jnp.sum(a[i][:, None] * ks, axis=0)
            momentum = momentum0 if rates is None else momentum0 + dt * jnp.sum(a[i][:, None] * rates, axis=0)
            k_i, rate_i = self._slopes(theta, momentum, q0, t + c[i] * dt, inertia, torque, args, _no_barrier)
            ks = ks.at[i].set(k_i)
            if rates is not None:
                rates = rates.at[i].set(rate_i)
            return ks, rates

        ks, rates = jax.lax.fori_loop(1, n_stages, one_stage, (ks, rates))
        return list(ks), [] if rates is None else list(rates)

    def combine(self, carry, dt, inertia, ks, rates, weights) -> LieRungeKuttaCarry:
        """The carry ``ψ(h Σ w_j K_j) ⊗ q_n``, ``L_n + h Σ w_j T_j`` for stage slopes ``ks``, ``rates``."""
        (q0, _), momentum0 = carry
        inertia = body_inertia(inertia)
        step_rotation, _ = CHARTS[self.chart][0](_combination(dt, weights, ks))
        q1 = stage(normalize(multiply(step_rotation, q0)))
        impulse = None if not rates else _combination(dt, weights, rates)
        momentum1 = momentum0 if impulse is None else momentum0 + impulse
        if self.momentum_frame == "world":
            omega1 = _omega(q1, momentum1, inertia)
        else:
            omega1 = rotate(q1, inertia.solve(momentum1))
        return LieRungeKuttaCarry(RotState(q1, omega1), momentum1)


def _bind(torque, consts):
    """A closure-converted torque with its hoisted constants put back."""
    return None if torque is None else (lambda t, q, omega, args: torque(t, q, omega, args, *consts))


@eqx.filter_custom_jvp
def _stages_with_looped_derivatives(
    carry, t, dt, inertia, args, first_torque, consts, *, scheme, torque, n_stages
):
    """The unrolled stages, differentiated as the looped ones (``loop_derivative_stages``)."""
    return scheme._unrolled_stages(carry, t, dt, inertia, _bind(torque, consts), args, n_stages, first_torque)


@_stages_with_looped_derivatives.def_jvp
def _stages_jvp(primals, tangents, *, scheme, torque, n_stages):
    def looped(carry, t, dt, inertia, args, first_torque, consts):
        return scheme._looped_stages(
            carry, t, dt, inertia, _bind(torque, consts), args, n_stages, first_torque
        )

    # Only the inputs with a tangent enter the JVP: the others (symbolic zeros, integers) are held.
    leaves, treedef = jax.tree_util.tree_flatten(primals)
    tangent_leaves = treedef.flatten_up_to(tangents)
    live = [i for i, tangent in enumerate(tangent_leaves) if tangent is not None]

    def of_live(*values):
        full = list(leaves)
        for i, value in zip(live, values, strict=True):
            full[i] = value
        return looped(*jax.tree_util.tree_unflatten(treedef, full))

    return jax.jvp(of_live, [leaves[i] for i in live], [tangent_leaves[i] for i in live])


def _omega(q, momentum, inertia):
    """World ``ω = R I⁻¹ Rᵀ L`` for the orientation ``q`` and world momentum ``L``."""
    return rotate(q, inertia.solve(rotate(conjugate(q), momentum)))
