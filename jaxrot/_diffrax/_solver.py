"""`jaxrot.solver`: any scheme of `jaxrot.SCHEMES` as a diffrax solver.

diffrax has no Lie-group solver; these step on the rotation group, so ``q`` stays a
unit quaternion to round-off at every step, and hand diffrax everything else: step
size controllers, `SaveAt`, events, adjoints. Only diffrax's public API is used
(`AbstractSolver`, `AbstractAdaptiveSolver`, `AbstractLocalInterpolation`,
`RESULTS`, the solvers' public ``tableau`` and ``interpolation_cls``).
"""

from typing import Any, ClassVar

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
from jax import lax

from .. import quaternion as quat
from .._integrate._bind import INERTIAL, scheme_for_call
from .._state import RotState
from ..schemes import FLUID_SCHEMES, AbstractExponentialLieRK, AbstractLieRungeKutta, AbstractScheme
from ..schemes._base import world_torque
from ..schemes._lie_runge_kutta import _combination, _momentum, exp_and_dexpinv
from ._interpolation import hermite_interpolation, stage_interpolation
from ._term import RigidBodyTerm


def _check_term(terms, y0) -> tuple[RigidBodyTerm, Any]:
    """The `RigidBodyTerm` inside ``terms`` and the time direction (+1, or -1 for ``t1 < t0``).

    diffeqsolve hands solvers its terms wrapped in diffrax's (private) ``WrapTerm``,
    which maps time by a ``direction``; its two attributes ``term`` and ``direction``
    are the one private detail read here (tested with diffrax 0.7)."""
    term, direction = terms, 1
    while not isinstance(term, RigidBodyTerm) and hasattr(term, "term") and hasattr(term, "direction"):
        term, direction = term.term, direction * term.direction
    if not isinstance(term, RigidBodyTerm):
        raise ValueError(
            "a jaxrot solver needs `terms` to be a jaxrot.RigidBodyTerm(inertia, torque), whose state is "
            f"a jaxrot.RotState(q, omega); got {type(term).__name__}. For a plain ODETerm use a "
            "diffrax solver (Tsit5, Dopri8)."
        )
    if not isinstance(y0, RotState):
        raise ValueError(f"`y0` must be a jaxrot.RotState(q, omega) (world omega); got {type(y0).__name__}.")
    return term, direction


def _batched(y: RotState, fn, tree):
    """``fn`` applied to each body's slice of ``tree`` (vmapped when ``y`` holds N bodies)."""
    return fn(tree) if y.q.ndim == 1 else jax.vmap(fn)(tree)


class SchemeSolver(diffrax.AbstractSolver):
    """A fixed-step jaxrot scheme as a diffrax solver (use `jaxrot.solver` to build one).

    Works with `diffrax.ConstantStepSize` and `diffrax.StepTo`; one step of the solver
    is one `scheme.step`, so ``diffeqsolve`` at a constant ``dt0`` gives `jaxrot.rollout`'s
    result at that ``dt``. The scheme's carry (a momentum, a reused torque) is the
    solver state; after a jump (``made_jump``) it is rebuilt from ``y``.

    Dense output (``SaveAt(ts=...)``): ``q`` on the unit sphere by cubic Hermite
    interpolation of the rotation vector in the Lie algebra (local error O(h⁴)), ``ω``
    from the linearly interpolated world angular momentum (O(h²); exact for a free body).
    """

    scheme: AbstractScheme
    term_structure: ClassVar = diffrax.AbstractTerm

    @property
    def interpolation_cls(self):  # pyright: ignore
        return hermite_interpolation

    def order(self, terms):
        return self.scheme.order

    def init(self, terms, t0, t1, y0, args):
        term, direction = _check_term(terms, y0)
        self._check_fluid(term)
        scheme = self.scheme
        t0 = t0 * direction
        return term.per_body(y0, args, lambda inertia, a, y: scheme.init(y, t0, inertia, term.torque, a), y0)

    def _check_fluid(self, term):
        """A ValueError for a term this solver does not integrate."""
        if term.fluid is not None:
            raise ValueError(
                f"{self.scheme.name!r} integrates a body in vacuum, and `terms` has a `fluid`: use "
                f"jaxrot.solver with a scheme of jaxrot.FLUID_SCHEMES ({_fluid_names()}), whose friction is "
                "exact, or a diffrax solver (Kvaerno5 where the friction is stiff)."
            )

    def _carry(self, terms, t0, y0, args, solver_state, made_jump):
        """The solver state, rebuilt from ``y0`` after a jump (a stale reused torque or momentum)."""
        if made_jump is False:
            return solver_state
        return lax.cond(made_jump, lambda: self.init(terms, t0, t0, y0, args), lambda: solver_state)

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        term, direction = _check_term(terms, y0)
        scheme = self.scheme
        carry = self._carry(terms, t0, y0, args, solver_state, made_jump)
        t0, dt = t0 * direction, (t1 - t0) * direction
        new = term.per_body(
            y0, args, lambda inertia, a, c: scheme.step(c, t0, dt, inertia, term.torque, a), carry
        )
        y1 = _batched(y0, scheme.state, new)
        return y1, None, self._hermite_info(term, y0, y1, dt, args), new, diffrax.RESULTS.successful

    def _hermite_info(self, term, y0, y1, dt, args):
        def one(inertia, a, s0, s1):
            theta1 = quat.log(quat.multiply(s1.q, quat.conjugate(s0.q)))
            _, rate1 = exp_and_dexpinv(theta1, s1.omega)
            return dict(
                q0=s0.q,
                theta1=theta1,
                theta_slopes=jnp.stack([dt * s0.omega, dt * rate1]),
                momentum0=_momentum(s0, inertia),
                momentum1=_momentum(s1, inertia),
                inverse_inertia=_matrix(inertia.inverse),
            )

        info = term.per_body(y0, args, one, y0, y1)
        if y0.q.ndim == 2:  # the stage axis goes first, as diffrax's interpolations expect
            info["theta_slopes"] = jnp.swapaxes(info["theta_slopes"], 0, 1)
        return info

    def func(self, terms, t0, y0, args):
        return terms.vf(t0, y0, args)


class AdaptiveLieSolver(SchemeSolver, diffrax.AbstractAdaptiveSolver):
    """A Lie-group Runge–Kutta pair as an adaptive diffrax solver (use `jaxrot.solver`).

    Works with `diffrax.PIDController`. The error estimate is the difference of the
    pair's two solutions, both computed on the group: ``y_error = (q1 − q̂1, ω1 − ω̂1)``
    with ``q̂1 = ψ(h Σ b̂_j K_j) ⊗ q0`` (``ψ`` the scheme's chart) and ``L̂1 = L0 + h Σ b̂_j T_j`` — the same
    quantities a Euclidean solver's controller sees, so ``rtol``/``atol`` mean the
    same as for `diffrax.Tsit5` on a `jaxrot.RigidBodyTerm`. The last stage of a
    first-same-as-last tableau is reused as the next step's first torque.

    Dense output: the pair's own continuous extension (diffrax's, for the same
    tableau) applied to the rotation vector in the Lie algebra and to the world
    angular momentum; ``q`` stays on the unit sphere.
    """

    scheme: AbstractLieRungeKutta

    def __check_init__(self):
        # The dense output interpolates the world L and the reused last stage is a world torque.
        if self.scheme.momentum_frame != "world":
            raise ValueError(
                f"the adaptive solver of {self.scheme.name!r} needs momentum_frame='world'; got "
                f"{self.scheme.momentum_frame!r}. Build the scheme with momentum_frame='world'."
            )

    @property
    def interpolation_cls(self):  # pyright: ignore
        algebra = self.scheme.dense_output

        def build(**info):
            return stage_interpolation(algebra, chart=self.scheme.chart, **info)

        return build

    def init(self, terms, t0, t1, y0, args):
        carry = super().init(terms, t0, t1, y0, args)
        term, direction = _check_term(terms, y0)
        if term.torque is None:
            return carry, None
        t0 = t0 * direction

        def first(inertia, a, c):
            return world_torque(term.torque, t0, c.state.q, c.state.omega, a)

        return carry, term.per_body(y0, args, first, carry)

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        term, direction = _check_term(terms, y0)
        scheme = self.scheme
        tableau = scheme.tableau
        carry, first_torque = self._carry(terms, t0, y0, args, solver_state, made_jump)
        t0, dt = t0 * direction, (t1 - t0) * direction

        def one(inertia, a, c, first):
            ks, taus = scheme.stages(c, t0, dt, inertia, term.torque, a, tableau.num_stages, first)
            new = scheme.combine(c, dt, inertia, ks, taus, tableau.b_sol)
            embedded = scheme.combine(c, dt, inertia, ks, taus, tableau.b_sol - tableau.b_error)
            zeros = jnp.zeros((tableau.num_stages, 3), ks[0].dtype)
            info = dict(
                q0=c.state.q,
                theta1=_combination(dt, tableau.b_sol, ks),
                theta_stages=dt * jnp.stack(ks),
                momentum0=c.momentum,
                momentum1=new.momentum,
                momentum_stages=dt * jnp.stack(taus) if taus else zeros,
                inverse_inertia=_matrix(inertia.inverse),
            )
            error = RotState(new.state.q - embedded.state.q, new.state.omega - embedded.state.omega)
            last = taus[-1] if taus else None
            return new, error, info, last

        new, error, info, last = term.per_body(y0, args, one, carry, first_torque)
        if y0.q.ndim == 2:
            for key in ("theta_stages", "momentum_stages"):
                info[key] = jnp.swapaxes(info[key], 0, 1)
        y1 = _batched(y0, scheme.state, new)
        return y1, error, info, (new, last), diffrax.RESULTS.successful


class FluidSolver(SchemeSolver):
    """An exponential scheme (`jaxrot.FLUID_SCHEMES`) as a fixed-step diffrax solver, for a
    `jaxrot.RigidBodyTerm` with a ``fluid`` (use `jaxrot.solver` to build one).

    Its step is the scheme's ``in_fluid()`` step (the friction's relaxation exact at any ``ζΔt/I``)
    without `jaxrot.rollout`'s graded start: a body started off its slow manifold relaxes within
    ``I/ζ``, which a fixed ``dt0`` above that does not resolve (the adaptive `AdaptiveFluidSolver`
    shrinks its steps there itself). Forward in time only (``t1 > t0``): backwards, the friction's
    relaxation ``e^{+ζ|Δt|/I}`` grows without bound."""

    scheme: AbstractExponentialLieRK

    def _check_fluid(self, term):
        if term.fluid is None:
            raise ValueError(
                f"{self.scheme.name!r} integrates a body in a fluid: build the term with "
                "jaxrot.RigidBodyTerm(inertia, torque, fluid=jaxrot.Fluid(friction))."
            )

    def init(self, terms, t0, t1, y0, args):
        carry = super().init(terms, t0, t1, y0, args)
        _, direction = _check_term(terms, y0)
        # diffeqsolve traces the direction: the check runs with the program, on the carry every step reads.
        return eqx.error_if(
            carry, direction != 1, f"{self.scheme.name!r} in a fluid steps forward only: t1 > t0."
        )


class AdaptiveFluidSolver(FluidSolver, diffrax.AbstractAdaptiveSolver):
    """An exponential scheme with embedded weights (``"exp_rk5"``) as an adaptive diffrax solver in a fluid.

    Works with `diffrax.PIDController`. ``y_error`` is the scheme's `step_with_error`: the
    difference of the method and its embedded method of lower order in ``q`` and in the deviation
    ``ω − R S`` from the slow velocity, at no extra torque call; the controller's ``error_order``
    is diffrax's default for a pair of orders ``p``, ``p − 1`` (``p``). Dense output as `SchemeSolver`'s."""

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        term, direction = _check_term(terms, y0)
        scheme = self.scheme
        carry = self._carry(terms, t0, y0, args, solver_state, made_jump)
        t0, dt = t0 * direction, (t1 - t0) * direction

        def one(inertia, a, c):
            return scheme.step_with_error(c, t0, dt, inertia, term.torque, a)

        new, error = term.per_body(y0, args, one, carry)
        y1 = _batched(y0, scheme.state, new)
        return y1, error, self._hermite_info(term, y0, y1, dt, args), new, diffrax.RESULTS.successful


def _fluid_names():
    return ", ".join(repr(n) for n, s in FLUID_SCHEMES.items() if isinstance(s, AbstractExponentialLieRK))


def _matrix(inverse):
    return jnp.diag(inverse) if inverse.ndim == 1 else inverse


def solver(scheme: Any) -> SchemeSolver:
    """A diffrax solver that steps with a jaxrot scheme, for a `jaxrot.RigidBodyTerm`.

    Schemes with an embedded error estimate and a continuous extension (the
    Lie-group Runge–Kutta pairs ``"rkmk_dopri5"``, ``"rkmk_dopri8"``) give a
    `diffrax.AbstractAdaptiveSolver` for `diffrax.PIDController`; every other scheme a
    fixed-step solver for `diffrax.ConstantStepSize` or `diffrax.StepTo`, whose
    constant-step result equals `jaxrot.rollout`'s. ``y`` is a `jaxrot.RotState`; ``q``
    stays unit to round-off at every step and in the dense output.

    In a fluid (a `jaxrot.RigidBodyTerm` with ``fluid=``): the exponential schemes
    (``"exp_midpoint"``, ``"exp_rk4"``: `FluidSolver`, fixed step; ``"exp_rk5"``, which has an
    embedded estimate: `AdaptiveFluidSolver`, for `diffrax.PIDController`), whose friction is exact
    at any ``ζΔt/I``. The other schemes refuse a term with a fluid.

    Gradients: `diffrax.RecursiveCheckpointAdjoint` (the default) and
    `diffrax.DirectAdjoint` differentiate through the steps. `diffrax.BacksolveAdjoint`
    does not apply: it integrates an augmented adjoint system, not a rigid body.

    Args:
        scheme: a name in `jaxrot.SCHEMES` or an `AbstractScheme` instance.

    Returns:
        `AdaptiveLieSolver` or `SchemeSolver`.

    Example:
        >>> import diffrax, jax.numpy as jnp, jaxrot
        >>> term = jaxrot.RigidBodyTerm(jnp.array([1.0, 2.0, 3.0]), None)
        >>> y0 = jaxrot.RotState(jnp.array([1.0, 0, 0, 0]), jnp.array([0.3, 1.0, 0.2]))
        >>> sol = diffrax.diffeqsolve(
        ...     term, jaxrot.solver("rkmk_dopri5"), 0.0, 10.0, 0.1, y0,
        ...     saveat=diffrax.SaveAt(ts=jnp.linspace(0, 10, 5)),
        ...     stepsize_controller=diffrax.PIDController(rtol=1e-8, atol=1e-8))
        >>> bool(jnp.allclose(jnp.linalg.norm(sol.ys.q, axis=-1), 1, atol=1e-14, rtol=0))
        True
    """
    if isinstance(scheme, str) and scheme in FLUID_SCHEMES:
        scheme = FLUID_SCHEMES[scheme]
    if isinstance(scheme, AbstractExponentialLieRK):  # a body in a fluid: a RigidBodyTerm with `fluid`
        scheme = scheme.in_fluid()
        return AdaptiveFluidSolver(scheme) if scheme.has_error_estimate else FluidSolver(scheme)
    scheme, _ = scheme_for_call(scheme, INERTIAL)  # a body in vacuum: the model a RigidBodyTerm is
    if isinstance(scheme, AbstractLieRungeKutta) and scheme.has_error_estimate and scheme.dense_output:
        return AdaptiveLieSolver(scheme)
    return SchemeSolver(scheme)
