"""Quaternion algebra: properties (hypothesis), scipy agreement, and the singular points."""

import hypothesis.extra.numpy as hnp
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, strategies as st
from scipy.spatial.transform import Rotation

from jaxrot import quaternion as quat


finite = st.floats(-1e3, 1e3, allow_nan=False, allow_infinity=False)
vectors = hnp.arrays(np.float64, (3,), elements=finite)


@st.composite
def unit_quaternions(draw):
    raw = draw(hnp.arrays(np.float64, (4,), elements=st.floats(-1, 1)))
    if np.linalg.norm(raw) < 1e-3:
        raw = np.array([1.0, 0, 0, 0]) + raw
    return jnp.asarray(raw / np.linalg.norm(raw))


@st.composite
def rotation_vectors(draw, max_angle=np.pi):
    """Directions with angles spanning 0, tiny (1e-12…) and up to `max_angle`."""
    direction = draw(hnp.arrays(np.float64, (3,), elements=st.floats(-1, 1)))
    if np.linalg.norm(direction) < 1e-3:
        direction = np.array([0.0, 0.0, 1.0])
    direction = direction / np.linalg.norm(direction)
    angle = draw(
        st.one_of(
            st.just(0.0),
            st.floats(1e-12, 1e-4),
            st.floats(1e-4, max_angle),
        )
    )
    return jnp.asarray(direction * angle)


def same_rotation(q1, q2, atol):
    return float(quat.angle_between(q1, q2)) < atol


@given(unit_quaternions(), vectors)
def test_rotate_preserves_length(q, v):
    v = jnp.asarray(v)
    np.testing.assert_allclose(jnp.linalg.norm(quat.rotate(q, v)), jnp.linalg.norm(v), rtol=1e-12, atol=1e-9)


@given(unit_quaternions(), vectors)
def test_rotate_equals_sandwich_product(q, v):
    v = jnp.asarray(v)
    sandwich = quat.multiply(quat.multiply(q, jnp.concatenate([jnp.zeros(1), v])), quat.conjugate(q))
    np.testing.assert_allclose(quat.rotate(q, v), sandwich[1:], atol=1e-9)
    np.testing.assert_allclose(sandwich[0], 0.0, atol=1e-9)


@given(unit_quaternions())
def test_to_matrix_is_orthonormal_with_det_one(q):
    m = quat.to_matrix(q)
    np.testing.assert_allclose(m @ m.T, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(jnp.linalg.det(m), 1.0, atol=1e-12)


@given(unit_quaternions(), vectors)
def test_to_matrix_matches_rotate(q, v):
    v = jnp.asarray(v)
    np.testing.assert_allclose(quat.to_matrix(q) @ v, quat.rotate(q, v), atol=1e-9)


@given(unit_quaternions())
def test_from_matrix_inverts_to_matrix(q):
    assert same_rotation(quat.from_matrix(quat.to_matrix(q)), q, 1e-7)
    assert quat.from_matrix(quat.to_matrix(q))[0] >= 0


@given(rotation_vectors(max_angle=np.pi * (1 - 1e-9)))
def test_log_inverts_exp(v):
    np.testing.assert_allclose(quat.log(quat.exp(v)), v, atol=1e-9, rtol=1e-9)


@given(unit_quaternions())
def test_exp_inverts_log(q):
    back = quat.exp(quat.log(q))
    assert same_rotation(back, q, 1e-7)
    np.testing.assert_allclose(jnp.abs(jnp.dot(back, q)), 1.0, atol=1e-12)


@given(unit_quaternions(), unit_quaternions(), unit_quaternions())
def test_multiply_is_associative_and_conjugate_inverts(a, b, c):
    np.testing.assert_allclose(
        quat.multiply(quat.multiply(a, b), c), quat.multiply(a, quat.multiply(b, c)), atol=1e-12
    )
    np.testing.assert_allclose(quat.multiply(a, quat.conjugate(a)), jnp.array([1.0, 0, 0, 0]), atol=1e-12)


@given(unit_quaternions(), unit_quaternions())
def test_angle_between_is_sign_invariant_geodesic(a, b):
    angle = quat.angle_between(a, b)
    np.testing.assert_allclose(quat.angle_between(a, -b), angle, atol=1e-12)
    np.testing.assert_allclose(
        angle, jnp.linalg.norm(quat.log(quat.multiply(quat.conjugate(a), b))), atol=1e-7
    )
    assert 0 <= float(angle) <= np.pi + 1e-12


# --- agreement with scipy through the scalar-last converters -------------------


@given(unit_quaternions(), vectors)
def test_rotate_agrees_with_scipy(q, v):
    r = Rotation.from_quat(np.array(quat.to_xyzw(q)))
    np.testing.assert_allclose(quat.rotate(q, jnp.asarray(v)), r.apply(np.array(v)), atol=1e-9)
    np.testing.assert_allclose(quat.to_matrix(q), r.as_matrix(), atol=1e-12)


@given(unit_quaternions(), unit_quaternions())
def test_multiply_agrees_with_scipy_composition(a, b):
    ra = Rotation.from_quat(np.array(quat.to_xyzw(a)))
    rb = Rotation.from_quat(np.array(quat.to_xyzw(b)))
    expected = quat.from_xyzw(jnp.asarray((ra * rb).as_quat()))
    assert same_rotation(quat.multiply(a, b), expected, 1e-7)


@given(rotation_vectors())
def test_exp_log_agree_with_scipy_rotvec(v):
    r = Rotation.from_rotvec(np.array(v))
    assert same_rotation(quat.exp(v), quat.from_xyzw(jnp.asarray(r.as_quat())), 1e-7)
    q = quat.from_xyzw(jnp.asarray(r.as_quat()))
    np.testing.assert_allclose(jnp.linalg.norm(quat.log(q)), np.linalg.norm(r.as_rotvec()), atol=1e-7)


@given(unit_quaternions())
def test_from_matrix_agrees_with_scipy(q):
    m = np.array(quat.to_matrix(q))
    expected = quat.from_xyzw(jnp.asarray(Rotation.from_matrix(m).as_quat()))
    assert same_rotation(quat.from_matrix(jnp.asarray(m)), expected, 1e-7)


@given(unit_quaternions())
def test_xyzw_round_trip(q):
    np.testing.assert_array_equal(quat.from_xyzw(quat.to_xyzw(q)), q)
    assert float(quat.to_xyzw(q)[3]) == float(q[0])


def test_from_axis_angle_matches_exp_and_broadcasts():
    axis = jnp.array([[1.0, 0, 0], [0, 2.0, 0]])
    angle = jnp.array([0.5, -1.0])
    expected = quat.exp(axis / jnp.linalg.norm(axis, axis=-1, keepdims=True) * angle[:, None])
    np.testing.assert_allclose(quat.from_axis_angle(axis, angle), expected, atol=1e-15)
    assert quat.from_axis_angle(axis, 0.3).shape == (2, 4)


def test_functions_broadcast_over_leading_axes():
    rng = np.random.default_rng(0)
    q = quat.normalize(jnp.asarray(rng.normal(size=(2, 5, 4))))
    v = jnp.asarray(rng.normal(size=(2, 5, 3)))
    assert quat.rotate(q, v).shape == (2, 5, 3)
    assert quat.to_matrix(q).shape == (2, 5, 3, 3)
    assert quat.from_matrix(quat.to_matrix(q)).shape == (2, 5, 4)
    assert quat.log(q).shape == (2, 5, 3)
    assert quat.angle_between(q, q).shape == (2, 5)
    np.testing.assert_allclose(quat.rotate(q, v)[1, 3], quat.rotate(q[1, 3], v[1, 3]), atol=1e-15)


# --- singular points: value and gradient exactly there -------------------------


def _all_finite(tree):
    return all(bool(jnp.all(jnp.isfinite(x))) for x in jax.tree_util.tree_leaves(tree))


def test_exp_at_zero_value_and_jacobian():
    zero = jnp.zeros(3)
    np.testing.assert_array_equal(quat.exp(zero), jnp.array([1.0, 0, 0, 0]))
    for jac in (jax.jacfwd(quat.exp)(zero), jax.jacrev(quat.exp)(zero)):
        expected = jnp.concatenate([jnp.zeros((1, 3)), 0.5 * jnp.eye(3)])
        np.testing.assert_allclose(jac, expected, atol=1e-15)


def test_log_at_identity_value_and_jacobian():
    ident = jnp.array([1.0, 0, 0, 0])
    np.testing.assert_array_equal(quat.log(ident), jnp.zeros(3))
    for jac in (jax.jacfwd(quat.log)(ident), jax.jacrev(quat.log)(ident)):
        expected = jnp.concatenate([jnp.zeros((3, 1)), 2 * jnp.eye(3)], axis=1)
        np.testing.assert_allclose(jac, expected, atol=1e-15)


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_log_at_180_degrees_value_and_gradient(axis):
    """The jaxlie#9 failure mode: w = 0 exactly."""
    q = jnp.zeros(4).at[axis + 1].set(1.0)
    expected = jnp.zeros(3).at[axis].set(jnp.pi)
    np.testing.assert_allclose(quat.log(q), expected, atol=1e-15)
    assert _all_finite(jax.jacrev(quat.log)(q))
    assert _all_finite(jax.jacfwd(quat.log)(q))
    assert _all_finite(jax.grad(lambda x: jnp.sum(quat.log(x) ** 2))(q))


@pytest.mark.parametrize("rotvec", [[0.0, 0.0, 0.0], [0.3, -0.2, 0.1]])
def test_angle_between_gradient_finite_at_equal_rotations(rotvec):
    q = quat.exp(jnp.array(rotvec))
    assert float(quat.angle_between(q, q)) < 1e-15
    assert _all_finite(jax.grad(quat.angle_between, argnums=(0, 1))(q, q))
    assert _all_finite(jax.grad(quat.angle_between, argnums=(0, 1))(q, -q))


@pytest.mark.parametrize("scale", [1e-9, 1e-6, 1e-3, 0.5, 3.0])
def test_exp_log_jacobians_match_finite_differences_near_and_far_from_zero(scale):
    v = scale * jnp.array([0.6, -0.3, 0.74])
    eps = 1e-5
    fd = jnp.stack([(quat.exp(v + eps * e) - quat.exp(v - eps * e)) / (2 * eps) for e in jnp.eye(3)], axis=1)
    np.testing.assert_allclose(jax.jacfwd(quat.exp)(v), fd, atol=1e-8)
    q = quat.exp(v)
    fd_log = jnp.stack(
        [(quat.log(q + eps * e) - quat.log(q - eps * e)) / (2 * eps) for e in jnp.eye(4)], axis=1
    )
    np.testing.assert_allclose(jax.jacrev(quat.log)(q), fd_log, atol=1e-6)


def test_float32_keeps_dtype():
    v = jnp.array([0.1, 0.2, 0.3], dtype=jnp.float32)
    q = quat.exp(v)
    assert q.dtype == jnp.float32
    assert quat.log(q).dtype == jnp.float32
    assert quat.rotate(q, v).dtype == jnp.float32
    assert quat.to_matrix(q).dtype == jnp.float32
    np.testing.assert_allclose(quat.log(q), v, atol=1e-6)
    assert _all_finite(jax.grad(lambda x: quat.exp(x).sum())(jnp.zeros(3, dtype=jnp.float32)))
