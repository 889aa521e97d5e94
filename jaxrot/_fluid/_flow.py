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


def _like(x, ndim):
    """``x`` with leading axes of length 1 up to ``ndim`` axes: explicit broadcasting against bodies."""
    x = jnp.asarray(x)
    return x.reshape((1,) * (ndim - x.ndim) + x.shape)


def flow_rotation(q, velocity_gradient, bretherton):
    """``ω_f = Ω + B p × (E p)`` ``(..., 3)``, world frame; zeros for a fluid at rest (None).

    ``q`` ``(..., 4)``; the fluid's values shared or with the same leading axes."""
    if velocity_gradient is None:
        return jnp.zeros(q.shape[:-1] + (3,), q.dtype)
    p = symmetry_axis(q)
    strain = _like(strain_rate(velocity_gradient), p.ndim + 1)
    strained = jnp.sum(strain * p[..., None, :], axis=-1)
    shape_factor = _like(bretherton, p.ndim - 1)[..., None]
    return _like(vorticity_rate(velocity_gradient), p.ndim) + shape_factor * jnp.cross(p, strained)


def fluid_torque(q, omega, fluid):
    """World torque ``R (ζ ⊙ Rᵀ (ω_f − ω))`` of ``fluid`` (a `jaxrot.Fluid`) on bodies at ``(q, ω)``."""
    gap = flow_rotation(q, fluid.velocity_gradient, fluid.bretherton) - omega
    friction = _like(fluid.friction, gap.ndim)
    return quat.rotate(q, friction * quat.rotate(quat.conjugate(q), gap))


def overdamped_velocity(q, fluid, torque=None):
    """World ``ω = ω_f + R (ζ⁻¹ ⊙ Rᵀ τ)``: the angular velocity at which ``fluid``'s torque balances ``τ``."""
    omega = flow_rotation(q, fluid.velocity_gradient, fluid.bretherton)
    if torque is None:
        return omega
    friction = _like(fluid.friction, omega.ndim)
    return omega + quat.rotate(q, quat.rotate(quat.conjugate(q), torque) / friction)


def body_flow(q, velocity_gradient, bretherton):
    """``(g, rate)``: the flow's rotation in the body frame, ``g = Rᵀ ω_f`` ``(3,)`` at ``q``, and
    ``rate(u) -> ġ`` ``(3,)``, its rate of change along a body-frame angular velocity ``u``
    (``q̇ = ½ q ⊗ (0, u)``).

    With ``Ω_b = Rᵀ Ω`` and ``E_b = Rᵀ E R``: ``g = Ω_b + B e_z × (E_b e_z)`` and, as
    ``d(Rᵀ x)/dt = −u × Rᵀ x``, ``ġ = −u × Ω_b + B e_z × (E_b (u × e_z) − u × (E_b e_z))``. Written
    out: fewer operations than a `jax.jvp` of ``g`` (tests/test_fluid.py compares the two).
    """
    rotation = quat.to_matrix(q)
    vorticity = rotation.T @ vorticity_rate(velocity_gradient)
    strain = rotation.T @ strain_rate(velocity_gradient) @ rotation
    strained_axis = strain[:, 2]  # E_b e_z

    def ez_cross(w):  # e_z × w
        return jnp.stack([-w[1], w[0], jnp.zeros_like(w[0])])

    def rate(u):
        axis_rate = strain @ jnp.stack([u[1], -u[0], jnp.zeros_like(u[0])]) - jnp.cross(u, strained_axis)
        return -jnp.cross(u, vorticity) + bretherton * ez_cross(axis_rate)

    return vorticity + bretherton * ez_cross(strained_axis), rate
