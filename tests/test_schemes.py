"""Every registered scheme: measured order, rest state, batching, float32, gradients, torque calls."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import (
    MOMENTS,
    PRINCIPAL_TO_BODY,
    ROTOR_SCHEMES,
    central_difference_grad,
    contract_params,
    fitted_order,
    full_tensor,
    gravity_args,
    order_errors,
    principal_state,
    rotor_flows,
    scheme_params,
    to_body_frame,
)

import jaxrot
from jaxrot import quaternion as quat
from jaxrot.scenes import gravity_torque, heavy_top
from jaxrot.schemes import Rozmanov


SCHEME_NAMES = list(jaxrot.SCHEMES)
TUMBLING = principal_state(omega_body=jnp.array([1.0, 2.0, 0.5]))

# Ladders in each scheme's asymptotic range: (scheme, t_end, coarse_steps); 5 halvings each.
# Rozmanov gets room to converge at the coarse end (dt = 0.1 needs ~10 iterations for 1e-13).
ORDER_LADDERS = {
    "zhao": ("zhao", 4.0, 40),
    "rozmanov": (Rozmanov(max_iter=20), 4.0, 40),
    "euler": ("euler", 2.0, 400),
    "no_squish": ("no_squish", 4.0, 40),
    "splitting": ("splitting", 4.0, 40),
}
# The high-order schemes' orders are fitted in tests/test_high_order.py, on ladders of their own.
ORDER_TESTED_ELSEWHERE = {"rkmk4", "rkmk_dopri5", "rkmk_dopri8", "srkn6b", "srkn14a"}
# Exact for a torque-free body at any dt (round-off only; tests/test_splitting.py): no order to fit.
EXACT_WHEN_TORQUE_FREE = {"splitting"}


def weight_args(weight_z):
    """Heavy-top torque arguments with a differentiable weight along z."""
    return {"offset_body": jnp.array([0.1, 0.05, 0.3]), "weight": weight_z * jnp.array([0.0, 0.0, 1.0])}


def test_every_scheme_has_a_ladder_and_metadata():
    assert set(ORDER_LADDERS) | ORDER_TESTED_ELSEWHERE == set(SCHEME_NAMES)
    for name, scheme in jaxrot.SCHEMES.items():
        assert scheme.name == name
        assert scheme.order in ((1, 2) if name in ORDER_LADDERS else (4, 5, 6, 8))
        assert scheme.torque_evals_per_step >= 1


# By default: Euler's under gravity (its order is measured nowhere else; Zhao's is, by default, in
# tests/test_zhao.py); the rest of the matrix in the slow set.
@pytest.mark.parametrize("inertia_form", ["diagonal", "full"])
@pytest.mark.parametrize("torque_name", [pytest.param("free", marks=pytest.mark.slow), "gravity"])
@pytest.mark.parametrize(
    "name",
    [pytest.param(n, marks=() if n == "euler" else pytest.mark.slow) for n in ORDER_LADDERS],
)
def test_measured_order(name, torque_name, inertia_form):
    """Log-log slope of max orientation error against dt, reference at rtol=atol=1e-13."""
    if torque_name == "free" and name in EXACT_WHEN_TORQUE_FREE:
        pytest.skip("exact for a torque-free body: see tests/test_splitting.py")
    scheme, t_end, coarse = ORDER_LADDERS[name]
    torque = None if torque_name == "free" else gravity_torque
    if inertia_form == "diagonal":
        state, inertia = TUMBLING, MOMENTS
        args = None if torque is None else gravity_args()
    else:
        state, inertia = to_body_frame(TUMBLING), full_tensor()
        args = None if torque is None else gravity_args(r=PRINCIPAL_TO_BODY)
    dts, errors = order_errors(scheme, state, inertia, t_end, coarse, 5, torque, args)
    assert errors[-1] > 1e-9  # far above the reference's own error
    assert fitted_order(dts, errors) == pytest.approx(jaxrot.SCHEMES[name].order, abs=0.15)


@pytest.mark.slow
@pytest.mark.parametrize("name", contract_params())
def test_zero_angular_velocity_without_torque_is_at_rest_with_finite_gradients(name):
    q0 = quat.exp(jnp.array([0.2, -0.1, 0.4]))
    traj = jaxrot.rollout(name, jaxrot.RotState(q0, jnp.zeros(3)), MOMENTS, 0.05, 50)
    np.testing.assert_array_equal(traj.omega, jnp.zeros_like(traj.omega))
    np.testing.assert_allclose(traj.q, jnp.broadcast_to(q0, traj.q.shape), atol=1e-15)

    weights = jnp.array([0.3, -0.7, 0.2, 0.5])

    def loss(omega0, inertia):
        out = jaxrot.rollout(name, jaxrot.RotState(q0, omega0), inertia, 0.05, 50)
        return jnp.sum(out.q[-1] * weights) + jnp.sum(out.omega[-1])

    # A full tensor here; the diagonal one in test_gradients_match_central_differences, whose compiled
    # gradient also serves ω0 = 0 (a gradient program costs 10-60 s to compile at conftest's -O0).
    g_omega, g_inertia = jax.jit(jax.grad(loss, argnums=(0, 1)))(jnp.zeros(3), full_tensor())
    assert bool(jnp.all(jnp.isfinite(g_omega))) and bool(jnp.all(jnp.isfinite(g_inertia)))
    assert float(jnp.linalg.norm(g_omega)) > 0  # a small spin does move the body


# ω = 0 under a torque, with finite gradients (and a central-difference check) through 10^4 steps,
# for every scheme: test_gradients_through_1e4_steps_at_extreme_bodies_and_rest in test_stability.py.


@pytest.mark.parametrize("name", contract_params())
def test_batch_equals_each_particle_alone(name):
    """Particles do not interact: a batch agrees with each particle alone to 1e-13 (relative).

    Not bitwise: batched and single runs compile to different SIMD code, measured to differ
    by 1-2 ulp per step (Zhao: |Δω| = 1.8e-15 after one step, 1.3e-13 after 20 at |ω| ≈ 5); a
    splitting by that much per free-rotor flow of a step."""
    rtol = 1e-13 * max(1, rotor_flows(name))
    rng = np.random.default_rng(1)
    n = 5
    q = quat.normalize(jnp.asarray(rng.normal(size=(n, 4))))
    omega = jnp.asarray(rng.normal(size=(n, 3)) * 2)
    inertia = jnp.asarray(rng.uniform(1.0, 2.0, size=(n, 3)))
    kwargs = dict(torque=gravity_torque, args=gravity_args(), save_every=10)
    batch = jaxrot.rollout(name, jaxrot.RotState(q, omega), inertia, 0.01, 20, **kwargs)
    for i in range(n):
        alone = jaxrot.rollout(name, jaxrot.RotState(q[i], omega[i]), inertia[i], 0.01, 20, **kwargs)
        np.testing.assert_allclose(batch.q[:, i], alone.q, rtol=rtol, atol=1e-15)
        np.testing.assert_allclose(batch.omega[:, i], alone.omega, rtol=rtol, atol=1e-15)


@pytest.mark.parametrize("name", scheme_params(SCHEME_NAMES))
def test_float32_in_float32_out_and_unit_norm_after_1000_steps(name):
    s32 = heavy_top(dtype=jnp.float32)
    traj = jaxrot.rollout(name, s32.state, s32.inertia, 0.005, 1000, torque=s32.torque, args=s32.args)
    assert traj.q.dtype == traj.omega.dtype == traj.t.dtype == jnp.float32
    assert float(jnp.max(jnp.abs(jnp.linalg.norm(traj.q, axis=-1) - 1))) < 1e-5


@pytest.mark.parametrize("name", scheme_params(SCHEME_NAMES))
def test_float32_round_off_accumulates_slowly(name):
    """1000 float32 steps of the heavy top stay within 1e-4 rad of the same run in float64, per
    free-rotor flow of a step for the splittings (each flow adds its own roundings).

    Measured (2026-11-29, the scene's I = (1.25, 2, 3) about the pivot): zhao 1.5e-5, rozmanov
    2.2e-6, euler 4.0e-6, no_squish 8.4e-6, splitting 6.4e-5 rad, srkn6b 1.2e-4 (5 flows), srkn14a
    1.0e-4 (15 flows). Zhao and NO_SQUISH update by increments so |ω| and |p|
    are not re-rounded each step; written the textbook way they drifted 3.4e-4 and 3.1e-4 rad,
    above their float64 truncation error."""
    s32, s64 = heavy_top(dtype=jnp.float32), heavy_top()
    traj32, traj64 = (
        jaxrot.rollout(name, s.state, s.inertia, 0.005, 1000, torque=s.torque, args=s.args, save_every=100)
        for s in (s32, s64)
    )
    bound = 1e-4 * max(1, rotor_flows(name))
    assert float(jnp.max(quat.angle_between(traj32.q.astype(jnp.float64), traj64.q))) < bound


# Measured |L| drift after 1e5 float32 steps of a free body (dt = 0.01, t = 1000), with the bound
# each must stay under. The splittings' DMV rotor corrects its output to the input's invariants
# (jaxrot._free_body._rotor), so what is left is an unbiased random walk of a few ulp per rotor flow:
# 10 eps sqrt(flows) bounds it (the elliptic rotor, `Splitting(rotor="exact")`, drifted 7.7e-3 here).
FLOAT32_MOMENTUM_DRIFT = {"zhao": 1e-3, "rozmanov": 1e-3, "no_squish": 1e-3}
FLOAT32_MOMENTUM_DRIFT |= {
    name: 10 * float(jnp.finfo(jnp.float32).eps) * (100_000 * rotor_flows(name)) ** 0.5
    for name in ROTOR_SCHEMES
}
# The Lie-group RK pairs carry L itself, unchanged by a torque-free step: what is left is the
# rounding of L recomputed from (q, ω) for the check, a few ulp (measured 1.3e-6). rkmk4 carries the
# body momentum, rounded once a step: a random walk, bounded as the rotors' (measured 1.6e-5; its
# truncation drift, 1e-7 over these 10^5 steps in float64, is below).
FLOAT32_MOMENTUM_DRIFT |= {"rkmk_dopri5": 1e-5, "rkmk_dopri8": 1e-5}
FLOAT32_MOMENTUM_DRIFT["rkmk4"] = 10 * float(jnp.finfo(jnp.float32).eps) * 100_000**0.5


@pytest.mark.parametrize("name", scheme_params(n for n in SCHEME_NAMES if jaxrot.SCHEMES[n].order >= 2))
def test_float32_free_body_keeps_unit_norm_and_angular_momentum_over_1e5_steps(name):
    """|q| stays unit and world L stays bounded in float32.

    Measured (dt = 0.01, t = 1000): |L| drift zhao 1.8e-4 (float64: 1.5e-4), rozmanov 1.3e-6,
    no_squish 4.3e-5, splitting 7.7e-3; without per-step renormalisation Zhao drifted 3.7e-2."""
    state = jaxrot.RotState(TUMBLING.q.astype(jnp.float32), TUMBLING.omega.astype(jnp.float32))
    traj = jaxrot.rollout(name, state, MOMENTS.astype(jnp.float32), 0.01, 100_000, save_every=1000)
    q, omega = traj.q.astype(jnp.float64), traj.omega.astype(jnp.float64)
    assert float(jnp.max(jnp.abs(jnp.linalg.norm(q, axis=-1) - 1))) < 1e-6
    l_world = quat.rotate(q, MOMENTS[None] * quat.rotate(quat.conjugate(q), omega))
    drift = jnp.linalg.norm(l_world - l_world[:1], axis=-1) / jnp.linalg.norm(l_world[0])
    assert float(jnp.max(drift)) < FLOAT32_MOMENTUM_DRIFT[name]


@pytest.mark.parametrize("name", scheme_params(SCHEME_NAMES))
def test_torque_calls_match_the_declared_count(name):
    calls = []

    def counting_torque(t, q, omega, args):
        jax.debug.callback(lambda t: calls.append(float(t)), t)
        return jnp.zeros(3)

    scheme = jaxrot.SCHEMES[name]
    jax.block_until_ready(jaxrot.rollout(name, TUMBLING, MOMENTS, 0.02, 7, torque=counting_torque))
    assert len(calls) == scheme.torque_evals_per_step * 7 + scheme.torque_evals_at_init


@pytest.mark.slow
@pytest.mark.parametrize("name", contract_params())
def test_gradients_match_central_differences(name):
    """d(loss)/d(rotation vector of q0, omega0, inertia, torque parameter), float64, 1e-6 relative; and
    finite at ω0 = 0 under zero weight (a body at rest, diagonal inertia)."""
    scheme = Rozmanov(max_iter=20) if name == "rozmanov" else name

    def loss(rotvec, omega0, inertia, weight_z):
        args = {
            "offset_body": jnp.array([0.1, 0.05, 0.3]),
            "weight": jnp.stack([0 * weight_z, 0 * weight_z, weight_z]),
        }
        state = jaxrot.RotState(quat.exp(rotvec), omega0)
        traj = jaxrot.rollout(scheme, state, inertia, 0.02, 50, torque=gravity_torque, args=args)
        return jnp.sum(traj.q[-1] * jnp.array([0.2, -0.5, 0.7, 0.1])) + 0.1 * jnp.sum(traj.omega[-1] ** 2)

    # Strictly inside the triangle inequality (1, 2, 3 lies on it) so the stencil stays valid.
    primals = (jnp.array([0.1, 0.2, 0.3]), TUMBLING.omega, jnp.array([1.2, 2.0, 2.9]), jnp.asarray(-9.81))
    gradient = jax.jit(jax.grad(loss, argnums=(0, 1, 2, 3)))
    grads = gradient(*primals)
    for argnum, grad in enumerate(grads):
        np.testing.assert_allclose(
            grad, central_difference_grad(loss, primals, argnum), rtol=1e-6, atol=1e-10
        )

    # zeros_like keeps the weak type of the scalar, so the compiled gradient is reused, not rebuilt.
    at_rest = gradient(primals[0], jnp.zeros(3), primals[2], jnp.zeros_like(primals[3]))
    assert all(bool(jnp.all(jnp.isfinite(g))) for g in at_rest)
    assert float(jnp.linalg.norm(at_rest[1])) > 0  # a small spin does move the body


@pytest.mark.parametrize("name", contract_params())
def test_step_is_usable_alone_and_matches_rollout(name):
    scheme = jaxrot.SCHEMES[name]
    inertia = jaxrot.body_inertia(MOMENTS)
    carry = scheme.init(TUMBLING, 0.0, inertia, None, None)
    for k in range(3):
        carry = scheme.step(carry, 0.02 * k, 0.02, inertia, None, None)
    traj = jaxrot.rollout(name, TUMBLING, MOMENTS, 0.02, 3)
    np.testing.assert_allclose(scheme.state(carry).q, traj.q[-1], atol=1e-15)
    np.testing.assert_allclose(scheme.state(carry).omega, traj.omega[-1], atol=1e-15)
