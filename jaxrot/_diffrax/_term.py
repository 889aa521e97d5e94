"""`RigidBodyTerm`: the rigid-body equations of motion as a `diffrax.AbstractTerm`."""

from collections.abc import Callable
from typing import Any

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp

from .. import quaternion as quat
from .._fluid._flow import fluid_torque
from .._fluid._fluid import Fluid, check_fluid
from .._inertia import body_inertia, check_inertia
from .._integrate._bind import temperature
from .._particles import PARTICLES, split_per_body, unwrap_per_body
from .._state import RotState
from .._validation import check_torque
from ..schemes._base import body_torque, world_torque
from ..schemes._exponential import FluidArgs


class RigidBodyTerm(diffrax.AbstractTerm):
    """The rigid-body equations of motion, for `diffrax.diffeqsolve`.

    The state ``y`` is a `jaxrot.RotState` ``(q, omega)``: ``q`` ``(4,)`` a unit
    quaternion, scalar first, body → world; ``omega`` ``(3,)`` the **world**
    angular velocity [rad / time]; or ``(N, 4)``/``(N, 3)`` for ``N`` bodies that
    share one step size (and may be coupled: the torque sees the particle axis
    ``"particles"`` as in `jaxrot.rollout`). ``args`` of `diffeqsolve` are the
    torque's ``args`` (leaves marked with `jaxrot.per_body` give one row per body).

    Its vector field is the Euclidean one in ``(q, ω)`` ∈ R⁴ × R³,
    ``q̇ = ½ (0, ω) ⊗ q`` and ``ω̇ = R I⁻¹ (τ_b − ω_b × I ω_b)`` with ``ω_b = Rᵀ ω``,
    so diffrax's own solvers (`diffrax.Tsit5`, `diffrax.Dopri8`) accept the term as
    it is: the generic comparison. They integrate ``q`` in R⁴ and let ``|q|`` drift;
    the solvers of `jaxrot.solver` step on the rotation group instead and keep ``q``
    unit to round-off.

    Args:
        inertia: body-frame inertia about the centre of mass [mass · length²]:
            principal moments ``(3,)`` or a symmetric tensor ``(3, 3)``, shared by
            all bodies, or ``(N, 3)``/``(N, 3, 3)`` one per body.
        torque: ``torque(t, q, omega, args) -> (3,)`` world-frame torque on one
            body, or None for a torque-free body.
        fluid: a `jaxrot.Fluid` at ``kT = 0`` (keyword), or None: its torque is added to
            ``torque`` (as `jaxrot.rollout`'s ``fluid=``), so diffrax's solvers integrate it as a plain
            torque and `jaxrot.solver` of an exponential scheme (``"exp_rk5"``, adaptive) takes its
            friction exactly. The inertia must then be principal moments ``(3,)`` (or ``(N, 3)``) about
            the friction's axes.

    Example:
        >>> import diffrax, jax.numpy as jnp, jaxrot
        >>> term = jaxrot.RigidBodyTerm(jnp.array([1.0, 2.0, 3.0]), None)
        >>> y0 = jaxrot.RotState(jnp.array([1.0, 0, 0, 0]), jnp.array([0.0, 0, 2.0]))
        >>> sol = diffrax.diffeqsolve(term, diffrax.Tsit5(), 0.0, 1.0, 0.01, y0)
        >>> [round(float(x), 6) for x in sol.ys.q[-1]]  # steady spin about z: angle 2 rad
        [0.540302, 0.0, 0.0, 0.841471]
    """

    inertia: jax.Array
    torque: Callable[..., jax.Array] | None = eqx.field(static=True)
    fluid: Fluid | None = None

    def __init__(
        self, inertia, torque: Callable[..., jax.Array] | None = None, *, fluid: Fluid | None = None
    ):
        check_torque(torque)
        if fluid is not None and not isinstance(fluid, Fluid):
            raise ValueError(f"`fluid` must be None or a jaxrot.Fluid; got {type(fluid).__name__}.")
        # kT's value, or under jit what the Fluid recorded where it was built (as jaxrot.rollout reads it).
        if fluid is not None and temperature(fluid) != "zero":
            raise ValueError(
                "`fluid.kT` must be 0 for a RigidBodyTerm: its equations are deterministic (for a fluid at a "
                "temperature use jaxrot.rollout with a `key`)."
            )
        inertia = jnp.asarray(inertia)
        if inertia.ndim not in (1, 2, 3) or inertia.shape[-1] != 3:
            raise ValueError(
                "`inertia` must be principal moments (3,) or a body-frame tensor (3, 3), shared, or "
                f"(N, 3) / (N, 3, 3) one per body; got shape {inertia.shape}."
            )
        self.inertia = inertia
        self.torque = torque
        self.fluid = fluid

    def per_body(self, y: RotState, args, fn: Callable[..., Any], *arrays):
        """``fn(inertia, args, *arrays)`` for one body, vmapped when ``y`` holds ``N`` bodies.

        ``inertia`` is the body's `jaxrot.BodyInertia` and ``args`` its torque arguments
        (its row of every `jaxrot.per_body` leaf); ``arrays`` have the bodies as their
        leading axis when ``y`` does. The vmap axis is named ``"particles"``, so coupled
        torques of `jaxrot.torques` see the other bodies. With a ``fluid``, ``args`` is a `FluidArgs`:
        the torque's own and the body's fluid values (`jaxrot._fluid._fluid.check_fluid`)."""
        if not isinstance(y, RotState):
            raise ValueError(
                f"a RigidBodyTerm's state `y0` must be a jaxrot.RotState(q, omega) (world omega); "
                f"got {type(y).__name__}."
            )
        if y.q.ndim not in (1, 2):
            raise ValueError(
                f"`y0.q` must be (4,) for one body or (N, 4) for N bodies; got shape {y.q.shape}. "
                "Flatten the particle axes, or jax.vmap diffeqsolve over them."
            )
        batch_shape = y.q.shape[:-1]
        inertia, per_particle = check_inertia(self.inertia, batch_shape, y.q.dtype, runtime=False)
        if self.fluid is not None:
            fluid_values, fluid_axes = check_fluid(self.fluid, batch_shape, y.q.dtype)
        if not batch_shape:
            args = unwrap_per_body(args)
            return fn(
                body_inertia(inertia), args if self.fluid is None else FluidArgs(args, fluid_values), *arrays
            )
        args_values, args_axes = split_per_body(args, batch_shape)
        if self.fluid is not None:
            args_values, args_axes = FluidArgs(args_values, fluid_values), FluidArgs(args_axes, fluid_axes)

        def one(inert, a, *xs):
            return fn(body_inertia(inert), a, *xs)

        in_axes = (0 if per_particle else None, args_axes, *(0,) * len(arrays))
        return jax.vmap(one, in_axes=in_axes, axis_name=PARTICLES)(inertia, args_values, *arrays)

    def vf(self, t, y: RotState, args) -> RotState:
        """``(q̇, ω̇)`` at ``(t, y)``: the Euclidean vector field, world frame."""
        return self.per_body(y, args, lambda inertia, a, y_i: self._vector_field(inertia, a, t, y_i), y)

    def _vector_field(self, inertia, args, t, y: RotState) -> RotState:
        q_unit = quat.normalize(y.q)
        omega_body = quat.rotate(quat.conjugate(q_unit), y.omega)
        if self.fluid is None:
            tau_body = body_torque(self.torque, t, q_unit, y.omega, args)
        else:
            args, fluid = args
            tau = fluid_torque(q_unit, y.omega, fluid)
            if self.torque is not None:
                tau = tau + world_torque(self.torque, t, q_unit, y.omega, args)
            tau_body = quat.rotate(quat.conjugate(q_unit), tau)
        q_dot = 0.5 * quat.multiply(quat.pure(y.omega), y.q)
        return RotState(q_dot, quat.rotate(q_unit, inertia.angular_acceleration(omega_body, tau_body)))

    def contr(self, t0, t1, **kwargs):
        return t1 - t0

    def prod(self, vf: RotState, control) -> RotState:
        return jax.tree_util.tree_map(lambda v: control * v, vf)
