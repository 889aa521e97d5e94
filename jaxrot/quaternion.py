"""Unit quaternions for rotations, scalar first: ``q = [w, x, y, z]``.

Conventions (fixed for all of jaxrot):

- ``q`` has shape ``(..., 4)`` and maps body-frame vectors to the world frame:
  ``rotate(q, v_body) = q ⊗ (0, v_body) ⊗ q*``.  World to body is
  ``rotate(conjugate(q), v_world)``.
- ``q`` and ``-q`` are the same rotation; compare with `angle_between`.
- Rotation vectors (the argument of `exp`, the result of `log`) have shape
  ``(..., 3)``; their length is the rotation angle in radians.
- scipy's ``Rotation`` is scalar *last*: use `to_xyzw` / `from_xyzw`.

Every function broadcasts over leading axes and works under ``jit``, ``vmap``
and ``grad``. `exp`, `log` and `angle_between` have finite values and finite
gradients at the identity, and `log` also at a rotation of exactly 180°.

Example:
    >>> import jax.numpy as jnp
    >>> from jaxrot import quaternion as quat
    >>> q = quat.from_axis_angle(jnp.array([0.0, 0.0, 1.0]), jnp.pi / 2)
    >>> print(quat.rotate(q, jnp.array([1.0, 0.0, 0.0])).round(6).tolist())
    [0.0, 1.0, 0.0]
"""

import jax
import jax.numpy as jnp

from ._math import safe_norm, taylor_threshold
from ._trig import sincos


__all__ = [
    "angle_between",
    "conjugate",
    "exp",
    "from_axis_angle",
    "from_matrix",
    "from_xyzw",
    "identity",
    "log",
    "multiply",
    "normalize",
    "pure",
    "rotate",
    "to_matrix",
    "to_xyzw",
]


def identity(shape=(), dtype=None):
    """The identity rotation ``[1, 0, 0, 0]`` with leading shape ``shape``."""
    q = jnp.zeros((*shape, 4), dtype=dtype)
    return q.at[..., 0].set(1)


def multiply(p, q):
    """Hamilton product ``p ⊗ q`` of ``(..., 4)`` quaternions (applies ``q`` first)."""
    pw, px, py, pz = p[..., 0], p[..., 1], p[..., 2], p[..., 3]
    qw, qx, qy, qz = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return jnp.stack(
        [
            pw * qw - px * qx - py * qy - pz * qz,
            pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw,
        ],
        axis=-1,
    )


def pure(v):
    """The pure quaternion ``(0, v)`` of a ``(..., 3)`` vector."""
    return jnp.concatenate([jnp.zeros_like(v[..., :1]), v], axis=-1)


def conjugate(q):
    """``[w, -x, -y, -z]``: the inverse rotation of a unit quaternion."""
    return jnp.concatenate([q[..., :1], -q[..., 1:]], axis=-1)


def rotate(q, v):
    """Rotate ``(..., 3)`` vectors ``v`` by unit quaternions ``q`` (body → world).

    Uses ``v + 2w (u × v) + 2 u × (u × v)`` with ``q = (w, u)``, which equals
    ``q ⊗ (0, v) ⊗ q*`` for unit ``q`` at a third of the cost.
    """
    # Written out per component: a smaller graph than two jnp.cross calls, which
    # shortens compile times of the schemes that rotate several times per step.
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    vx, vy, vz = v[..., 0], v[..., 1], v[..., 2]
    tx = 2 * (y * vz - z * vy)
    ty = 2 * (z * vx - x * vz)
    tz = 2 * (x * vy - y * vx)
    return jnp.stack(
        [vx + w * tx + y * tz - z * ty, vy + w * ty + z * tx - x * tz, vz + w * tz + x * ty - y * tx], axis=-1
    )


def normalize(q):
    """``q / |q|``. A zero quaternion is not a rotation and gives NaN."""
    return q / jnp.linalg.norm(q, axis=-1, keepdims=True)


def from_axis_angle(axis, angle):
    """Rotation by ``angle`` radians ``(...)`` about ``axis`` ``(..., 3)``.

    ``axis`` need not be unit length but must be nonzero.
    """
    axis = jnp.asarray(axis)
    angle = jnp.asarray(angle)
    batch = jnp.broadcast_shapes(axis.shape[:-1], angle.shape)
    axis = jnp.broadcast_to(axis / jnp.linalg.norm(axis, axis=-1, keepdims=True), (*batch, 3))
    half = jnp.broadcast_to(0.5 * angle[..., None], (*batch, 1))
    return jnp.concatenate([jnp.cos(half), jnp.sin(half) * axis], axis=-1)


def exp(rotvec):
    """Quaternion of the rotation vector ``rotvec`` ``(..., 3)``, angle = ``|rotvec|``.

    ``exp(v) = (cos(|v|/2), sin(|v|/2) v/|v|)``. Near ``v = 0`` a Taylor branch
    (behind a double ``where``) keeps value and gradient exact and finite.
    """
    theta_sq = jnp.sum(rotvec * rotvec, axis=-1, keepdims=True)
    use_taylor = theta_sq < taylor_threshold(rotvec.dtype)
    theta = jnp.sqrt(jnp.where(use_taylor, 1, theta_sq))
    sin_half, cos_half = sincos(0.5 * theta)
    real = jnp.where(use_taylor, 1 - theta_sq / 8 + theta_sq**2 / 384, cos_half)
    imag_factor = jnp.where(use_taylor, 0.5 - theta_sq / 48 + theta_sq**2 / 3840, sin_half / theta)
    return jnp.concatenate([real, imag_factor * rotvec], axis=-1)


def cayley(rotvec):
    """Unit quaternion of the Cayley map of ``rotvec`` ``(..., 3)``: ``(1, v/2) / √(1 + |v|²/4)``.

    The rotation ``(I − v̂/2)⁻¹ (I + v̂/2)``: about ``v`` by ``2 atan(|v|/2)``, equal to
    `exp` to second order (``cayley(v) = exp(v) + O(|v|³)``). No trigonometry and no
    branch: value and gradient are exact and finite everywhere, ``v = 0`` included. The
    chart of jaxrot's Lie-group Runge–Kutta schemes (`jaxrot.schemes.AbstractLieRungeKutta`).

    Example:
        >>> import jax.numpy as jnp
        >>> cayley(jnp.array([0.0, 0.0, 2.0])).tolist()  # 90° about z
        [0.7071067811865475, 0.0, 0.0, 0.7071067811865475]
    """
    half = 0.5 * rotvec
    scale = jax.lax.rsqrt(1 + jnp.sum(half * half, axis=-1, keepdims=True))
    return jnp.concatenate([scale, scale * half], axis=-1)


def log(q):
    """Rotation vector ``(..., 3)`` of ``q``, with angle in ``[0, π]``.

    Inverse of `exp` up to the sign of ``q``: ``q`` and ``-q`` give the same
    vector. Finite value and gradient at the identity and at 180°.
    """
    q = jnp.where(q[..., :1] < 0, -q, q)
    w = q[..., :1]
    v = q[..., 1:]
    s = safe_norm(v, keepdims=True)
    # atan(t)/t with t = s/w; near the identity its series avoids 0/0.
    t_sq = jnp.sum(v * v, axis=-1, keepdims=True) / jnp.where(w > 0, w * w, 1)
    use_taylor = (w > 0) & (t_sq < taylor_threshold(q.dtype))
    w_safe = jnp.where(use_taylor, w, 1)
    s_safe = jnp.where(use_taylor, 1, s)
    factor = jnp.where(
        use_taylor,
        (2 / w_safe) * (1 - t_sq / 3 + t_sq**2 / 5),
        2 * jnp.arctan2(s_safe, w) / s_safe,
    )
    return factor * v


def angle_between(q1, q2):
    """Geodesic angle (radians, in ``[0, π]``) between two rotations.

    Sign invariant: ``angle_between(q, -q) == 0``. Shape ``(...)``.
    """
    d = multiply(conjugate(q1), q2)
    return 2 * jnp.arctan2(safe_norm(d[..., 1:]), jnp.abs(d[..., 0]))


def to_matrix(q):
    """Rotation matrix ``(..., 3, 3)`` of unit ``q``: ``to_matrix(q) @ v == rotate(q, v)``."""
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    rows = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ]
    return jnp.stack([jnp.stack(r, axis=-1) for r in rows], axis=-2)


def from_matrix(m):
    """Unit quaternion of a rotation matrix ``(..., 3, 3)``, with ``w >= 0``.

    Shepperd's method: of the four algebraically equal formulas, use the one
    whose square root has the largest argument, so it never loses precision.
    """
    m00, m11, m22 = m[..., 0, 0], m[..., 1, 1], m[..., 2, 2]
    trace = m00 + m11 + m22
    # Each candidate is 4·c·q for a component c of q; pick the largest |4c²|.
    candidates = jnp.stack(
        [
            jnp.stack(
                [
                    1 + trace,
                    m[..., 2, 1] - m[..., 1, 2],
                    m[..., 0, 2] - m[..., 2, 0],
                    m[..., 1, 0] - m[..., 0, 1],
                ],
                axis=-1,
            ),
            jnp.stack(
                [
                    m[..., 2, 1] - m[..., 1, 2],
                    1 + m00 - m11 - m22,
                    m[..., 0, 1] + m[..., 1, 0],
                    m[..., 0, 2] + m[..., 2, 0],
                ],
                axis=-1,
            ),
            jnp.stack(
                [
                    m[..., 0, 2] - m[..., 2, 0],
                    m[..., 0, 1] + m[..., 1, 0],
                    1 - m00 + m11 - m22,
                    m[..., 1, 2] + m[..., 2, 1],
                ],
                axis=-1,
            ),
            jnp.stack(
                [
                    m[..., 1, 0] - m[..., 0, 1],
                    m[..., 0, 2] + m[..., 2, 0],
                    m[..., 1, 2] + m[..., 2, 1],
                    1 - m00 - m11 + m22,
                ],
                axis=-1,
            ),
        ],
        axis=-2,
    )
    diag = jnp.stack([1 + trace, 1 + m00 - m11 - m22, 1 - m00 + m11 - m22, 1 - m00 - m11 + m22], axis=-1)
    best = jnp.argmax(diag, axis=-1)
    chosen = jnp.take_along_axis(candidates, best[..., None, None], axis=-2)[..., 0, :]
    chosen_diag = jnp.take_along_axis(diag, best[..., None], axis=-1)
    q = chosen / (2 * jnp.sqrt(chosen_diag))
    return jnp.where(q[..., :1] < 0, -q, q)


def to_xyzw(q):
    """Scalar-first ``[w, x, y, z]`` → scalar-last ``[x, y, z, w]`` (scipy's order)."""
    return jnp.roll(q, -1, axis=-1)


def from_xyzw(q_xyzw):
    """Scalar-last ``[x, y, z, w]`` (scipy's order) → scalar-first ``[w, x, y, z]``."""
    return jnp.roll(q_xyzw, 1, axis=-1)
