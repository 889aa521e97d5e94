"""free_top: the exact torque-free motion against the diffrax reference, invariants and special cases."""

import jax
import jax.numpy as jnp
import np_quat
import numpy as np
import pytest
from helpers import MOMENTS, Q0, central_difference_grad, full_tensor, to_body_frame

import jaxrot
from jaxrot import analytic, quaternion as quat


# (name, principal moments, body-frame angular velocity, kind). "full tensor" is case A for a body
# whose body axes are not principal; the others have a diagonal inertia. Kinds: "generic" (checked
# against the reference up to t = 50), "separatrix", "near separatrix" (1e-9 off it), "steady".
# On the separatrix I₁(I₂−I₁)ω₁² = I₃(I₃−I₂)ω₃² = 12 exactly, so L² = 2E I₂ to the last bit.
CASES = [
    ("case A", (1.0, 2.0, 3.0), (0.3, 1.0, 2.0), "generic"),
    ("case B", (1.0, 2.0, 3.0), (2.0, 1.0, 0.3), "generic"),
    ("case B, negative components", (1.0, 2.0, 3.0), (-2.0, 0.7, -0.3), "generic"),
    ("case A, unsorted moments", (3.0, 1.0, 2.5), (0.3, 1.0, 2.0), "generic"),
    ("case A, omega_1 = 0", (1.0, 2.0, 3.0), (0.0, 1.0, 2.0), "generic"),
    ("symmetric, oblate", (1.0, 1.0, 1.7), (0.7, -0.4, 3.0), "generic"),
    ("symmetric, prolate", (1.0, 2.0, 2.0), (0.7, -0.4, 3.0), "generic"),
    ("spherical", (2.0, 2.0, 2.0), (0.7, -0.4, 3.0), "generic"),
    ("0.1% off the separatrix", (3.0, 4.0, 6.0), (2.002, 0.5, 1.0), "generic"),
    ("full tensor", (1.0, 2.0, 3.0), (0.3, 1.0, 2.0), "generic"),
    ("separatrix", (3.0, 4.0, 6.0), (2.0, 0.5, 1.0), "separatrix"),
    ("separatrix, -omega_1", (3.0, 4.0, 6.0), (-2.0, 0.5, 1.0), "separatrix"),
    ("separatrix, -omega_2, -omega_3", (3.0, 4.0, 6.0), (2.0, -0.5, -1.0), "separatrix"),
    ("separatrix, omega_2 = 0", (3.0, 4.0, 6.0), (2.0, 0.0, 1.0), "separatrix"),
    ("above the separatrix", (3.0, 4.0, 6.0), (2.0 * (1 + 1e-9), 0.5, 1.0), "near separatrix"),
    ("below the separatrix", (3.0, 4.0, 6.0), (2.0 * (1 - 1e-9), 0.5, 1.0), "near separatrix"),
    ("pure spin, axis 1", (1.0, 2.0, 3.0), (2.0, 0.0, 0.0), "steady"),
    ("pure spin, axis 2 (unstable)", (1.0, 2.0, 3.0), (0.0, -2.0, 0.0), "steady"),
    ("pure spin, axis 3", (1.0, 2.0, 3.0), (0.0, 0.0, 2.0), "steady"),
    ("at rest", (1.0, 2.0, 3.0), (0.0, 0.0, 0.0), "steady"),
    ("sphere", (2.0, 2.0, 2.0), (-1.0, 0.3, 0.2), "steady"),
    ("symmetric, transverse spin", (1.0, 1.0, 1.7), (0.7, -0.4, 0.0), "steady"),
]
NAMES = [case[0] for case in CASES]
TS = jnp.linspace(0.0, 50.0, 101)


def _indices(*kinds):
    return np.array([i for i, case in enumerate(CASES) if case[3] in kinds])


def _max_errors(traj, ref, index, steps=slice(None)):
    """Per-case max orientation angle and max |Δω| over the time steps."""
    q_err = np.max(np_quat.angle_between(traj.q[steps][:, index], ref.q[steps][:, index]), axis=0)
    omega_err = np.max(np.abs(traj.omega[steps][:, index] - ref.omega[steps][:, index]), axis=(0, 2))
    return q_err, omega_err


def _to_numpy(traj):
    return jaxrot.Trajectory(*(np.asarray(x, dtype=np.float64) for x in traj))


@pytest.mark.slow
def test_free_top_against_the_reference_and_in_the_special_cases():
    """Every case in one batch (one reference solve, one compile per inertia form and dtype).

    Generic cases, against Dopri8 at rtol = atol = 1e-13 up to t = 50 (measured at most
    4.3e-11 rad and 8.6e-11 in ω; the reference is the limit: for the sphere and pure spin
    the exact answer is exp(ω t) ⊗ q0 and the reference is off by 3.4e-11 rad at t = 50).
    Inertia as (3, 3) tensors and, for the diagonal ones, as (3,) moments.

    Separatrix: the motion is homoclinic, the body tends to pure spin about the intermediate
    axis. The reference agrees until the exponential sensitivity near that saddle takes over
    (measured 2.8e-11 rad and 3.5e-11 in ω for t <= 10; 2e-8 rad by t = 15, 0.14 rad at
    t = 50). Elliptic solutions 1e-9 off the separatrix on either side stay within 1e-8 of
    it for t <= 5 (and within 3e-11 of the reference for t <= 10).

    Steady rotation, ω × Iω = 0 (the unstable intermediate axis included): ω constant and
    q(t) = exp(ω t) ⊗ q0 to round-off, at any t.

    Energy and world angular momentum: relative drift below 5e-15 (measured); unit norm to
    round-off; q starts at q0 and has no q → −q jumps (ψ is unwrapped).

    float32: same dtype out; against float64 from the same rounded inputs, measured 3.8e-5 rad
    and 3.4e-5 in ω up to t = 50 (about 100 rad of rotation), 4.4e-4 rad 0.1% off the separatrix.
    """
    q0s, omegas, tensors = [], [], []
    for name, moments, omega_body, kind in CASES:
        # The separatrix and the unstable steady spin are hit only if the body-frame ω is
        # exactly the intended one (q0 = 1): after a round-off perturbation the motion leaves
        # the intermediate axis, as it physically does, by t ~ ln(1e16) / λ ≈ 30 here.
        exact_body = "separatrix" in kind or "unstable" in name
        q_principal = np.array([1.0, 0.0, 0.0, 0.0]) if exact_body else np.asarray(Q0)
        omegas.append(np_quat.rotate(q_principal, np.array(omega_body)))
        if name == "full tensor":  # the same body, described in a non-principal body frame
            q0s.append(np.asarray(to_body_frame(jaxrot.RotState(Q0, jnp.zeros(3))).q))
            tensors.append(np.asarray(full_tensor(jnp.array(moments))))
        else:
            q0s.append(q_principal)
            tensors.append(np.diag(moments))
    q0, omega0, tensors = np.stack(q0s), np.stack(omegas), np.stack(tensors)
    state = jaxrot.RotState(jnp.asarray(q0), jnp.asarray(omega0))
    ref = _to_numpy(jaxrot.reference_rollout(state, jnp.asarray(tensors), TS, rtol=1e-13, atol=1e-13))
    exact = _to_numpy(analytic.free_top(state, jnp.asarray(tensors), TS))
    diagonal = np.array([i for i, name in enumerate(NAMES) if name != "full tensor"])
    moments = jnp.array([CASES[i][1] for i in diagonal])
    diag_state = jaxrot.RotState(state.q[diagonal], state.omega[diagonal])
    from_moments = _to_numpy(analytic.free_top(diag_state, moments, TS))
    # The same motion from principal moments and from diag(moments) through eigh.
    assert np.max(np_quat.angle_between(from_moments.q, exact.q[:, diagonal])) < 1e-12

    generic = _indices("generic")
    q_err, omega_err = _max_errors(exact, ref, generic)
    report = {NAMES[i]: (a, b) for i, a, b in zip(generic, q_err, omega_err, strict=True)}
    assert np.max(q_err) < 1e-10 and np.max(omega_err) < 1e-10, report

    sep = _indices("separatrix")
    q_err, omega_err = _max_errors(exact, ref, _indices("separatrix", "near separatrix"), slice(0, 21))
    assert np.max(q_err) < 1e-10 and np.max(omega_err) < 1e-10  # t <= 10
    body = np_quat.rotate(np_quat.conjugate(exact.q[-1, sep]), exact.omega[-1, sep])
    l_norm = np.linalg.norm(
        np.array([3.0, 4.0, 6.0]) * np_quat.rotate(np_quat.conjugate(q0[sep]), omega0[sep]), axis=-1
    )
    # At t = 50: |ω₂| = |L| / I₂ and ω₁, ω₃ ~ e^(−ν t).
    np.testing.assert_allclose(np.abs(body[:, 1]), l_norm / 4.0, rtol=1e-10)
    assert np.max(np.abs(body[:, 0]) + np.abs(body[:, 2])) < 1e-5
    for i in _indices("near separatrix"):
        assert np.max(np.abs(exact.q[:11, sep[0]] - exact.q[:11, i])) < 1e-8

    steady = _indices("steady")
    spin = np_quat.exp(np.asarray(TS)[:, None, None] * omega0[None, steady])
    np.testing.assert_allclose(
        exact.q[:, steady], np_quat.multiply(spin, np.broadcast_to(q0[steady], spin.shape)), atol=1e-14
    )
    np.testing.assert_allclose(
        exact.omega[:, steady], np.broadcast_to(omega0[steady], spin.shape[:-1] + (3,)), atol=1e-14
    )

    np.testing.assert_allclose(exact.q[0], q0, atol=1e-15)
    np.testing.assert_allclose(exact.omega[0], omega0, atol=1e-14)
    assert np.min(np.sum(exact.q[1:] * exact.q[:-1], axis=-1)) > 0  # no sign flips; |ω| Δt < π here
    omega_body = np_quat.rotate(np_quat.conjugate(exact.q), exact.omega)
    l_body = np.einsum("pij,tpj->tpi", tensors, omega_body)
    energy = 0.5 * np.sum(omega_body * l_body, axis=-1)
    momentum = np_quat.rotate(exact.q, l_body)
    moving = np.array([i for i, name in enumerate(NAMES) if name != "at rest"])
    energy_drift = np.abs(energy[:, moving] / energy[:1, moving] - 1)
    momentum_drift = np.abs(momentum[:, moving] - momentum[:1, moving]) / np.linalg.norm(
        momentum[:1, moving], axis=-1, keepdims=True
    )
    assert np.max(energy_drift) < 5e-14 and np.max(momentum_drift) < 5e-14
    assert np.max(np.abs(np.linalg.norm(exact.q, axis=-1) - 1)) < 1e-14

    state32 = jaxrot.RotState(state.q.astype(jnp.float32), state.omega.astype(jnp.float32))
    tensors32 = jnp.asarray(tensors, dtype=jnp.float32)
    exact32 = analytic.free_top(state32, tensors32, TS.astype(jnp.float32))
    assert exact32.q.dtype == exact32.omega.dtype == exact32.t.dtype == jnp.float32
    exact32 = _to_numpy(exact32)
    assert np.all(np.isfinite(exact32.q)) and np.all(np.isfinite(exact32.omega))
    # Against float64 from the same (float32-rounded) inputs, so that the sensitivity of the
    # motion to its initial state (large near the separatrix) is not counted.
    rounded = jaxrot.RotState(state32.q.astype(jnp.float64), state32.omega.astype(jnp.float64))
    exact_rounded = _to_numpy(analytic.free_top(rounded, tensors32.astype(jnp.float64), TS))
    well_conditioned = np.array([i for i in generic if "separatrix" not in NAMES[i]])
    q_err32, omega_err32 = _max_errors(exact32, exact_rounded, well_conditioned)
    assert np.max(q_err32) < 1e-4  # measured 3.8e-5 rad (about 100 rad turned)
    assert np.max(omega_err32) < 1e-4  # measured 3.4e-5
    assert np.max(_max_errors(exact32, exact_rounded, generic)[0]) < 1e-3  # 4.4e-4, near the separatrix


@pytest.mark.slow
def test_batch_shapes_shared_inertia_and_start_time():
    rng = np.random.default_rng(2)
    q = quat.normalize(jnp.asarray(rng.normal(size=(2, 3, 4))))
    omega = jnp.asarray(rng.normal(size=(2, 3, 3)))
    ts = jnp.array([1.0, 3.5, -2.0, 1.0])  # any order; the state is at ts[0]
    tensor = full_tensor()
    exact = analytic.free_top(jaxrot.RotState(q, omega), tensor, ts)
    assert exact.q.shape == (4, 2, 3, 4) and exact.omega.shape == (4, 2, 3, 3)
    np.testing.assert_array_equal(exact.t, ts)
    np.testing.assert_allclose(exact.q[0], q, atol=1e-15)
    np.testing.assert_allclose(exact.q[3], q, atol=1e-15)
    # From the state at t = 3.5, back to t = 1 and on to t = -2: the same motion.
    later = analytic.free_top(
        jaxrot.RotState(exact.q[1], exact.omega[1]), tensor, jnp.array([3.5, 1.0, -2.0, 3.5])
    )
    assert float(jnp.max(quat.angle_between(later.q[1], q))) < 1e-13
    assert float(jnp.max(quat.angle_between(later.q[2], exact.q[2]))) < 1e-13
    np.testing.assert_allclose(later.omega[2], exact.omega[2], atol=1e-13)


@pytest.mark.slow
def test_gradients_are_finite_and_match_finite_differences():
    """At rest, for pure spin, a symmetric top and a generic one: finite. Generic and symmetric
    (including the symmetry-breaking inertia direction): equal to central differences."""
    ts = jnp.array([0.0, 1.5, 7.0])
    weights = jnp.array([0.3, -0.7, 0.2, 0.5])

    @jax.jit
    def loss(omega, inertia):
        out = analytic.free_top(jaxrot.RotState(Q0, omega), inertia, ts)
        return jnp.sum(out.q[-1] * weights) + jnp.sum(out.omega[-1])

    grad = jax.jit(jax.grad(loss, argnums=(0, 1)))
    checked = [
        ((0.0, 0.0, 0.0), (1.0, 2.0, 3.0), True),
        ((0.0, 0.0, 2.0), (1.0, 2.0, 3.0), False),  # pure spin: finite, not the wobble's derivative
        ((0.0, 1.0, 2.0), (1.0, 2.0, 3.0), True),  # ω₁ = 0: am(u₀) = π/2
        ((0.3, 1.0, 2.0), (1.0, 2.0, 3.0), True),
        ((2.0, 1.0, 0.3), (1.0, 2.0, 3.0), True),
        ((0.3, 1.0, 2.0), (1.0, 1.0, 1.7), True),
    ]
    for omega_body, moments, compare in checked:
        omega = quat.rotate(Q0, jnp.array(omega_body))
        inertia = jnp.array(moments)
        g_omega, g_inertia = grad(omega, inertia)
        assert bool(jnp.all(jnp.isfinite(g_omega))) and bool(jnp.all(jnp.isfinite(g_inertia)))
        if compare:
            for argnum, g in ((0, g_omega), (1, g_inertia)):
                fd = central_difference_grad(loss, (omega, inertia), argnum)
                np.testing.assert_allclose(g, fd, rtol=1e-6, atol=1e-8)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"state": jaxrot.RotState(jnp.ones(3), jnp.zeros(3))}, "state.q"),
        ({"state": jaxrot.RotState(2 * Q0, jnp.zeros(3))}, "unit"),
        ({"state": jaxrot.RotState(Q0, jnp.array([jnp.nan, 0.0, 0.0]))}, "NaN"),
        ({"inertia": jnp.array([1.0, 2.0, -3.0])}, "positive definite"),
        ({"inertia": jnp.array([1.0, 1.0, 3.0])}, "triangle"),
        ({"inertia": jnp.ones((2, 3))}, "inertia"),
        ({"ts": jnp.zeros((2, 2))}, "ts"),
        ({"ts": jnp.zeros((0,))}, "ts"),
        ({"ts": jnp.array([0.0, jnp.inf])}, "ts"),
    ],
    ids=[
        "q shape",
        "non-unit q",
        "NaN omega",
        "negative moment",
        "triangle",
        "inertia shape",
        "ts 2-D",
        "ts empty",
        "ts inf",
    ],
)
def test_bad_input_raises_value_error(kwargs, match):
    args = {"state": jaxrot.RotState(Q0, jnp.zeros(3)), "inertia": MOMENTS, "ts": TS} | kwargs
    with pytest.raises(ValueError, match=match):
        analytic.free_top(args["state"], args["inertia"], args["ts"])


def test_principal_axes_is_a_proper_rotation():
    for inertia in (jnp.array([3.0, 1.0, 2.5]), full_tensor(), jnp.diag(jnp.array([2.0, 1.0, 2.0]))):
        moments, r = analytic.principal_axes(inertia)
        assert bool(jnp.all(jnp.diff(moments) >= 0))
        rot = quat.to_matrix(r)
        tensor = inertia if inertia.ndim == 2 else jnp.diag(inertia)
        np.testing.assert_allclose(rot @ jnp.diag(moments) @ rot.T, tensor, atol=1e-14)
        assert float(jnp.linalg.det(rot)) == pytest.approx(1.0, abs=1e-14)


# Where the elliptic formulas' derivatives were once wrong by up to 1e17 (values right): short flights
# (|ω| t small, ω = 0 included, as in every step of "splitting" for a body started at rest), and
# near-steady rotation, for asymmetric and symmetric bodies (moments, body-frame ω, t). The first two
# are the measured points: ∂q/∂ω₀ was 2.5e7 and 1e17 for a true 2.5e-4.
NEAR_STEADY = [
    ((1.0, 2.0, 3.0), (0.0, 1e-8, 1e-9), 5e-4),
    ((1.0, 5.0, 5.0), (1e-20, 1.0, 0.1), 5e-4),
    ((1.0, 2.0, 3.0), (0.0, 0.0, 0.0), 5e-4),
    ((1.0, 2.0, 3.0), (0.0, 0.0, 0.0), 1.5),
    ((1e-6, 1.0, 1.0), (0.0, 1e-6, 1e-26), 5e-4),
    ((1.0, 5.0, 5.0), (1e-12, 1.0, 0.3), 1.5),  # prolate, ω almost ⊥ the symmetry axis
    ((2.0, 2.0, 3.0), (0.7, -0.4, 1e-22), 1.5),  # oblate, the same
    ((2.0, 2.0, 3.0), (1e-13, 2e-13, 1.0), 1.5),  # oblate, ω almost along the axis
    ((2.0, 2.0, 2.0), (0.7, -0.4, 0.2), 1.5),  # sphere: every inertia direction
    ((1.0, 2.0, 3.0), (1e-12, 7e-13, 1.0), 1.5),  # near the major axis
    ((1.0, 2.0, 3.0), (1.0, 7e-13, 1e-12), 1.5),  # near the minor axis
    ((1.0, 2.0, 3.0), (0.0, 0.0, 1.0), 1.5),  # exactly steady
    ((1.0, 2.0, 3.0), (1e-9, 7e-9, 1.0), 5e-3),  # near the major axis, just above the Taylor branch
]


def _near_steady_points():
    """The listed points and random near-steady ones, ε = |ω⊥|/|ω| from 1e-14 to 1e-3: about the major
    and minor axes of an asymmetric body, and about the symmetry axis or a generic transverse axis of a
    symmetric one. Not about the intermediate axis, nor about a transverse *principal* axis of a
    symmetric body (the central difference in the inertia makes it intermediate): there the values
    themselves lose accuracy (orientation error ~1e-17/ε for t ~ 1, a known limit)."""
    rng = np.random.default_rng(5)
    points = list(NEAR_STEADY)
    for moments, axes in (
        ((1.0, 2.0, 3.0), (0, 2)),
        ((1.0, 5.0, 5.0), (0, None)),
        ((2.0, 2.0, 3.0), (2, None)),
    ):
        for axis in axes:
            for t in (3e-4, 0.3, 2.0):
                eps = 10 ** rng.uniform(-14, -3)
                direction = np.zeros(3)
                if axis is None:  # a transverse axis of the symmetric body, not a coordinate axis
                    direction[1:] = (0.6, 0.8) if moments[0] < moments[1] else (0.0, 0.0)
                    if moments[0] == moments[1]:
                        direction[:2] = (0.6, 0.8)
                else:
                    direction[axis] = 1.0
                omega_body = (
                    eps * rng.normal(size=3) + rng.choice([-1.0, 1.0]) * rng.uniform(0.5, 2.0) * direction
                )
                points.append((moments, tuple(float(x) for x in omega_body), t))
    return points


_WEIGHTS = jnp.array([0.3, -0.7, 0.2, 0.5])


@jax.jit
def _one_flight_loss(q, omega, inertia, t):
    out = analytic.free_top(
        jaxrot.RotState(quat.normalize(q), omega), inertia, jnp.stack([jnp.zeros_like(t), t])
    )
    return jnp.sum(out.q[-1] * _WEIGHTS) + jnp.sum(out.omega[-1] * _WEIGHTS[1:])


_one_flight_grad = jax.jit(jax.grad(_one_flight_loss, argnums=(0, 1, 2)))


@pytest.mark.slow
@pytest.mark.parametrize("moments, omega_body, t", _near_steady_points())
def test_gradients_at_short_flights_and_near_steady_rotation(moments, omega_body, t):
    """free_motion's derivatives w.r.t. ω, q and the moments against 4th-order central differences
    (to 1e-6 of each gradient's size, plus 1e-12), finite at ω = 0. The moments go through free_top,
    whose principal_axes sorts them, so that a central difference may cross two equal moments."""
    omega = quat.rotate(Q0, jnp.array(omega_body))
    inertia = jnp.array(moments)
    t = jnp.asarray(t)
    grads = _one_flight_grad(Q0, omega, inertia, t)

    def loss(q, omega, inertia):
        return _one_flight_loss(q, omega, inertia, t)

    for argnum, g in enumerate(grads):
        assert bool(jnp.all(jnp.isfinite(g)))
        # A step of 1e-3 (relative): truncation ~1e-12, round-off in the loss ~1e-16 / h <= 2e-11.
        fd = central_difference_grad(loss, (Q0, omega, inertia), argnum, rel_step=1e-3)
        scale = float(jnp.max(jnp.abs(fd)))
        np.testing.assert_allclose(g, fd, rtol=0, atol=1e-6 * scale + 1e-12)
