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
import numpy as np

from ._core._concrete import is_concrete
from ._core._math import safe_norm, taylor_threshold
from ._core._trig import sincos


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


def _from_orthogonal_matrix(m):
    """Unit quaternion (``w >= 0``) of a rotation matrix ``(..., 3, 3)`` known to be orthogonal.

    Shepperd's method: of the four algebraically equal formulas, use the one
    whose square root has the largest argument, so it never loses precision.
    For a matrix that is orthogonal only to round-off (an eigenbasis), where
    `from_matrix`'s projection would change nothing but the last bits.
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


# A rotation matrix rounded to d decimals (or d significant digits: its entries are at most 1) is off
# its rotation by at most 1.5 * 10**-d in the spectral norm: 9 entries each off by half a unit of the
# last digit, spectral ≤ Frobenius ≤ 3 × 0.5 * 10**-d. 2e-2 accepts every rotation matrix written with
# two or more digits (1.5e-2), and any round-off, and refuses a matrix that stretches or shrinks some
# direction by more than 2 %: a scale, a shear, a matrix that is something else.
MATRIX_TOL = 2e-2
# Newton steps of the polar decomposition: 3 reach float64 round-off from a distance of 2e-2, 8 from
# a condition number of 1e10 (the scaled iteration, measured on random matrices): enough that a
# traced input, whose distance is not checked, still gets its polar factor.
_POLAR_STEPS = 8


def _check_rotation_matrix(m, tol):
    """Eager: ``m`` ``(..., 3, 3)`` is finite, with a positive determinant, within ``tol`` of a rotation."""
    if m.ndim < 2 or m.shape[-2:] != (3, 3):
        raise ValueError(f"`m` must have shape (..., 3, 3) (rotation matrices); got {m.shape}.")
    if not is_concrete(m):
        return
    flat = np.asarray(m, dtype=np.float64).reshape(-1, 3, 3)
    where = (
        (lambda i: "")
        if m.ndim == 2
        else (lambda i: f" at index {tuple(int(k) for k in np.unravel_index(i, m.shape[:-2]))}")
    )
    bad = np.flatnonzero(~np.all(np.isfinite(flat), axis=(-2, -1)))
    if bad.size:
        raise ValueError(f"`m` contains NaN or infinite values{where(bad[0])}.")
    det = np.linalg.det(flat)
    bad = np.flatnonzero(det <= 0)
    if bad.size:
        raise ValueError(
            f"`m`{where(bad[0])} has determinant {det[bad[0]]:.3g} ≤ 0: a reflection or a singular matrix, "
            "not a rotation. A rotation matrix is right-handed (det = +1); a left-handed frame needs one "
            "axis negated."
        )
    distance = np.max(np.abs(np.linalg.svd(flat, compute_uv=False) - 1), axis=-1)
    bad = np.flatnonzero(distance > tol)
    if bad.size:
        raise ValueError(
            f"`m`{where(bad[0])} is {distance[bad[0]]:.3g} from the nearest rotation (its singular values "
            f"differ from 1 by up to that), more than tol={tol:g}: not a rotation matrix (a scaled, sheared "
            "or other matrix). Remove the scale or shear, or pass a larger `tol` (math.inf projects any "
            "matrix with a positive determinant onto its nearest rotation, as scipy does)."
        )


def _polar_factor(m):
    """The orthogonal factor ``R`` of ``m = R H`` (``H`` symmetric positive definite), ``(..., 3, 3)``.

    Newton's iteration ``X ← ½ (γX + (γX)⁻ᵀ)`` with the determinant scaling
    ``γ = |det X|^(-1/3)`` (Higham, *Functions of Matrices*, SIAM 2008, ch. 8),
    a fixed number of steps. Unlike an SVD, whose derivative divides by
    differences of singular values (all equal at a rotation), each step is
    smooth: gradients are finite at exact rotations. ``(γX)⁻ᵀ`` is the cofactor
    matrix over the determinant: the columns' cross products.
    """

    def newton(_, m):
        a, b, c = m[..., :, 0], m[..., :, 1], m[..., :, 2]
        cofactor = jnp.stack([jnp.cross(b, c), jnp.cross(c, a), jnp.cross(a, b)], axis=-1)
        det = jnp.sum(a * cofactor[..., :, 0], axis=-1)[..., None, None]
        gamma = jnp.cbrt(det) ** -1
        return 0.5 * (gamma * m + cofactor / (gamma * det))

    # A loop, not eight unrolled copies: its derivatives' programs compile several times faster.
    return jax.lax.fori_loop(0, _POLAR_STEPS, newton, m)


def from_matrix(m, *, tol=MATRIX_TOL):
    """Unit quaternion ``(..., 4)``, ``w >= 0``, of the rotation nearest to ``m`` ``(..., 3, 3)``.

    ``to_matrix(from_matrix(m))`` is the orthogonal polar factor of ``m``: the
    rotation nearest to ``m`` in the Frobenius norm, as scipy's
    ``Rotation.from_matrix`` computes it (with an SVD). A rotation matrix
    printed with a few digits, or accumulated in float32, comes back as the
    exact rotation it approximates. Refused eagerly with a ``ValueError``:

    - a determinant ≤ 0 (a reflection, a singular matrix; scipy refuses it too);
    - a matrix farther than ``tol`` from its nearest rotation, measured as
      ``max |σᵢ − 1|`` over its singular values σ (how much more or less than a
      rotation it stretches some direction). The default ``tol = 2e-2`` accepts
      any rotation matrix printed with two or more digits (rounding to d
      decimals or significant digits moves it by at most 1.5·10⁻ᵈ) and refuses
      a scale or a shear of more than 2 %. scipy refuses nothing with a
      positive determinant: ``tol=math.inf`` does the same here.

    Under ``jit`` with a traced ``m`` the checks are skipped (a determinant ≤ 0
    then gives NaN) and the result is still the nearest rotation: jit, vmap and
    grad work, with finite gradients at exact rotations (the polar factor is
    found by a Newton iteration, not an SVD). Then Shepperd's method, of the
    four algebraically equal formulas the one whose square root has the
    largest argument, turns the rotation into a quaternion.

    Example:
        >>> import jax.numpy as jnp, numpy as np
        >>> from jaxrot import quaternion as quat
        >>> m = jnp.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # 90° about z
        >>> print(np.round(quat.from_matrix(m), 6))
        [0.707107 0.       0.       0.707107]
        >>> printed = jnp.array([[0.866, -0.5, 0.0], [0.5, 0.866, 0.0], [0.0, 0.0, 1.0]])  # 30°, 3 digits
        >>> bool(abs(jnp.linalg.norm(quat.from_matrix(printed)) - 1) < 1e-15)  # unit to round-off
        True
        >>> quat.from_matrix(2 * m)  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        ValueError: `m` is 1 from the nearest rotation ...
    """
    m = jnp.asarray(m)
    if not jnp.issubdtype(m.dtype, jnp.floating):
        m = m.astype(jnp.result_type(float))
    _check_rotation_matrix(m, tol)
    return _project(m)


@jax.jit
def _project(m):
    """`from_matrix` after its checks, ``(..., 3, 3)`` → ``(..., 4)``. One compiled program per shape and
    dtype: called eagerly, its ~50 operations (the polar iteration, Shepperd's branches) would each
    compile one of their own, about as long as the whole program (measured per call of
    tests/test_from_matrix.py: ~50 programs before, 1 after). Inside a caller's ``jit`` it is inlined."""
    det = jnp.sum(m[..., :, 0] * jnp.cross(m[..., :, 1], m[..., :, 2]), axis=-1)[..., None, None]
    m = jnp.where(det > 0, m, jnp.nan)
    return normalize(_from_orthogonal_matrix(_polar_factor(m)))


def to_xyzw(q):
    """Scalar-first ``[w, x, y, z]`` → scalar-last ``[x, y, z, w]`` (scipy's order)."""
    return jnp.roll(q, -1, axis=-1)


def from_xyzw(q_xyzw):
    """Scalar-last ``[x, y, z, w]`` (scipy's order) → scalar-first ``[w, x, y, z]``."""
    return jnp.roll(q_xyzw, 1, axis=-1)
