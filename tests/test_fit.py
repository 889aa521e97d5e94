"""`jaxrot.fit_inertia`: gradients through the integrator, recovery from noisy observations, bad input."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import central_difference_grad

import jaxrot
from jaxrot import _fit, quaternion as quat
from jaxrot._fit import _parameterisation
from jaxrot._fit._fit_inertia import _model, _residuals, _solve


# An asymmetric body well inside the physical set (I1 + I2 > I3), in a lab body frame where its
# tensor is full (not diagonal).
MOMENTS = jnp.array([2.0, 3.0, 4.0])
PRINCIPAL_TO_BODY = quat.exp(jnp.array([0.4, -0.7, 0.25]))
TENSOR = quat.to_matrix(PRINCIPAL_TO_BODY) @ jnp.diag(MOMENTS) @ quat.to_matrix(PRINCIPAL_TO_BODY).T
STATE = jaxrot.RotState(quat.exp(jnp.array([0.1, 0.2, 0.3])), jnp.array([0.8, -0.5, 1.5]))
ARGS = {"offset": jnp.array([0.1, 0.05, 0.3]), "weight": jnp.array([0.0, 0.0, -9.81])}
NOISE = 1e-3  # rad, standard deviation of each rotation-vector component of the orientation noise


def gravity(t, q, omega, args):
    """A heavy top: weight at a body-frame offset from the fixed point (world-frame torque)."""
    return jnp.cross(quat.rotate(q, args["offset"]), args["weight"])


@functools.cache
def observations(torque_on: bool, n: int = 200, t_end: float = 10.0, seed: int = 0):
    """Reference orientations at ``n`` times with rotation-vector noise, and the noise angles."""
    ts = jnp.linspace(0.0, t_end, n)
    ref = jaxrot.reference_rollout(
        STATE, TENSOR, ts, torque=gravity if torque_on else None, args=ARGS, rtol=1e-12, atol=1e-12
    )
    noise = NOISE * jax.random.normal(jax.random.PRNGKey(seed), (n, 3), dtype=jnp.float64)
    q = quat.multiply(quat.exp(noise), ref.q)
    return jaxrot.Trajectory(ts, q, None), ref


def axis_errors_deg(axes, true_axes):
    """Angle (degrees) between matching principal axes (columns in ascending-moment order), sign-free."""
    cos = jnp.abs(jnp.sum(axes * true_axes, axis=0))
    return np.degrees(np.arccos(np.clip(np.asarray(cos), 0.0, 1.0)))


# --------------------------------------------------------------------------- the parameterisation


def test_parameterisation_is_physical_and_onto():
    params = jax.random.normal(jax.random.PRNGKey(1), (500, 6), dtype=jnp.float64)
    inertia = _fit.inertia_from_cholesky(params)
    np.testing.assert_allclose(inertia, jnp.swapaxes(inertia, -1, -2), atol=1e-14)
    moments = np.linalg.eigvalsh(np.asarray(inertia))
    assert np.all(moments > 0)
    total = moments.sum(-1, keepdims=True)
    assert np.all(total - 2 * moments >= -1e-12 * total)  # I1 + I2 >= I3, every permutation
    # Round trip through `cholesky_from_inertia`, including a planar body on the boundary.
    planar = jnp.diag(jnp.array([1.0, 2.0, 3.0]))
    for tensor in (TENSOR, planar):
        back = _fit.inertia_from_cholesky(jnp.asarray(_fit.cholesky_from_inertia(tensor)))
        np.testing.assert_allclose(back, tensor, rtol=0, atol=1e-5 * float(jnp.trace(tensor)))
    unit = _fit.inertia_from_cholesky(params[0], unit_trace=True)
    np.testing.assert_allclose(jnp.trace(unit), 1.0, rtol=1e-14)


# --------------------------------------------------------------------------- gradients


@functools.cache
def gradient_problem(checkpoint: bool):
    """1000 Zhao steps of the heavy top: 101 observations, 10 steps per interval."""
    obs, _ = observations(True, n=101, t_end=5.0)
    problem, _ = _model.build_model(
        obs, torque=gravity, args=ARGS, segments=1, unit_trace=False, substeps=10, checkpoint=checkpoint
    )
    assert problem.substeps * (obs.t.shape[0] - 1) == 1000
    return problem


@functools.cache
def loss_and_grad(checkpoint: bool):
    """Compiled objective of `gradient_problem` and its gradient w.r.t. (inertia, q0, omega0)."""
    loss = functools.partial(_residuals.single_shooting_loss, gradient_problem(checkpoint))
    return jax.jit(loss), jax.jit(jax.value_and_grad(loss, argnums=(0, 1, 2)))


@pytest.mark.slow
def test_gradients_match_central_differences_through_1000_zhao_steps():
    loss, value_and_grad = loss_and_grad(True)
    # Away from the optimum, so that every gradient component is well above round-off.
    primals = (TENSOR * 1.02 + 0.01 * jnp.eye(3), STATE.q, STATE.omega * 1.01)
    _, grads = value_and_grad(*primals)
    for argnum, name in enumerate(("inertia", "q0", "omega0")):
        fd = central_difference_grad(loss, primals, argnum)
        assert bool(jnp.all(jnp.isfinite(grads[argnum])))
        np.testing.assert_allclose(grads[argnum], fd, rtol=1e-6, atol=0, err_msg=name)


@pytest.mark.slow
def test_checkpointed_gradient_equals_plain_gradient():
    primals = (TENSOR * 1.02, STATE.q, STATE.omega)
    (value, grads), (plain_value, plain_grads) = (loss_and_grad(ck)[1](*primals) for ck in (True, False))
    np.testing.assert_allclose(value, plain_value, rtol=1e-12)
    for g, plain in zip(grads, plain_grads, strict=True):
        np.testing.assert_allclose(g, plain, rtol=1e-10, atol=1e-12 * float(jnp.max(jnp.abs(plain))))
    # √N chunks: 32 × 32 >= 1000 steps, the last 24 are padding at dt = 0.
    problem = gradient_problem(True)
    assert (problem.n_outer, problem.n_inner) == (32, 32)


@pytest.mark.slow
def test_gradients_of_the_fit_parameters_match_central_differences():
    """The full objective (parameterised tensor, rotation-vector q0 offset, ω0) on a short problem."""
    obs, _ = observations(True, n=101, t_end=5.0)
    problem, extra = _model.build_model(
        obs, torque=gravity, args=ARGS, segments=1, unit_trace=False, substeps=10
    )
    params = _parameterisation._Params(
        jnp.asarray(_fit.cholesky_from_inertia(TENSOR * 1.02)),
        jnp.full((1, 3), 0.01),
        jnp.asarray(extra.omega_estimate[:1]),
    )
    value_and_grad = _residuals.value_and_grad(params, problem)
    objective = jax.jit(_residuals.objective)
    for field in range(3):

        def f(x, field=field):
            return objective(params._replace(**{params._fields[field]: x}), problem)

        fd = central_difference_grad(f, (params[field],), 0)
        np.testing.assert_allclose(value_and_grad[1][field], fd, rtol=1e-6, atol=0)


# --------------------------------------------------------------------------- recovery


@pytest.mark.slow
def test_recovers_tensor_and_axes_under_a_known_torque():
    obs, ref = observations(True)
    fit = jaxrot.fit_inertia(obs, torque=gravity, args=ARGS)
    assert fit.converged and fit.scale_determined
    rel = float(jnp.linalg.norm(fit.inertia - TENSOR) / jnp.linalg.norm(TENSOR))
    assert rel < 0.01, rel
    true_moments, true_axes = jnp.linalg.eigh(TENSOR)
    assert np.all(axis_errors_deg(fit.axes, true_axes) < 1.0), axis_errors_deg(fit.axes, true_axes)
    np.testing.assert_allclose(fit.moments, true_moments, rtol=0.01)
    # At the noise floor: the fitted model misses the observations by no more than the truth does.
    truth_misfit = float(jnp.sqrt(jnp.mean(quat.angle_between(ref.q, obs.q) ** 2)))
    assert float(fit.rms_angle) <= 1.01 * truth_misfit
    assert float(quat.angle_between(fit.q0, STATE.q)) < 5 * NOISE
    np.testing.assert_allclose(
        fit.omega0, STATE.omega, rtol=0, atol=0.01 * float(jnp.linalg.norm(STATE.omega))
    )
    assert fit.loss_history.shape == (fit.n_iterations + 1,)
    assert bool(jnp.all(jnp.diff(fit.loss_history) <= 0))
    assert fit.trajectory.q.shape == obs.q.shape


@functools.cache
def torque_free_fit():
    return jaxrot.fit_inertia(observations(False)[0])


@pytest.mark.slow
def test_torque_free_determines_only_the_ratios():
    obs, _ = observations(False)
    fit = torque_free_fit()
    assert fit.converged and not fit.scale_determined
    np.testing.assert_allclose(jnp.trace(fit.inertia), 1.0, rtol=1e-12)  # the documented normalisation
    true_moments, true_axes = jnp.linalg.eigh(TENSOR)
    ratios = fit.moments / fit.moments[0]
    np.testing.assert_allclose(ratios, true_moments / true_moments[0], rtol=0.01)
    assert np.all(axis_errors_deg(fit.axes, true_axes) < 1.0)
    # Any scale of the true tensor fits equally well: the objective cannot see it.
    problem, _ = _model.build_model(obs, torque=None, args=None, segments=1, unit_trace=False)
    loss = jax.jit(functools.partial(_residuals.single_shooting_loss, problem))
    np.testing.assert_allclose(
        loss(TENSOR, STATE.q, STATE.omega), loss(7.0 * TENSOR, STATE.q, STATE.omega), rtol=1e-9
    )


@pytest.mark.slow
def test_multiple_shooting_fits_segments_that_join():
    obs, _ = observations(False)
    fit = jaxrot.fit_inertia(obs, segments=4)
    true_moments, _ = jnp.linalg.eigh(TENSOR)
    np.testing.assert_allclose(fit.moments / fit.moments[0], true_moments / true_moments[0], rtol=0.01)
    assert fit.converged
    assert float(fit.rms_angle) < 3 * NOISE
    assert fit.trajectory.q.shape == (200, 4)


@pytest.mark.slow
def test_observed_angular_velocity_is_used():
    obs, ref = observations(False)
    with_omega = jaxrot.Trajectory(obs.t, obs.q, ref.omega)  # noisy q, exact omega
    fit = jaxrot.fit_inertia(with_omega, omega_weight=1.0)
    np.testing.assert_allclose(fit.omega0, STATE.omega, atol=1e-3)
    np.testing.assert_allclose(fit.trajectory.omega, ref.omega, atol=1e-2)


# --------------------------------------------------------------------------- convergence


def true_ratios():
    moments = np.linalg.eigvalsh(np.asarray(TENSOR))
    return moments[1:] / moments[0]


def fitted_ratios(fit):
    moments = np.asarray(fit.moments, dtype=np.float64)
    return moments[1:] / moments[0]


def perfect_observations(dtype):
    """Noise-free orientations stepped by Zhao itself (dt = 0.01, 400 steps, every 20th saved): the model
    of ``fit_inertia(obs, substeps=20)`` reproduces them exactly, but for round-off."""
    state = jaxrot.RotState(STATE.q.astype(dtype), STATE.omega.astype(dtype))
    return jaxrot.rollout("zhao", state, TENSOR.astype(dtype), 0.01, 400, save_every=20)


def round_off_floor(obs, **options):
    """`fit_inertia`'s round-off floor of the objective for torque-free ``obs``."""
    problem, extra = _model.build_model(obs, torque=None, args=None, segments=1, unit_trace=True, **options)
    return _solve.round_off_floor(problem, float(np.max(np.linalg.norm(extra.omega_estimate, axis=-1))))


def ratio_sensitivity(obs, **options):
    """Rows ``Mᵀ ∇(I₂/I₁)``, ``Mᵀ ∇(I₃/I₁)`` at the true body, ``M`` whitening the Gauss–Newton Hessian.

    ``Mᵀ H M = 𝟙`` for the Hessian ``H = 2 JᵀJ`` of the objective (float64, torque-free, one segment),
    so near the optimum ``f = f* + ½ |Δz|²`` with ``Δx = M Δz``, and the ratios move by ``rows @ Δz``.
    """
    obs = jaxrot.Trajectory(*(None if x is None else jnp.asarray(x, jnp.float64) for x in obs))
    problem, _ = _model.build_model(obs, torque=None, args=None, segments=1, unit_trace=True, **options)
    chol = _fit.cholesky_from_inertia(TENSOR)
    params = _parameterisation._Params(jnp.asarray(chol / chol[0]), jnp.zeros((1, 3)), STATE.omega[None])
    x = _parameterisation._flat(params)
    free = np.arange(1, x.size)  # chol[0] is fixed in a torque-free fit

    def residuals(z):
        return _residuals.residuals(
            _parameterisation._unflat(jnp.asarray(x).at[free].set(z), params, jnp.float64), problem
        )[0]

    jac = np.asarray(jax.jacfwd(residuals)(jnp.asarray(x[free])))
    values, vectors = np.linalg.eigh(2 * jac.T @ jac)
    whiten = vectors / np.sqrt(values)

    def ratios(chol):
        moments = jnp.linalg.eigvalsh(_fit.inertia_from_cholesky(chol, unit_trace=True))
        return moments[1:] / moments[0]

    gradient = np.asarray(jax.jacfwd(ratios)(jnp.asarray(x[:6])))[:, 1:]  # w.r.t. the free chol[1:]
    return gradient @ whiten[:5]


@pytest.mark.slow
@pytest.mark.parametrize("dtype", [jnp.float64, jnp.float32])
def test_a_perfect_fit_converges_in_either_precision(dtype):
    """Noise-free data: the objective ends at round-off, where only its floor can say "converged"."""
    obs = perfect_observations(dtype)
    fit = jaxrot.fit_inertia(obs, substeps=20)
    floor = round_off_floor(obs, substeps=20)
    assert fit.converged and fit.loss.dtype == dtype
    assert 0 <= float(fit.loss) <= floor  # a sum of squares without cancellation: never negative
    # f = f* + ½|Δz|² with f* >= 0, so |Δz| <= √(2 floor): the ratios are off by at most |row| √(2 floor)
    # (float64: 4e-13; float32, 400 steps: 2e-4, where the linear start is already at the floor).
    bound = np.linalg.norm(ratio_sensitivity(obs, substeps=20), axis=1) * np.sqrt(2 * floor)
    assert np.all(np.abs(fitted_ratios(fit) - true_ratios()) <= bound), (fitted_ratios(fit), bound)


@pytest.mark.slow  # 22-28 s; identify's calibration (slow) checks the intervals over 120 seeds
def test_a_noisy_fit_converges_within_its_standard_errors():
    obs, _ = observations(False)
    fit = torque_free_fit()
    assert fit.converged
    assert float(fit.loss) > round_off_floor(obs)  # ended by ftol, not by the round-off floor
    # Least squares: each of the 3 n residual components carries noise NOISE / √n (the objective is a
    # mean), so cov(Δz) = 2 (NOISE² / n) 𝟙 in whitened coordinates: one standard error per ratio is
    # √2 NOISE / √n |row|. 4 of them: a component exceeds that with probability 6e-5; Zhao's bias
    # (~1e-5 relative) and the ftol stop (0.01 standard errors) are below 0.1 of one.
    n = obs.t.shape[0]
    standard_error = np.sqrt(2.0 / n) * NOISE * np.linalg.norm(ratio_sensitivity(obs), axis=1)
    error = fitted_ratios(fit) - true_ratios()
    assert np.all(np.abs(error) <= 4 * standard_error), error / standard_error


@pytest.mark.slow
@pytest.mark.parametrize("max_iter", [0, 1])
def test_max_iter_stops_before_convergence(max_iter):
    # The linear start misses by ~1e-5 rad (f ≈ 3e-10) and one step leaves f ≈ 3e-19, predicted to drop
    # by as much again: 7 decades above both the floor (8e-27) and ftol × f.
    fit = jaxrot.fit_inertia(perfect_observations(jnp.float64), substeps=20, max_iter=max_iter)
    assert not fit.converged
    assert fit.n_iterations == max_iter and fit.loss_history.shape == (max_iter + 1,)


# --------------------------------------------------------------------------- bad input


@pytest.mark.parametrize(
    "make, match",
    [
        (lambda o: (o.t, o.q), "jaxrot.Trajectory"),
        (lambda o: o._replace(q=o.q[:, :3]), r"observed.q` must have shape \(n, 4\)"),
        (lambda o: o._replace(q=o.q[None]), r"observed.q` must have shape \(n, 4\)"),
        (lambda o: o._replace(t=o.t[:-1]), r"observed.q` must have shape"),
        (lambda o: o._replace(t=o.t[:2], q=o.q[:2]), "at least 3 times"),
        (lambda o: o._replace(omega=jnp.zeros((5, 3))), r"observed.omega` must be None"),
        (lambda o: o._replace(q=o.q.at[3, 1].set(jnp.nan)), r"observed.q` contains NaN"),
        (lambda o: o._replace(t=o.t.at[2].set(jnp.inf)), r"observed.t` contains NaN"),
        (
            lambda o: o._replace(omega=jnp.full(o.q.shape[:1] + (3,), jnp.nan)),
            r"observed.omega` contains NaN",
        ),
        (lambda o: o._replace(t=o.t[::-1]), "strictly increasing"),
        (lambda o: o._replace(q=2 * o.q), "unit quaternions"),
    ],
)
def test_bad_observed_raises(make, match):
    obs, _ = observations(False)
    with pytest.raises(ValueError, match=match):
        jaxrot.fit_inertia(make(obs))


def test_bad_options_raise():
    obs, _ = observations(False)
    with pytest.raises(ValueError, match="segments"):
        jaxrot.fit_inertia(obs, segments=200)
    with pytest.raises(ValueError, match="dt"):
        jaxrot.fit_inertia(obs, dt=-1.0)
    with pytest.raises(ValueError, match="torque"):
        jaxrot.fit_inertia(obs, torque="gravity")
    with pytest.raises(ValueError, match="scheme"):
        jaxrot.fit_inertia(obs, scheme="rk4")
    with pytest.raises(ValueError, match="inertia0"):
        jaxrot.fit_inertia(obs, inertia0=jnp.ones(3))
