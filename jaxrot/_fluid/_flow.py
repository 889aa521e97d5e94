"""The angular velocity a linear flow imposes on a body, and the fluid's torque (one body).

For a flow ``u(x) = A x`` (``A[i, j] = ∂u_i/∂x_j``, world frame, traceless) the fluid turns at
``Ω = ½ ∇ × u`` (``Ω_i = ½ ε_ijk A_kj``) and strains at ``E = ½ (A + Aᵀ)``. An axisymmetric body of
shape factor ``B`` (symmetry axis ``p``, the body z axis in the world) is turned by the flow at

    ω_f = Ω + B p × (E p)

(Jeffery, Proc. R. Soc. A 102, 161 (1922): then ``ṗ = ω_f × p = Ω × p + B (E p − (pᵀE p) p)``), and a
body turning at ``ω`` feels the torque ``τ = R (ζ ⊙ Rᵀ(ω_f − ω))`` (``R`` the rotation of ``q``,
``ζ`` the principal frictions about the body axes). Without inertia the torques balance:
``ω = ω_f + R (ζ⁻¹ ⊙ Rᵀ τ_other)`` (the overdamped model).
"""

import jax.numpy as jnp

from .. import quaternion as quat


def vorticity_rate(velocity_gradient):
    """``Ω = ½ ∇ × u`` ``(..., 3)`` of ``u = A x``, ``A`` ``(..., 3, 3)``: the fluid's angular velocity."""
    a = velocity_gradient
    return 0.5 * jnp.stack(
        [a[..., 2, 1] - a[..., 1, 2], a[..., 0, 2] - a[..., 2, 0], a[..., 1, 0] - a[..., 0, 1]], -1
    )


def strain_rate(velocity_gradient):
    """``E = ½ (A + Aᵀ)`` ``(..., 3, 3)``."""
    return 0.5 * (velocity_gradient + jnp.swapaxes(velocity_gradient, -1, -2))


def symmetry_axis(q):
    """The body z axis in the world, ``p = R e_z`` ``(..., 3)`` (the third column of the rotation)."""
    w, x, y, z = (q[..., i] for i in range(4))
    return jnp.stack([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)], -1)


def flow_rotation(q, velocity_gradient, bretherton):
    """``ω_f = Ω + B p × (E p)`` ``(3,)``, world frame, for one body; zeros for a fluid at rest (None)."""
    if velocity_gradient is None:
        return jnp.zeros(q.shape[:-1] + (3,), q.dtype)
    p = symmetry_axis(q)
    strained = jnp.einsum("...ij,...j->...i", strain_rate(velocity_gradient), p)
    return vorticity_rate(velocity_gradient) + bretherton[..., None] * jnp.cross(p, strained)


def fluid_torque(q, omega, fluid):
    """World torque ``R (ζ ⊙ Rᵀ (ω_f − ω))`` of ``fluid`` (a `jaxrot.Fluid`) on bodies at ``(q, ω)``."""
    gap = flow_rotation(q, fluid.velocity_gradient, jnp.asarray(fluid.bretherton)) - omega
    return quat.rotate(q, fluid.friction * quat.rotate(quat.conjugate(q), gap))


def overdamped_velocity(q, fluid, torque=None):
    """World ``ω = ω_f + R (ζ⁻¹ ⊙ Rᵀ τ)``: the angular velocity at which ``fluid``'s torque balances ``τ``."""
    omega = flow_rotation(q, fluid.velocity_gradient, jnp.asarray(fluid.bretherton))
    if torque is None:
        return omega
    return omega + quat.rotate(q, quat.rotate(quat.conjugate(q), torque) / fluid.friction)
