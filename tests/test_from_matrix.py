"""`quaternion.from_matrix`: the nearest rotation of a near-rotation matrix, refusals, and scipy's own cases.

scipy's cases are ported from scipy 1.17's ``scipy/spatial/transform/tests/test_rotation.py``
(``test_from_single_nd_matrix`` … ``test_from_matrix_int_dtype``, ``test_as_rotvec_degrees``,
``test_n_rotations``). scipy projects every matrix with a positive determinant onto its nearest
rotation (``_rotation_xp.from_matrix``: SVD ``U @ Vt`` where ``M Mᵀ`` is not the identity within
1e-12); jaxrot does that only within ``tol`` (2e-2 by default), so scipy's far-from-rotation
inputs are ported with ``tol=math.inf`` and checked to be refused by default.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from scipy.stats import special_ortho_group

from jaxrot import quaternion as quat


EPS = float(np.finfo(np.float64).eps)


def scipy_quat(m):
    """scipy's quaternion of ``m`` (its SVD projection), scalar first."""
    return np.asarray(quat.from_xyzw(jnp.asarray(Rotation.from_matrix(np.asarray(m)).as_quat())))


def assert_same_rotation(q, expected, atol):
    np.testing.assert_array_less(np.asarray(quat.angle_between(jnp.asarray(q), jnp.asarray(expected))), atol)


# --- scipy's cases -------------------------------------------------------------


@pytest.mark.parametrize("ndim", range(1, 6))
def test_scipy_from_single_nd_matrix(ndim):
    mat = jnp.array([[0, 0, 1], [1, 0, 0], [0, 1, 0]]).reshape((1,) * (ndim - 1) + (3, 3))
    expected = np.full((1,) * (ndim - 1) + (4,), 0.5)
    np.testing.assert_allclose(quat.from_matrix(mat), expected, atol=4 * EPS)


def test_scipy_from_matrix_calculation():
    expected = quat.from_xyzw(jnp.array([1.0, 1, 6, 1]) / math.sqrt(39))
    mat = jnp.array(
        [
            [-0.8974359, -0.2564103, 0.3589744],
            [0.3589744, -0.8974359, 0.2564103],
            [0.2564103, 0.3589744, 0.8974359],
        ]
    )
    np.testing.assert_allclose(quat.from_matrix(mat), expected, atol=1e-8)
    np.testing.assert_allclose(quat.from_matrix(mat.reshape(1, 3, 3)), expected.reshape(1, 4), atol=1e-8)


def test_scipy_matrix_calculation_pipeline():
    mat = special_ortho_group.rvs(3, size=10, random_state=0)
    np.testing.assert_allclose(quat.to_matrix(quat.from_matrix(jnp.asarray(mat))), mat, atol=16 * EPS)


def test_scipy_from_matrix_ortho_output():
    """Random matrices (entries in [0, 1), det made positive): far from rotations, projected with
    ``tol=math.inf`` to orthogonal matrices and to scipy's quaternions; refused by default."""
    mat = np.random.RandomState(0).random_sample((100, 3, 3))
    mat[np.linalg.det(mat) < 0] *= -1
    q = quat.from_matrix(jnp.asarray(mat), tol=math.inf)
    ortho = np.asarray(quat.to_matrix(q))
    np.testing.assert_allclose(
        ortho @ np.swapaxes(ortho, -1, -2), np.broadcast_to(np.eye(3), mat.shape), atol=1e-12
    )
    # The projections agree with scipy's SVD to round-off times the matrices' condition numbers (< 1e4).
    assert_same_rotation(q, scipy_quat(mat), 1e-11)
    with pytest.raises(ValueError, match=r"`m` at index \(0,\) is .* from the nearest rotation"):
        quat.from_matrix(jnp.asarray(mat))


@pytest.mark.parametrize(
    "mat, expected",
    [
        (
            [[1, 1, 0], [0, 1, 0], [0, 0, 1]],
            [[0.894427, 0.447214, 0.0], [-0.447214, 0.894427, 0.0], [0.0, 0.0, 1.0]],
        ),
        ([[0, -0.5, 0], [0.5, 0, 0], [0, 0, 0.5]], [[0.0, -1, 0], [1, 0, 0], [0, 0, 1]]),
    ],
    ids=["shear", "half_scale"],
)
def test_scipy_from_matrix_normalize(mat, expected):
    mat, expected = jnp.asarray(mat, float), np.asarray(expected)
    np.testing.assert_allclose(quat.to_matrix(quat.from_matrix(mat, tol=math.inf)), expected, atol=1e-6)
    # A mix of projected and exact matrices.
    both = quat.from_matrix(jnp.stack([mat, jnp.eye(3)]), tol=math.inf)
    np.testing.assert_allclose(quat.to_matrix(both), np.stack([expected, np.eye(3)]), atol=1e-6)
    with pytest.raises(ValueError, match="from the nearest rotation"):
        quat.from_matrix(mat)


@pytest.mark.parametrize("corner", [0.0, -1.0], ids=["singular", "reflection"])
def test_scipy_from_matrix_non_positive_determinant(corner):
    mat = jnp.eye(3).at[0, 0].set(corner)
    with pytest.raises(ValueError, match="determinant"):
        quat.from_matrix(mat)
    with pytest.raises(ValueError, match="determinant"):
        quat.from_matrix(mat, tol=math.inf)
    # Traced, the check cannot run: NaN, as scipy's lazy backends give, never a wrong rotation.
    assert np.all(np.isnan(jax.jit(quat.from_matrix)(mat)))


def test_scipy_from_matrix_array_like():
    rng = np.random.default_rng(123)
    r = Rotation.random(rng=rng)
    assert_same_rotation(quat.from_matrix(r.as_matrix().tolist()), scipy_quat(r.as_matrix()), 1e-12)
    r = Rotation.random(3, rng=rng)
    assert_same_rotation(quat.from_matrix(r.as_matrix().tolist()), scipy_quat(r.as_matrix()), 1e-12)


def test_scipy_from_matrix_int_dtype():
    assert quat.from_matrix(jnp.eye(3, dtype=int)).dtype == jnp.result_type(float)
    np.testing.assert_array_equal(quat.from_matrix(np.eye(3, dtype=int)), [1.0, 0, 0, 0])


def test_scipy_as_rotvec_degrees():
    rotvec = quat.log(quat.from_matrix(jnp.array([[0, 0, 1], [1, 0, 0], [0, 1, 0]])))  # x→y, y→z, z→x
    np.testing.assert_allclose(np.degrees(jnp.linalg.norm(rotvec)), 120.0, rtol=1e-14)
    np.testing.assert_allclose(rotvec[0], rotvec[1], rtol=1e-14)
    np.testing.assert_allclose(rotvec[1], rotvec[2], rtol=1e-14)


def test_scipy_n_rotations():
    mat = jnp.array([[[0, -1, 0], [1, 0, 0], [0, 0, 1]], [[1, 0, 0], [0, 0, -1], [0, 1, 0]]])
    assert quat.from_matrix(mat).shape == (2, 4)


# --- near-rotations: the nearest rotation, and the tolerance -------------------


def _printed(m, digits, significant):
    fmt = f"{{:.{digits}{'g' if significant else 'f'}}}"
    return np.vectorize(lambda x: float(fmt.format(x)))(m)


@pytest.mark.parametrize("digits", [2, 3, 6])
@pytest.mark.parametrize("significant", [False, True], ids=["decimals", "significant"])
def test_printed_rotation_matrices_give_their_nearest_rotation(digits, significant):
    """Rotation matrices printed with 2, 3 or 6 digits: accepted, and turned into the unit quaternion
    of their polar factor (scipy's SVD projection) to round-off. The 3-digit case once gave
    |q| − 1 = 3.6e-5, which `rollout` refuses."""
    rotations = Rotation.random(500, rng=np.random.default_rng(digits)).as_matrix()
    printed = _printed(rotations, digits, significant)
    distance = np.max(np.abs(np.linalg.svd(printed, compute_uv=False) - 1), axis=-1)
    assert distance.max() <= 1.5 * 10.0**-digits  # the bound that MATRIX_TOL is argued from
    q = quat.from_matrix(jnp.asarray(printed))
    # Unit to round-off (one division by the norm: a few eps), the projection to the SVD's round-off.
    np.testing.assert_allclose(jnp.linalg.norm(q, axis=-1), 1.0, rtol=0, atol=4 * EPS)
    assert_same_rotation(q, scipy_quat(printed), 64 * EPS)
    # ... and within the print's error E of the rotation R that was printed: the polar factor P moves
    # by ‖P − R‖_F ≤ 2 ‖E‖_F / (1 + σ_min) (R.-C. Li, SIAM J. Matrix Anal. Appl. 16, 1995), and the
    # angle is about ‖P − R‖_F / √2.
    error = np.linalg.norm(printed - rotations, axis=(-2, -1))
    assert_same_rotation(q, scipy_quat(rotations), error + 64 * EPS)


def test_tolerance_boundary_and_message():
    """Singular values 1 ± 0.019 pass, 1.021 is refused, with the batch index, the distance and the fix."""
    rot = special_ortho_group.rvs(3, random_state=1)
    near = rot @ np.diag([1.019, 1.0, 0.981])
    far = rot @ np.diag([1.0, 1.021, 1.0])
    assert_same_rotation(quat.from_matrix(jnp.asarray(near)), scipy_quat(rot), 16 * EPS)
    batch = np.stack([np.stack([rot, rot]), np.stack([rot, far])])
    with pytest.raises(
        ValueError, match=r"`m` at index \(1, 1\) is 0\.021 from .* tol=0\.02.* pass a larger `tol`"
    ):
        quat.from_matrix(jnp.asarray(batch))
    assert quat.from_matrix(jnp.asarray(batch), tol=0.03).shape == (2, 2, 4)


@pytest.mark.parametrize(
    "mat, match",
    [
        (np.diag([-1.0, -1.0, -1.0]), "determinant -1 ≤ 0"),  # a point reflection
        (np.diag([1.0, 1.0, -1.0]), "determinant -1 ≤ 0"),  # a mirror
        (np.zeros((3, 3)), "determinant 0 ≤ 0"),
        (np.diag([1.0, 2.0, 3.0]), "from the nearest rotation"),  # an inertia tensor passed by mistake
        (1.03 * np.eye(3), "0.03 from the nearest rotation"),
        (np.full((3, 3), np.nan), "NaN or infinite"),
    ],
    ids=["point_reflection", "mirror", "zero", "inertia", "scale_3pc", "nan"],
)
def test_non_rotations_are_refused(mat, match):
    with pytest.raises(ValueError, match=match):
        quat.from_matrix(jnp.asarray(mat))


def test_shape_is_checked():
    with pytest.raises(ValueError, match=r"shape \(\.\.\., 3, 3\)"):
        quat.from_matrix(jnp.eye(4))


def test_traced_input_skips_the_checks_and_still_projects():
    """Under jit and vmap nothing is checked (values unknown), and a matrix beyond `tol` still gets
    its nearest rotation: skipped, never wrong."""
    mat = np.random.RandomState(1).random_sample((8, 3, 3))
    mat[np.linalg.det(mat) < 0] *= -1
    expected = scipy_quat(mat)
    assert_same_rotation(jax.jit(quat.from_matrix)(jnp.asarray(mat)), expected, 1e-11)
    assert_same_rotation(jax.vmap(quat.from_matrix)(jnp.asarray(mat)), expected, 1e-11)


# --- round trips at the edge cases, float32, gradients ---------------------------

EDGE_ROTVECS = {
    "identity": [0.0, 0.0, 0.0],
    "tiny": [1e-12, -2e-12, 3e-12],
    "180_x": [np.pi, 0.0, 0.0],
    "180_y": [0.0, np.pi, 0.0],
    "180_z": [0.0, 0.0, np.pi],
    "180_generic": (np.pi * np.array([1.0, -2.0, 2.0]) / 3).tolist(),
    "w_near_0": ((np.pi - 1e-9) * np.array([0.6, 0.0, 0.8])).tolist(),
    "90_y": [0.0, np.pi / 2, 0.0],
}


@pytest.mark.parametrize("rotvec", EDGE_ROTVECS.values(), ids=EDGE_ROTVECS.keys())
def test_round_trip_at_edge_cases(rotvec):
    """``from_matrix(to_matrix(q)) = ±q`` and ``to_matrix(from_matrix(m)) = m`` to a few eps (each
    entry of `to_matrix` and each step carry one or two roundings), with ``w ≥ 0``; at 180° ``q``
    and ``-q`` both have ``w = 0``, so the comparison is sign-invariant."""
    q = quat.exp(jnp.asarray(rotvec))
    m = quat.to_matrix(q)
    back = quat.from_matrix(m)
    assert float(back[0]) >= 0
    np.testing.assert_allclose(abs(float(jnp.dot(back, q))), 1.0, rtol=0, atol=4 * EPS)
    np.testing.assert_allclose(jnp.minimum(jnp.abs(back - q), jnp.abs(back + q)), 0.0, atol=8 * EPS)
    np.testing.assert_allclose(quat.to_matrix(back), m, atol=8 * EPS)


# Compiled, one program each for every point: eagerly, each operation of the Newton iteration's
# derivatives compiled a program of its own (141 programs at the first point).
JACREV = jax.jit(jax.jacrev(quat.from_matrix))
JACFWD = jax.jit(jax.jacfwd(quat.from_matrix))


@pytest.mark.parametrize("rotvec", EDGE_ROTVECS.values(), ids=EDGE_ROTVECS.keys())
def test_gradient_is_finite_and_matches_finite_differences(rotvec):
    """The Newton polar iteration keeps the derivative finite at exact rotations, where an SVD's
    (1/(σᵢ² − σⱼ²)) is not. Away from the sign flip at w = 0 the Jacobian matches central
    differences of scipy's SVD projection (truncation ~h², round-off ~eps/h: 1e-7 at h = 1e-5)."""
    m = quat.to_matrix(quat.exp(jnp.asarray(rotvec)))
    jac = JACREV(m)
    assert np.all(np.isfinite(jac)) and np.all(np.isfinite(JACFWD(m)))
    if abs(float(quat.from_matrix(m)[0])) < 1e-3:
        return  # w = 0: -q and q swap across the point; only finiteness is asked there.
    h = 1e-5
    fd = np.zeros((4, 3, 3))
    for i in range(3):
        for j in range(3):
            e = np.zeros((3, 3))
            e[i, j] = h
            fd[:, i, j] = (scipy_quat(np.asarray(m) + e) - scipy_quat(np.asarray(m) - e)) / (2 * h)
    np.testing.assert_allclose(jac, fd, atol=1e-7)


def test_float32_keeps_dtype_and_unit_norm():
    printed = _printed(Rotation.random(50, rng=np.random.default_rng(5)).as_matrix(), 3, True)
    q = quat.from_matrix(jnp.asarray(printed, jnp.float32))
    assert q.dtype == jnp.float32
    eps32 = float(np.finfo(np.float32).eps)
    np.testing.assert_allclose(jnp.linalg.norm(q, axis=-1), 1.0, rtol=0, atol=4 * eps32)
    assert_same_rotation(np.asarray(q, np.float64), scipy_quat(printed), 64 * eps32)
