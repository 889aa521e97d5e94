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

    As ``d(Rᵀ x)/dt = −u × Rᵀ x + Rᵀ ẋ`` and ``Ω`` is constant: ``ġ = −u × g + Rᵀ ω̇_f`` with
    ``ω̇_f = B (ṗ × (E p) + p × (E ṗ))``, ``ṗ = (R u) × p``. Written out: fewer operations than a
    `jax.jvp` of ``g`` (tests/test_fluid.py compares the two), and three products of ``R`` with a
    vector instead of the body-frame strain ``Rᵀ E R`` (two 3 × 3 matrix products per stage, most
    of an exponential step's operations in a shear: benchmarks/fluid_step_cost.py). The products
    stay matrix products: written as elementwise sums or as quaternion rotations, fewer operations
    ran slower on XLA:CPU (measured).
    """
    rotation = quat.to_matrix(q)
    strain = strain_rate(velocity_gradient)
    p = rotation[:, 2]
    strained = strain @ p  # E p
    g = rotation.T @ (vorticity_rate(velocity_gradient) + bretherton * jnp.cross(p, strained))

    def rate(u):
        p_dot = jnp.cross(rotation @ u, p)
        flow_dot = bretherton * (jnp.cross(p_dot, strained) + jnp.cross(p, strain @ p_dot))
        return -jnp.cross(u, g) + rotation.T @ flow_dot

    return g, rate
