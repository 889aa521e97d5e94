r"""jax_md's quaternion conjugate momentum and jaxrot's angular velocity, converted exactly both ways.

jax_md (`jax_md.rigid_body`, after Miller et al., J. Chem. Phys. 116, 8649 (2002)) carries a 3-d rigid
body's rotation as its orientation ``q`` (scalar first, body → world, the body axes its principal axes)
and the quaternion conjugate momentum ``P = 2 S(q) (0, L_b) = 2 q ⊗ (0, L_b)``, with ``L_b`` the
body-frame angular momentum; back, ``(0, L_b) = ½ S(q)ᵀ P = ½ q* ⊗ P``
(``rigid_body.conjugate_momentum_to_angular_momentum`` reads the vector part). jaxrot carries
``(q, ω)`` with ``ω`` the world-frame angular velocity (`jaxrot.RotState`): ``ω = R(q) (L_b / I)``.

Both maps are linear in the momentum; for a unit ``q`` and a ``P`` orthogonal to ``q`` (the
momenta jax_md's own steps produce, up to round-off) each inverts the other to a few ulps. A ``P``
with a component along ``q`` (the direction in which the momentum carries no motion) loses that
component on the way through ``L_b``, as jax_md's own kinetic energy and temperature ignore it.
"""

import jax.numpy as jnp

from .. import quaternion as quat
from .._state import RotState


def angular_momentum(q, momentum):
    """Body-frame angular momentum ``L_b = (½ q* ⊗ P)[1:]`` ``(..., 3)`` of jax_md's conjugate momentum.

    Args:
        q: ``(..., 4)`` orientations (scalar first, body → world), as jax_md's ``Quaternion.vec``.
        momentum: ``(..., 4)`` conjugate momenta ``P`` (jax_md's ``state.momentum.orientation.vec``).

    The same numbers as ``jax_md.rigid_body.conjugate_momentum_to_angular_momentum``.

    Example:
        >>> import jax.numpy as jnp
        >>> from jaxrot.jax_md import angular_momentum, conjugate_momentum
        >>> q = jnp.array([0.6, 0.0, 0.8, 0.0])
        >>> p = conjugate_momentum(q, jnp.array([1.0, 2.0, 3.0]))
        >>> [round(float(x), 12) for x in angular_momentum(q, p)]
        [1.0, 2.0, 3.0]
    """
    return 0.5 * quat.multiply(quat.conjugate(q), momentum)[..., 1:]


def conjugate_momentum(q, angular_momentum_body):
    """jax_md's conjugate momentum ``P = 2 q ⊗ (0, L_b)`` ``(..., 4)`` of a body-frame angular momentum.

    Args:
        q: ``(..., 4)`` orientations (scalar first, body → world).
        angular_momentum_body: ``(..., 3)`` ``L_b`` in the body (principal) frame.

    The same numbers as ``jax_md.rigid_body.angular_momentum_to_conjugate_momentum``; see
    `angular_momentum` for an example.
    """
    return 2 * quat.multiply(q, quat.pure(angular_momentum_body))


def to_rot_state(q, momentum, moments) -> RotState:
    """jaxrot's `RotState` ``(q, ω)`` of jax_md's orientation and conjugate momentum.

    Args:
        q: ``(..., 4)`` orientations (body → world; the body axes the principal axes, as
            ``jax_md.rigid_body.point_union_shape`` builds them).
        momentum: ``(..., 4)`` conjugate momenta ``P``.
        moments: ``(..., 3)`` principal moments of inertia (jax_md's ``state.mass.orientation``).

    Returns:
        ``RotState(q, omega)`` with ``q`` unchanged and ``omega = R(q) (L_b / I)`` ``(..., 3)``, world
        frame (rad per unit time).

    Example:
        >>> import jax.numpy as jnp
        >>> from jaxrot.jax_md import from_rot_state, to_rot_state
        >>> q, moments = jnp.array([0.6, 0.0, 0.8, 0.0]), jnp.array([1.0, 2.0, 3.0])
        >>> p = jnp.array([-3.2, -0.4, 2.4, -2.8])  # 2 q ⊗ (0, L_b) for L_b = (1, 2, -1)
        >>> s = to_rot_state(q, p, moments)  # body spin L_b / I = (1, 1, -1/3)
        >>> [round(float(x), 12) for x in from_rot_state(s, moments)[1]]
        [-3.2, -0.4, 2.4, -2.8]
    """
    body_spin = angular_momentum(q, momentum) / moments
    return RotState(q, quat.rotate(q, body_spin))


def from_rot_state(state: RotState, moments):
    """``(q, P)`` in jax_md's convention of a jaxrot `RotState` (world ``ω``) of bodies of principal
    ``moments`` ``(..., 3)``: ``P = 2 q ⊗ (0, I ⊙ R(q)ᵀ ω)`` ``(..., 4)``. Inverse of `to_rot_state`."""
    q, omega = state
    return q, conjugate_momentum(q, moments * quat.rotate(quat.conjugate(q), omega))


def body_torque(q, force):
    """Body-frame torque ``τ_b = (½ q* ⊗ F)[1:]`` ``(..., 3)`` of jax_md's orientation force ``F``
    ``(..., 4)`` (minus the energy's gradient in ``q``, projected on the tangent space): the map of
    the momentum, since the kick ``P += h F`` is ``L_b += h τ_b`` (Miller et al., eq. 2.20)."""
    return angular_momentum(q, force)


def moments_per_body(moments, q):
    """The principal moments broadcast to ``q``'s bodies ``(..., 3)`` (jax_md's mass may be shared)."""
    moments = jnp.asarray(moments)
    return jnp.broadcast_to(moments, (*q.shape[:-1], 3)).astype(q.dtype)
