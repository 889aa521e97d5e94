"""Every bad input of DESIGN.md gets a ValueError naming the argument; tracers are never checked."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import MOMENTS, contract_params, principal_state

import jaxrot
from jaxrot import quaternion as quat
from jaxrot._inertia import triangle_tolerance


GOOD = principal_state()
Q, OMEGA = GOOD


def run(state=GOOD, inertia=MOMENTS, dt=0.01, n_steps=3, **kwargs):
    return jaxrot.rollout(kwargs.pop("scheme", "zhao"), state, inertia, dt, n_steps, **kwargs)


BAD_INPUTS = {
    "q wrong trailing shape": (dict(state=jaxrot.RotState(Q[:3], OMEGA)), r"state\.q.*\(\.\.\., 4\)"),
    "omega wrong trailing shape": (
        dict(state=jaxrot.RotState(Q, jnp.zeros(4))),
        r"state\.omega.*\(\.\.\., 3\)",
    ),
    "particle axes differ": (
        dict(state=jaxrot.RotState(jnp.stack([Q, Q]), OMEGA)),
        "share their leading",
    ),
    "state not a RotState": (dict(state=Q), "RotState"),
    "q NaN": (dict(state=jaxrot.RotState(Q.at[0].set(jnp.nan), OMEGA)), r"state\.q.*NaN"),
    "omega infinite": (dict(state=jaxrot.RotState(Q, OMEGA.at[1].set(jnp.inf))), r"state\.omega.*infinite"),
    "q not unit": (dict(state=jaxrot.RotState(Q * (1 + 1e-4), OMEGA)), r"state\.q.*normalize=True"),
    "q zero": (dict(state=jaxrot.RotState(jnp.zeros(4), OMEGA)), "zero quaternion"),
    "inertia wrong shape": (dict(inertia=jnp.ones(4)), r"inertia.*\(3,\).*\(3, 3\)"),
    "inertia per-particle shape mismatch": (dict(inertia=jnp.ones((2, 3))), r"inertia.*particle axes"),
    "inertia NaN": (dict(inertia=MOMENTS.at[0].set(jnp.nan)), "inertia.*NaN"),
    "inertia not symmetric": (dict(inertia=jnp.diag(MOMENTS).at[0, 1].set(0.1)), "inertia.*symmetric"),
    "inertia not positive definite": (
        dict(inertia=jnp.array([-1.0, 2.0, 2.0])),
        "inertia.*positive definite",
    ),
    "inertia zero moment": (dict(inertia=jnp.array([0.0, 1.0, 1.0])), "inertia.*positive definite"),
    "inertia tensor indefinite": (
        dict(inertia=jnp.array([[1.0, 2.0, 0.0], [2.0, 1.0, 0.0], [0.0, 0.0, 2.0]])),
        "inertia.*positive definite",
    ),
    "inertia triangle inequality": (dict(inertia=jnp.array([1.0, 1.0, 3.0])), "inertia.*triangle inequality"),
    "dt zero": (dict(dt=0.0), r"dt.*> 0"),
    "dt negative": (dict(dt=-0.1), r"dt.*> 0"),
    "dt NaN": (dict(dt=float("nan")), r"dt.*finite"),
    "dt not scalar": (dict(dt=jnp.array([0.1, 0.2])), r"dt.*scalar"),
    "n_steps negative": (dict(n_steps=-1), r"n_steps.*>= 0"),
    "n_steps float": (dict(n_steps=2.5), r"n_steps.*Python int"),
    "save_every zero": (dict(save_every=0), r"save_every.*>= 1"),
    "save_every does not divide n_steps": (
        dict(n_steps=10, save_every=4),
        r"save_every.*must divide `n_steps`",
    ),
    "unknown scheme": (dict(scheme="rk4"), r"scheme.*'zhao'"),
    "torque not callable": (dict(torque=jnp.zeros(3)), r"torque.*callable"),
    "t0 not scalar": (dict(t0=jnp.zeros(2)), r"t0.*scalar"),
}


@pytest.mark.parametrize("kwargs, match", BAD_INPUTS.values(), ids=BAD_INPUTS.keys())
def test_bad_input_raises_value_error_naming_the_argument(kwargs, match):
    with pytest.raises(ValueError, match=match):
        run(**kwargs)


@pytest.mark.parametrize("kwargs, match", list(BAD_INPUTS.values())[:16], ids=list(BAD_INPUTS)[:16])
def test_reference_rollout_checks_state_and_inertia_the_same_way(kwargs, match):
    with pytest.raises(ValueError, match=match):
        jaxrot.reference_rollout(
            kwargs.get("state", GOOD), kwargs.get("inertia", MOMENTS), jnp.array([0.0, 0.1])
        )


# Not "must be unit quaternions" (float16 rounds |q| by ~5e-4): the dtype, named, and what to do.
BAD_DTYPES = {
    "q float16": (
        dict(state=jaxrot.RotState(Q.astype(jnp.float16), OMEGA.astype(jnp.float16))),
        r"`state\.q` has dtype float16; jaxrot computes in float32 or float64 only.*\.astype",
    ),
    "omega bfloat16": (
        dict(state=jaxrot.RotState(Q, OMEGA.astype(jnp.bfloat16))),
        r"`state\.omega` has dtype bfloat16; jaxrot computes in float32 or float64",
    ),
    "q complex": (
        dict(state=jaxrot.RotState(Q.astype(jnp.complex64), OMEGA)),
        r"`state\.q` has dtype complex64",
    ),
    "q and omega differ": (
        dict(state=jaxrot.RotState(Q.astype(jnp.float32), OMEGA)),
        r"`state\.q` \(float32\) and `state\.omega` \(float64\) must have the same dtype, float32 or float64",
    ),
    "inertia float16": (dict(inertia=MOMENTS.astype(jnp.float16)), r"`inertia` has dtype float16"),
}


@pytest.mark.parametrize("kwargs, match", BAD_DTYPES.values(), ids=BAD_DTYPES.keys())
def test_unsupported_or_mixed_dtypes_are_named(kwargs, match):
    with pytest.raises(ValueError, match=match):
        run(**kwargs)
    with pytest.raises(ValueError, match=match):
        jaxrot.reference_rollout(
            kwargs.get("state", GOOD), kwargs.get("inertia", MOMENTS), jnp.array([0.0, 0.1])
        )


def test_untyped_inputs_and_the_inertia_take_the_state_dtype():
    """Python lists (and a float64 inertia) follow a float32 state: nothing to match there."""
    traj = run(state=jaxrot.RotState(Q.astype(jnp.float32), OMEGA.tolist()), inertia=MOMENTS)
    assert traj.q.dtype == traj.omega.dtype == traj.t.dtype == jnp.float32


@pytest.mark.parametrize("scheme", contract_params())
def test_torque_of_wrong_shape_is_reported(scheme):
    with pytest.raises(ValueError, match=r"torque.*shape \(3,\)"):
        run(scheme=scheme, torque=lambda t, q, omega, args: jnp.zeros(2))


def test_n_steps_traced_is_rejected_clearly():
    with pytest.raises(ValueError, match=r"n_steps.*Python int"):
        jax.jit(lambda n: run(n_steps=n))(3)


@pytest.mark.slow
def test_checks_skip_tracers_under_jit_and_grad():
    """A non-unit q under jit is the caller's business (no check, no error); gradients stay finite."""
    off_unit = jaxrot.RotState(Q * 1.5, OMEGA)
    out = jax.jit(lambda s, inertia: run(state=s, inertia=inertia))(off_unit, MOMENTS)
    assert bool(jnp.all(jnp.isfinite(out.q)))

    def loss(inertia, dt):
        return jnp.sum(run(inertia=inertia, dt=dt).omega[-1])

    grads = jax.grad(loss, argnums=(0, 1))(MOMENTS, 0.01)
    assert all(bool(jnp.all(jnp.isfinite(g))) for g in grads)
    grads_full = jax.grad(loss)(jnp.diag(MOMENTS), 0.01)
    assert bool(jnp.all(jnp.isfinite(grads_full)))


def test_integer_and_list_inputs_are_converted_to_float():
    traj = jaxrot.rollout("zhao", jaxrot.RotState([1, 0, 0, 0], [0, 0, 1]), [1, 2, 2], 0.1, 2)
    assert jnp.issubdtype(traj.q.dtype, jnp.floating)
    np.testing.assert_allclose(traj.omega[-1], [0.0, 0.0, 1.0], atol=1e-15)


# Hairer & Vilmart's water molecule, a planar body rounded to three digits: 0.345 + 0.653 = 0.998 < 1.
WATER = jnp.array([0.345, 0.653, 1.0])
# ACM TOMS Algorithm 903's test body: 1 + 1.0127 < 3.3062, a mathematical body no mass distribution has.
TOMS_903 = jnp.array([1.0, 1.0127, 3.3062])


def _last_q(inertia):
    return jaxrot.rollout("zhao", jaxrot.RotState(Q, OMEGA), inertia, 0.01, 3).q[-1]


def test_a_rounded_planar_body_is_accepted_eagerly_and_under_jit():
    """Its violation (0.002) is within the rounding of three significant digits (0.006), both forms;
    the same body under jit gives the same result (to the few ulp by which XLA may order the
    3 steps' operations differently inside an outer jit)."""
    eager = _last_q(WATER)
    np.testing.assert_allclose(jax.jit(_last_q)(WATER), eager, rtol=0, atol=1e-14)
    assert bool(jnp.all(jnp.isfinite(_last_q(jnp.diag(WATER)))))
    np.testing.assert_allclose(jaxrot.rollout("zhao", jaxrot.RotState(Q, OMEGA), WATER, 0.01, 3).q[-1], eager)


def test_a_mathematical_body_is_refused_alike_eagerly_and_under_jit_unless_opted_in():
    with pytest.raises(ValueError, match=r"not a physical body.*by 1.29.*jaxrot.MathematicalBody"):
        _last_q(TOMS_903)
    # eqx.error_if raises through a host callback: jax reports it as JaxRuntimeError, or as a
    # ValueError ("INTERNAL: CpuCallback error", seen in pytest-xdist workers); both carry the message.
    runtime_error = (jax.errors.JaxRuntimeError, ValueError)
    with pytest.raises(runtime_error, match=r"(?s)not a physical body.*jaxrot.MathematicalBody"):
        jax.block_until_ready(jax.jit(_last_q)(TOMS_903))
    body = jaxrot.MathematicalBody(TOMS_903)
    eager = _last_q(body)
    assert bool(jnp.all(jnp.isfinite(eager)))
    np.testing.assert_allclose(jax.jit(_last_q)(body), eager, rtol=0, atol=1e-14)
    reference = jaxrot.reference_rollout(jaxrot.RotState(Q, OMEGA), body, jnp.array([0.0, 0.03]))
    assert float(quat.angle_between(reference.q[-1], eager)) < 1e-5  # zhao's error after 3 steps


def test_triangle_tolerance_is_the_rounding_of_three_digits():
    """Half a unit in the third significant digit of each moment: 0.0005 + 0.0005 + 0.005 for water.
    A violation just beyond it is refused; the opt-in still requires positive definiteness."""
    assert float(triangle_tolerance(np.asarray(WATER))) == pytest.approx(0.006)
    _last_q(jnp.array([1.0, 2.0, 3.014]))  # violation 0.014 within 0.005 × 3 (each moment in [1, 10))
    with pytest.raises(ValueError, match="not a physical body"):
        _last_q(jnp.array([1.0, 2.0, 3.02]))
    with pytest.raises(ValueError, match="positive definite"):
        _last_q(jaxrot.MathematicalBody(jnp.array([1.0, -1.0, 3.0])))
