"""jaxrot's schemes as diffrax solvers: `RigidBodyTerm` and `jaxrot.solver`."""

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrot
from jaxrot import quaternion as quat

from .helpers import MOMENTS, full_tensor, gravity_args, principal_state


# Tolerances and steps go in as arrays: diffeqsolve is `eqx.filter_jit`, so a Python float would
# compile a new program for each value.


STATE = principal_state()
T_END = 2.0


def _orientation_time_torque(t, q, omega, args):
    """Gravity on an offset centre of mass plus a time-dependent kick: no ω, so every scheme takes it."""
    lever = quat.rotate(q, args["offset_body"])
    return jnp.cross(lever, args["weight"]) * 0.05 + 0.2 * jnp.sin(3 * t) * jnp.array([1.0, 0.0, 0.5])


def _drag_torque(t, q, omega, args):
    return _orientation_time_torque(t, q, omega, args) - 0.3 * omega


ARGS = gravity_args()


def _takes_omega(name):
    return name not in ("srkn6b", "srkn14a")


def _solve(name, state, inertia, torque, t1, dt, **kwargs):
    term = jaxrot.RigidBodyTerm(inertia, torque)
    dt = None if dt is None else jnp.asarray(dt)
    return diffrax.diffeqsolve(term, jaxrot.solver(name), 0.0, t1, dt, state, args=ARGS, **kwargs)


def _pid(tol):
    return diffrax.PIDController(rtol=jnp.asarray(tol), atol=jnp.asarray(tol))


# By default a plain-state carry and the adaptive pair's; the momentum carries (no_squish, the RKMK
# family's L) and the rest in the slow set.
SOLVER_DEFAULTS = {"zhao", "rkmk_dopri5"}


@pytest.mark.parametrize(
    "name",
    [pytest.param(n, marks=() if n in SOLVER_DEFAULTS else pytest.mark.slow) for n in sorted(jaxrot.SCHEMES)],
)
def test_constant_steps_equal_rollout(name):
    """`diffeqsolve` with a constant dt0 is `rollout` at that dt: same steps, carries in the solver state."""
    torque = _drag_torque if _takes_omega(name) else _orientation_time_torque
    n, dt = 25, 0.02
    ts = dt * jnp.arange(n + 1, dtype=float)
    sol = _solve(name, STATE, MOMENTS, torque, n * dt, dt, saveat=diffrax.SaveAt(ts=ts), max_steps=n + 1)
    traj = jaxrot.rollout(name, STATE, MOMENTS, dt, n, torque=torque, args=ARGS)
    # Both compute the same steps; diffrax accumulates t0 + k dt differently and the torque
    # sees t, so they differ by a few ulp per step: 25 steps x ~10 eps << 1e-12.
    np.testing.assert_allclose(sol.ys.q, traj.q, rtol=0, atol=1e-12)
    np.testing.assert_allclose(sol.ys.omega, traj.omega, rtol=0, atol=1e-12)


def test_batch_in_one_solve_equals_rollout():
    """N bodies in one `diffeqsolve` (shared steps): per-body inertia tensors and per_body args."""
    rng = np.random.default_rng(3)
    q = quat.normalize(jnp.asarray(rng.normal(size=(3, 4))))
    state = jaxrot.RotState(q, jnp.asarray(rng.normal(size=(3, 3))))
    inertia = jnp.stack([full_tensor(), jnp.diag(MOMENTS), full_tensor(MOMENTS * 2)])
    args = {**ARGS, "offset_body": jaxrot.per_body(jnp.asarray(rng.normal(size=(3, 3)) * 0.1))}
    term = jaxrot.RigidBodyTerm(inertia, _drag_torque)
    sol = diffrax.diffeqsolve(term, jaxrot.solver("zhao"), 0.0, 0.5, 0.01, state, args=args)
    traj = jaxrot.rollout("zhao", state, inertia, 0.01, 50, torque=_drag_torque, args=args)
    np.testing.assert_allclose(sol.ys.q[-1], traj.q[-1], rtol=0, atol=1e-12)
    np.testing.assert_allclose(sol.ys.omega[-1], traj.omega[-1], rtol=0, atol=1e-12)


# One reference for the adaptive and the dense-output tests below (a reference program compiles for
# seconds): at the adaptive tests' 9 save times and the dense tests' 16 off-step times (and t = 0).
# Its steps do not depend on the save times (diffrax interpolates the saves), so each row is what a
# reference at that test's times alone gives.
SAVE_TS = np.linspace(0.0, T_END, 9)
OFF_STEP_TS = np.concatenate([[0.0], T_END * (np.arange(16) + 0.37) / 16])
REFERENCE_TS = np.union1d(SAVE_TS, OFF_STEP_TS)


@pytest.fixture(scope="module")
def reference():
    return jaxrot.reference_rollout(
        STATE, MOMENTS, jnp.asarray(REFERENCE_TS), torque=_drag_torque, args=ARGS, rtol=1e-14, atol=1e-14
    )


def _reference_at(reference, ts):
    """The reference's rows at ``ts`` (a subset of `REFERENCE_TS`)."""
    rows = np.searchsorted(REFERENCE_TS, ts)
    assert np.array_equal(REFERENCE_TS[rows], ts)
    return jaxrot.Trajectory(*(np.asarray(a)[rows] for a in reference))


def _adaptive(name, tol, ts, **kwargs):
    return _solve(
        name,
        STATE,
        MOMENTS,
        _drag_torque,
        T_END,
        None,
        saveat=diffrax.SaveAt(ts=ts),
        stepsize_controller=_pid(tol),
        max_steps=10_000,
        **kwargs,
    )


@pytest.mark.parametrize("name", ["rkmk_dopri5", pytest.param("rkmk_dopri8", marks=pytest.mark.slow)])
@pytest.mark.parametrize("tol", [1e-6, 1e-9])
def test_adaptive_error_follows_the_tolerance(name, tol, reference):
    """PID-controlled Lie-group pairs: error of the order of the tolerance, unit q at every save.

    The controller bounds the local error per step by ~tol; over the ~10-60 steps of t = 2 on
    this (chaotic-free, mildly damped) top the global error stays below 100 tol. |q| - 1 is the
    round-off of one normalisation plus the group interpolation's exp: a few eps, 1e-12 is ample.
    """
    reference = _reference_at(reference, SAVE_TS)
    sol = _adaptive(name, tol, jnp.asarray(reference.t))
    assert isinstance(jaxrot.solver(name), diffrax.AbstractAdaptiveSolver)
    error = float(jnp.max(quat.angle_between(sol.ys.q, reference.q)))
    assert error < 100 * tol
    assert float(jnp.max(jnp.abs(sol.ys.omega - reference.omega))) < 100 * tol
    assert float(jnp.max(jnp.abs(jnp.linalg.norm(sol.ys.q, axis=-1) - 1))) < 1e-12


def _dense_errors(name, steps, reference):
    """Max orientation and ω errors of the dense output between the steps, for each step count."""
    ref = _reference_at(reference, OFF_STEP_TS)
    ts_ref = jnp.asarray(ref.t)
    errors = []
    for n in steps:
        sol = _solve(name, STATE, MOMENTS, _drag_torque, T_END, T_END / n, saveat=diffrax.SaveAt(ts=ts_ref))
        errors.append(
            (
                float(jnp.max(quat.angle_between(sol.ys.q, ref.q))),
                float(jnp.max(jnp.abs(sol.ys.omega - ref.omega))),
            )
        )
    return np.array(errors)


@pytest.mark.parametrize(
    ("name", "steps", "q_order", "omega_order"),
    [
        # Hermite Θ (local O(h^4)) on an order-4 scheme; linear L (local O(h^2)) under a torque.
        pytest.param("rkmk4", [8, 16, 32, 64], 4, 2, marks=pytest.mark.slow),
        # Dopri5's continuous extension in the algebra: order 4, local O(h^5) = the steps' order 5.
        ("rkmk_dopri5", [8, 16, 32], 5, 5),
        # Hermite on an order-2 scheme: the steps' own error dominates.
        pytest.param("zhao", [32, 64, 128], 2, 2, marks=pytest.mark.slow),
    ],
)
def test_dense_output_order(name, steps, q_order, omega_order, reference):
    """Orders of the dense output at off-step times (log-log slope within ±0.3 of the claim)."""
    errors = _dense_errors(name, steps, reference)
    h = T_END / np.asarray(steps)
    q_slope = np.polyfit(np.log(h), np.log(errors[:, 0]), 1)[0]
    omega_slope = np.polyfit(np.log(h), np.log(errors[:, 1]), 1)[0]
    assert abs(q_slope - q_order) < 0.3, (q_slope, errors)
    assert abs(omega_slope - omega_order) < 0.3, (omega_slope, errors)


@pytest.mark.slow
def test_gradient_through_adaptive_solve_matches_central_differences():
    """d/d(inertia) of a projection of the final (q, ω) through a PID-controlled solve (default adjoint).

    At tol 1e-11 the discrete solution is within ~1e-9 of the exact one, so the derivative
    of either differs by far less than the 1e-5 tolerance; central differences with h = 1e-5
    have truncation error ~h² |third derivative| ~ 1e-10 and round-off eps/h ~ 1e-11."""
    weights = jnp.asarray(np.random.default_rng(0).normal(size=7))

    def projected(moments):
        sol = _solve("rkmk_dopri5", STATE, moments, _drag_torque, 1.0, None, stepsize_controller=_pid(1e-11))
        return jnp.dot(weights, jnp.concatenate([sol.ys.q[-1], sol.ys.omega[-1]]))

    grad = jax.jit(jax.grad(projected))(MOMENTS)
    h = 1e-5
    fd = jnp.stack([(projected(MOMENTS + e) - projected(MOMENTS - e)) / (2 * h) for e in h * jnp.eye(3)])
    np.testing.assert_allclose(grad, fd, rtol=0, atol=1e-5)


def _final_q(state):
    """q at t = 0.5 of an adaptive rkmk_dopri8 solve under drag."""
    sol = _solve(
        "rkmk_dopri8", state, MOMENTS, _drag_torque, 0.5, None, stepsize_controller=_pid(1e-8), max_steps=64
    )
    return sol.ys.q[-1]


@pytest.mark.slow
def test_vmap_over_bodies_equals_one_solve_each():
    """`jax.vmap` over diffeqsolve: each body adapts its own steps, as when solved alone.

    The vmapped program is compiled differently (its round-off differs by ~eps per operation),
    and the PID controller turns that into step sizes that differ at round-off level; each
    result is within ~tol of the exact solution, so they agree to a few tol (bound: 10 tol)."""
    rng = np.random.default_rng(5)
    q = quat.normalize(jnp.asarray(rng.normal(size=(3, 4))))
    states = jaxrot.RotState(q, jnp.asarray(rng.normal(size=(3, 3))))
    batched = jax.vmap(_final_q)(states)
    for i in range(3):
        one = _final_q(jaxrot.RotState(states.q[i], states.omega[i]))
        np.testing.assert_allclose(batched[i], one, rtol=0, atol=1e-7)


@pytest.mark.slow
def test_direct_adjoint_gives_the_default_adjoints_gradient():
    """`DirectAdjoint` and `RecursiveCheckpointAdjoint` give the same gradient, to the solve's tolerance.

    On fixed steps the two reverse passes do the same arithmetic in a different order: agreement to
    1e-14 (~50 ulp on gradients of size ~0.2; measured 1.4e-16). Under the PID controller the default
    adjoint also differentiates the step-size choice and DirectAdjoint does not (its gradient equals
    the one through the same steps held fixed, to 3e-17, measured): that path moves the result only
    through the truncation error, which the controller holds near ``tol``, so the two agree to
    ``tol`` (measured 4.5e-11 at tol = 1e-8; 1e-12, asserted before, held on one machine only).
    One gradient of a weighted sum of the final q (one reverse pass) on the FSAL pair: the Jacobian
    through rkmk_dopri8 (four reverse passes, each traced anew) made this a 230 s test."""
    weights = jnp.array([0.3, -0.7, 0.2, 0.5])
    tol = 1e-8

    def grad(adjoint, controller, dt0):
        def loss(w):
            sol = _solve(
                "rkmk_dopri5", jaxrot.RotState(STATE.q, w), MOMENTS, _drag_torque, 0.5, dt0,
                stepsize_controller=controller, max_steps=8, adjoint=adjoint,
            )  # fmt: skip  # 5 steps either way; DirectAdjoint's program grows with max_steps
            return jnp.sum(sol.ys.q[-1] * weights)

        return jax.jit(jax.grad(loss))(STATE.omega)

    for controller, dt0, atol in ((diffrax.ConstantStepSize(), 0.1, 1e-14), (_pid(tol), None, tol)):
        default = grad(diffrax.RecursiveCheckpointAdjoint(), controller, dt0)
        direct = grad(diffrax.DirectAdjoint(), controller, dt0)
        assert float(jnp.linalg.norm(default)) > 0.1
        np.testing.assert_allclose(default, direct, rtol=0, atol=atol)


@pytest.mark.slow
def test_made_jump_rebuilds_the_carry():
    """A jump at t0 makes the solver rebuild its carry (reused torque, momentum) from y: same result."""
    kwargs = dict(stepsize_controller=_pid(1e-8), max_steps=1000)
    plain = _solve("rkmk_dopri5", STATE, MOMENTS, _drag_torque, 1.0, None, **kwargs)
    jumped = _solve("rkmk_dopri5", STATE, MOMENTS, _drag_torque, 1.0, None, made_jump=True, **kwargs)
    np.testing.assert_allclose(jumped.ys.q, plain.ys.q, rtol=0, atol=1e-14)


@pytest.mark.slow
def test_backward_in_time_returns_to_the_start():
    """t1 < t0: the solver steps the physical time backwards (diffrax's time reversal)."""
    kwargs = dict(stepsize_controller=_pid(1e-10), max_steps=1000)
    forward = _solve("rkmk_dopri8", STATE, MOMENTS, _drag_torque, 1.0, None, **kwargs)
    end = jaxrot.RotState(forward.ys.q[-1], forward.ys.omega[-1])
    term = jaxrot.RigidBodyTerm(MOMENTS, _drag_torque)
    back = diffrax.diffeqsolve(term, jaxrot.solver("rkmk_dopri8"), 1.0, 0.0, None, end, args=ARGS, **kwargs)
    assert float(quat.angle_between(back.ys.q[-1], STATE.q)) < 1e-8
    np.testing.assert_allclose(back.ys.omega[-1], STATE.omega, rtol=0, atol=1e-8)


def test_plain_ode_term_is_refused_with_the_fix():
    term = diffrax.ODETerm(lambda t, y, args: y)
    with pytest.raises(ValueError, match="RigidBodyTerm"):
        diffrax.diffeqsolve(term, jaxrot.solver("zhao"), 0.0, 1.0, 0.1, STATE)


def test_bad_state_and_inertia_are_refused():
    term = jaxrot.RigidBodyTerm(MOMENTS, None)
    with pytest.raises(ValueError, match="RotState"):
        diffrax.diffeqsolve(term, jaxrot.solver("zhao"), 0.0, 1.0, 0.1, (STATE.q, STATE.omega))
    with pytest.raises(ValueError, match="inertia"):
        jaxrot.RigidBodyTerm(jnp.ones(4), None)
    with pytest.raises(ValueError, match="torque"):
        jaxrot.RigidBodyTerm(MOMENTS, "gravity")


@pytest.mark.slow
def test_diffrax_solvers_accept_the_same_term():
    """The Euclidean vector field: Tsit5 on `RigidBodyTerm` agrees with the reference (R⁴ integration)."""
    ts = jnp.linspace(0.0, 1.0, 3)
    ref = jaxrot.reference_rollout(STATE, MOMENTS, ts, torque=_drag_torque, args=ARGS, rtol=1e-12, atol=1e-12)
    sol = diffrax.diffeqsolve(
        jaxrot.RigidBodyTerm(MOMENTS, _drag_torque),
        diffrax.Tsit5(),
        0.0,
        1.0,
        None,
        STATE,
        args=ARGS,
        saveat=diffrax.SaveAt(ts=ts),
        stepsize_controller=_pid(1e-10),
    )
    assert float(jnp.max(quat.angle_between(quat.normalize(sol.ys.q), ref.q))) < 1e-8
