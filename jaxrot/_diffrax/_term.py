"""`RigidBodyTerm`: the rigid-body equations of motion as a `diffrax.AbstractTerm`."""

from collections.abc import Callable
from typing import Any

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp

from .. import quaternion as quat
from .._inertia import body_inertia, check_inertia
from .._particles import PARTICLES, split_per_body, unwrap_per_body
from .._state import RotState
from .._validation import check_torque
from ..schemes._base import body_torque


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

    def __init__(self, inertia, torque: Callable[..., jax.Array] | None = None):
        check_torque(torque)
        inertia = jnp.asarray(inertia)
        if inertia.ndim not in (1, 2, 3) or inertia.shape[-1] != 3:
            raise ValueError(
                "`inertia` must be principal moments (3,) or a body-frame tensor (3, 3), shared, or "
                f"(N, 3) / (N, 3, 3) one per body; got shape {inertia.shape}."
            )
        self.inertia = inertia
        self.torque = torque

    def per_body(self, y: RotState, args, fn: Callable[..., Any], *arrays):
        """``fn(inertia, args, *arrays)`` for one body, vmapped when ``y`` holds ``N`` bodies.

        ``inertia`` is the body's `jaxrot.BodyInertia` and ``args`` its torque arguments
        (its row of every `jaxrot.per_body` leaf); ``arrays`` have the bodies as their
        leading axis when ``y`` does. The vmap axis is named ``"particles"``, so coupled
        torques of `jaxrot.torques` see the other bodies."""
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
        if not batch_shape:
            return fn(body_inertia(inertia), unwrap_per_body(args), *arrays)
        args_values, args_axes = split_per_body(args, batch_shape)

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
        tau_body = body_torque(self.torque, t, q_unit, y.omega, args)
        q_dot = 0.5 * quat.multiply(quat.pure(y.omega), y.q)
        return RotState(q_dot, quat.rotate(q_unit, inertia.angular_acceleration(omega_body, tau_body)))

    def contr(self, t0, t1, **kwargs):
        return t1 - t0

    def prod(self, vf: RotState, control) -> RotState:
        return jax.tree_util.tree_map(lambda v: control * v, vf)
