"""Runge–Kutta–Munthe-Kaas: any explicit Butcher tableau lifted to SO(3) × R³.

The state is the orientation ``R`` (the quaternion ``q``) and the world angular
momentum ``L = R I Rᵀ ω``; with ``ω(R, L) = R I⁻¹ Rᵀ L`` and ``τ`` the world torque,
one step of length ``h`` from ``(q_n, L_n)`` at time ``t`` is, for stages ``i``:

    Θ_i = h Σ_j a_ij K_j,     q_i = exp(Θ_i) ⊗ q_n,     L_i = L_n + h Σ_j a_ij T_j,
    ω_i = ω(q_i, L_i),        K_i = dexp⁻¹_{Θ_i}(ω_i),  T_i = τ(t + c_i h, q_i, ω_i),
    q_{n+1} = exp(h Σ_j b_j K_j) ⊗ q_n,                L_{n+1} = L_n + h Σ_j b_j T_j.

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

from typing import Any, ClassVar, NamedTuple

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._fusion import stage
from .._inertia import body_inertia
from .._math import taylor_threshold
from .._state import RotState
from .._trig import sincos
from ..quaternion import cayley, conjugate, multiply, normalize, rotate
from ._base import AbstractScheme, world_torque


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


def _combination(dt, weights, vectors):
    """``dt · Σ_j weights[j] · vectors[j]`` over the nonzero (static) weights; None if all are zero."""
    # dt scales each scalar weight, not the sum: with dt a runtime value (a user's jit taking dt, the
    # race's one program per scheme) ``dt * Σ`` compiled to 2.5x more broadcasts and transposes and ran
    # rkmk_dopri8 2.6x slower than with dt a constant (100 bodies, heavy top: 10 vs 3.8 ms); this form
    # runs both at 3.8-4.0 ms.
    terms = [(float(w) * dt) * v for w, v in zip(weights, vectors, strict=False) if w != 0]
    if not terms:
        return None
    total = terms[0]
    for term in terms[1:]:
        total = total + term
    return total


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
        momentum: world angular momentum ``L = R I Rᵀ ω`` ``(3,)``, the variable the
            scheme integrates. Carried rather than rebuilt from ``ω`` each step, so a
            torque-free body keeps ``L`` exactly (rebuilt, float32 drifted 1.2e-2 in 10⁵ steps).
    """

    state: RotState
    momentum: jax.Array


def _momentum(state, inertia):
    q, omega = state
    return rotate(q, inertia.apply(rotate(conjugate(q), omega)))


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

    def init(self, state, t0, inertia, torque, args):
        return LieRungeKuttaCarry(state, _momentum(state, body_inertia(inertia)))

    def state(self, carry):
        return carry.state

    def with_state(self, carry, state, inertia):
        return LieRungeKuttaCarry(state, _momentum(state, body_inertia(inertia)))

    def step(self, carry, t, dt, inertia, torque, args):
        n_stages = _last_needed_stage(self.tableau, with_error=False)
        ks, taus = self.stages(carry, t, dt, inertia, torque, args, n_stages)
        return self.combine(carry, dt, inertia, ks, taus, self.tableau.b_sol)

    def step_with_error(self, carry, t, dt, inertia, torque, args):
        """``(new carry, (Θ_err (3,), L_err (3,)))``: the step and the embedded error estimate.

        The error lives in the Lie algebra (``h Σ (b_j − b̂_j) K_j``, a rotation vector,
        radians) and in the world angular momentum (``h Σ (b_j − b̂_j) T_j``; zeros
        when torque-free)."""
        if not self.has_error_estimate:
            raise ValueError(f"{self.name} has no embedded error estimate.")
        n_stages = _last_needed_stage(self.tableau, with_error=True)
        ks, taus = self.stages(carry, t, dt, inertia, torque, args, n_stages)
        return self.combine(carry, dt, inertia, ks, taus, self.tableau.b_sol), self.error(dt, ks, taus)

    def error(self, dt, ks, taus):
        """The embedded error estimate ``(Θ_err (3,), L_err (3,))`` of a step's stages."""
        theta_err = _combination(dt, self.tableau.b_error, ks)
        momentum_err = None if not taus else _combination(dt, self.tableau.b_error, taus)
        return theta_err, jnp.zeros_like(theta_err) if momentum_err is None else momentum_err

    def stages(self, carry, t, dt, inertia, torque, args, n_stages, first_torque=None):
        """The first ``n_stages`` stage slopes ``(K_i, T_i)`` of a step, as two lists of ``(3,)``.

        ``K_i`` is the stage's rotation-vector rate (``dψ⁻¹_{Θ_i}(ω_i)`` in the ``chart`` ψ, world,
        rad / time) and ``T_i`` its world torque (an empty list when torque-free). ``first_torque``, when
        given, is used as ``T_1`` instead of calling the torque: the last stage of a
        first-same-as-last tableau, reused by the adaptive solver."""
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

    def _unrolled_stages(self, carry, t, dt, inertia, torque, args, n_stages, first_torque):
        """`stages`, one stage after another in the program (each behind a `stage` barrier)."""
        inertia = body_inertia(inertia)
        (q0, omega0), momentum0 = carry
        c = np.concatenate([[0.0], self.tableau.c])
        ks, taus = [omega0], []
        if torque is not None:
            if first_torque is None:
                first_torque = world_torque(torque, t, q0, omega0, args)
            taus.append(stage(first_torque))
        for i in range(1, n_stages):
            a_row = self.tableau.a_lower[i - 1]
            theta = _combination(dt, a_row, ks)
            if theta is None:  # a stage at the start point (a zero row)
                theta = jnp.zeros_like(omega0)
            impulse = None if torque is None else _combination(dt, a_row, taus)
            momentum = momentum0 if impulse is None else momentum0 + impulse
            k_i, tau_i = self._slopes(theta, momentum, q0, t + float(c[i]) * dt, inertia, torque, args, stage)
            ks.append(k_i)
            if torque is not None:
                taus.append(tau_i)
        return ks, taus

    def _slopes(self, theta, momentum, q0, t_i, inertia, torque, args, barrier):
        """One stage's ``(K_i, T_i)`` (``T_i`` None when torque-free) at ``Θ_i`` and ``L_i``.

        ``barrier`` is `stage` in the unrolled stages and `_no_barrier` inside the stage loop."""
        chart, inverse_differential = CHARTS[self.chart]
        rotation, c_theta = barrier(*chart(theta))
        q_i = barrier(multiply(rotation, q0))
        omega_i = barrier(_omega(q_i, momentum, inertia))
        k_i = barrier(inverse_differential(theta, c_theta, omega_i))
        tau_i = None if torque is None else barrier(world_torque(torque, t_i, q_i, omega_i, args))
        return k_i, tau_i

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
        taus = None
        if torque is not None:
            if first_torque is None:
                first_torque = world_torque(torque, t, q0, omega0, args)
            taus = jnp.zeros((n_stages, *omega0.shape), dtype).at[0].set(first_torque)

        def one_stage(i, slopes):
            ks, taus = slopes
            # Weighted sums as products and a sum, not a dot: XLA:CPU runs small batched dots slowly.
            theta = dt * jnp.sum(a[i][:, None] * ks, axis=0)
            momentum = momentum0 if taus is None else momentum0 + dt * jnp.sum(a[i][:, None] * taus, axis=0)
            k_i, tau_i = self._slopes(theta, momentum, q0, t + c[i] * dt, inertia, torque, args, _no_barrier)
            ks = ks.at[i].set(k_i)
            if taus is not None:
                taus = taus.at[i].set(tau_i)
            return ks, taus

        ks, taus = jax.lax.fori_loop(1, n_stages, one_stage, (ks, taus))
        return list(ks), [] if taus is None else list(taus)

    def combine(self, carry, dt, inertia, ks, taus, weights) -> LieRungeKuttaCarry:
        """The carry ``ψ(h Σ w_j K_j) ⊗ q_n``, ``L_n + h Σ w_j T_j`` for stage slopes ``ks``, ``taus``."""
        (q0, _), momentum0 = carry
        step_rotation, _ = CHARTS[self.chart][0](_combination(dt, weights, ks))
        q1 = stage(normalize(multiply(step_rotation, q0)))
        impulse = None if not taus else _combination(dt, weights, taus)
        momentum1 = momentum0 if impulse is None else momentum0 + impulse
        return LieRungeKuttaCarry(RotState(q1, _omega(q1, momentum1, body_inertia(inertia))), momentum1)


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
