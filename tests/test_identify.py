"""`jaxrot.identify`: parameters, several experiments, partial observations and their uncertainties.

The fits that compile a three-manoeuvre model (10-30 s each on 2 cores) are in the slow set; the
default set keeps one fit of each kind of check (round-off, float32, an unidentifiable pair, a
body at rest) and the input checks.

Data come from the package's reference solver (diffrax Dopri8 at 1e-12, `_telemetry`), or,
for the round-off checks, from the fitted scheme itself at the fit's own step.
Recovery is checked as |estimate − truth| < 4 standard errors for every parameter: for a
calibrated fit each such event has probability 6e-5, so 30 parameters fail together with
probability < 2e-3 for any seed (the seeds here are fixed, so the outcome is deterministic).
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _telemetry import SATELLITE_DIPOLE, SATELLITE_INERTIA, dipole_torque, satellite_experiments

import jaxrot
from jaxrot import quaternion as quat


Z = 4.0


@pytest.fixture(scope="module")
def satellite():
    experiments, truth = satellite_experiments(0)
    fit = jaxrot.identify(
        experiments, torque=dipole_torque, args={"dipole": jnp.zeros(3)}, free_args={"dipole": True}
    )
    return experiments, truth, fit


@pytest.mark.slow
def test_satellite_inertia_dipole_and_states_within_their_standard_errors(satellite):
    experiments, truth, fit = satellite
    assert fit.converged and fit.unidentified == ()
    assert np.all(np.abs(np.asarray(fit.inertia) - SATELLITE_INERTIA) < Z * fit.stderr.inertia)
    assert np.all(np.abs(np.asarray(fit.args["dipole"]) - SATELLITE_DIPOLE) < Z * fit.stderr.args["dipole"])
    assert np.all(np.abs(np.asarray(fit.omega0) - np.stack(truth["omega0"])) < Z * fit.stderr.omega0)
    angles = quat.angle_between(fit.q0, jnp.asarray(np.stack(truth["q0"])))
    assert np.all(np.asarray(angles) < Z * 3 * np.max(fit.stderr.q0))
    # The standard errors are those of the data, not vacuous: 1e-4 rad, 2e-5 rad/s noise on 363 samples.
    assert np.all(fit.stderr.inertia < 1e-3 * np.trace(SATELLITE_INERTIA))
    # The misfit is the noise: with the true σ, the loss is χ² with m − n degrees of freedom.
    m = sum(int(np.sum(np.isfinite(r))) for parts in fit.residuals for r in parts.values())
    n = len(fit.names)
    assert abs(fit.loss - (m - n)) < 5 * np.sqrt(2 * (m - n))
    assert fit.scale_determined


@pytest.mark.slow
def test_a_close_start_skips_the_windows_for_the_same_optimum(satellite):
    """The satellite's linear-estimate start is 0.33–0.52 rad off the data (close: under `CLOSE_ANGLE`),
    so the fit runs on the whole record at once. Forced through the windows it stops at the same
    optimum: each run stops once the predicted decrease is ≤ ftol · f, i.e. within √(ftol · f) standard
    errors of the optimum along any direction (f ≈ 2.1e3: 4.6e-4), so the two differ by < 1e-3 standard
    errors in every coordinate of φ. One compiled loop serves both (``use_windows`` is a runtime value)."""
    from jaxrot._fit._identify._check import check_arguments
    from jaxrot._fit._identify._problem import build_problem
    from jaxrot._fit._identify._solve import solve
    from jaxrot._fit._identify._start import starting_point

    experiments, _, fit = satellite
    settings = check_arguments(
        experiments, torque=dipole_torque, args={"dipole": jnp.zeros(3)}, free_args={"dipole": True},
        inertia0=None, free_inertia=True, scheme=None, dt=None, q0=None, omega0=None, max_iter=100,
        ftol=1e-10, rcond=None, sensors=None,
    )  # fmt: skip
    start = starting_point(settings)
    problem = build_problem(settings, start)
    close = solve(problem, settings, start.speed)
    windowed = solve(problem, settings, start.speed, use_windows=True)
    assert not close.windowed and windowed.windowed and close.converged and windowed.converged
    assert close.n_iterations == fit.n_iterations < windowed.n_iterations
    se = np.sqrt(np.diag(np.linalg.inv(close.jac.T @ close.jac)))
    assert np.all(np.abs(close.phi - windowed.phi) < 1e-3 * se)


@pytest.mark.slow
def test_covariance_labels_and_correlations(satellite):
    _, _, fit = satellite
    assert fit.names[:6] == (
        "inertia[0,0]",
        "inertia[1,1]",
        "inertia[2,2]",
        "inertia[0,1]",
        "inertia[0,2]",
        "inertia[1,2]",
    )
    assert fit.names[6:9] == ("args.dipole[0]", "args.dipole[1]", "args.dipole[2]")
    assert fit.names[9] == "q0[0].rotation[0]" and fit.names[12] == "omega0[0,0]"
    assert fit.covariance.shape == (len(fit.names),) * 2
    np.testing.assert_allclose(np.sqrt(np.diag(fit.covariance))[:3], np.diag(fit.stderr.inertia), rtol=1e-10)
    np.testing.assert_allclose(np.diag(fit.correlation), 1.0, rtol=1e-12)
    assert np.all(np.abs(fit.correlation) <= 1 + 1e-12)


def _torque_free_record(scheme, dt, dtype, n=31, every=10):
    state = jaxrot.RotState(jnp.array([1.0, 0, 0, 0], dtype), jnp.array([0.3, 0.1, 1.0], dtype))
    return jaxrot.rollout(
        scheme, state, jnp.array([1.0, 1.5, 2.0], dtype), dt, (n - 1) * every, save_every=every
    )


def test_noise_free_fit_reaches_round_off():
    # Data stepped by the fitted scheme at the fit's own step: the model can be exact, so the fit
    # ends at round-off. Any scheme shows it; zhao's Jacobian compiles in half of rkmk4's time (the
    # default scheme is fitted by the doctest, the sphere test and the slow set). Each of the 300
    # steps rounds by ~eps, so the states are known to ~3e-14 rad; with moment sensitivities of
    # order 1 rad per unit ratio, ratios come back to ~1e-12.
    record = _torque_free_record("zhao", 0.02, jnp.float64)
    fit = jaxrot.identify(jaxrot.Experiment(record.t, q=record.q, sigma_q=1e-3), dt=0.02, scheme="zhao")
    assert fit.converged
    moments = np.linalg.eigvalsh(np.asarray(fit.inertia))
    np.testing.assert_allclose(moments / moments[0], [1.0, 1.5, 2.0], rtol=1e-9)
    np.testing.assert_allclose(np.trace(np.asarray(fit.inertia)), 1.0, rtol=1e-12)  # scale not determined
    assert not fit.scale_determined
    assert fit.loss < 1e-12


def test_float32_noise_free_converges_without_nan():
    record = _torque_free_record("zhao", 0.02, jnp.float32)
    fit = jaxrot.identify(jaxrot.Experiment(record.t, q=record.q), dt=0.02, scheme="zhao")
    assert fit.inertia.dtype == jnp.float32 and fit.converged
    moments = np.linalg.eigvalsh(np.asarray(fit.inertia, np.float64))
    # float32: 300 steps of eps = 1.2e-7 leave ~4e-5 rad in the states, and the ratios follow.
    np.testing.assert_allclose(moments / moments[0], [1.0, 1.5, 2.0], rtol=1e-3)
    assert np.all(np.isfinite(fit.stderr.inertia))


def test_unidentifiable_combination_is_named_not_hidden():
    # Two gains that enter only through their sum: the data fix a + b, not a and b. (With the
    # inertia free as well, only I / (a + b) would be fixed: the inertia is held here.)
    def torque(t, q, omega, args):
        return (args["a"] + args["b"]) * jnp.array([0.0, 0.0, 1.0]) * 0.01

    truth = {"a": jnp.array(0.4), "b": jnp.array(0.6)}
    state = jaxrot.RotState(jnp.array([1.0, 0, 0, 0]), jnp.array([0.3, 0.1, 1.0]))
    # The record from rkmk4 at a quarter of the fit's step: the recovered a + b then carries the fitting
    # scheme's truncation error at dt = 0.05 (6e-10) and not the generator's (rkmk4's at dt = 0.05:
    # 1.7e-8; at h/4, 4⁴ = 256 times less, 7e-11). rkmk4's program compiles in a third of rkmk_dopri8's
    # (4 stages, not 13), which generated this record before at dt = 0.05.
    record = jaxrot.rollout(
        "rkmk4", state, jnp.array([1.0, 1.5, 2.0]), 0.0125, 800, torque=torque, args=truth, save_every=20
    )
    experiment = jaxrot.Experiment(record.t, q=record.q, sigma_q=1e-4)
    with pytest.warns(UserWarning, match="do not determine"):
        fit = jaxrot.identify(
            experiment,
            torque=torque,
            args={"a": jnp.array(0.3), "b": jnp.array(0.5)},
            free_args={"a": True, "b": True},
            inertia0=jnp.diag(jnp.array([1.0, 1.5, 2.0])),
            free_inertia=False,
            dt=0.05,
        )
    assert set(fit.unidentified) == {"args.a", "args.b"}
    assert np.isinf(fit.stderr.args["a"]) and np.isinf(fit.stderr.args["b"])
    assert np.all(np.isfinite(fit.stderr.omega0))
    np.testing.assert_allclose(float(fit.args["a"] + fit.args["b"]), 1.0, rtol=1e-8)


@pytest.mark.slow
def test_estimated_sigmas_of_two_kinds_match_the_noise():
    # σ not given: estimated per experiment and kind from the residuals, then the fit is repeated with
    # them. Each estimate pools 363 residuals (121 samples × 3 axes, less 27/6 parameters' share):
    # its relative sd is 1/√(2·363) = 3.7 %, so 20 % is over 5 sd.
    experiments, _ = satellite_experiments(0)
    blind = [jaxrot.Experiment(e.t, q=e.q, omega_body=e.omega_body, control=e.control) for e in experiments]
    fit = jaxrot.identify(
        blind, torque=dipole_torque, args={"dipole": jnp.zeros(3)}, free_args={"dipole": True}
    )
    assert fit.converged and fit.unidentified == ()
    np.testing.assert_allclose(fit.sigma[:, 0], 1e-4, rtol=0.2)
    np.testing.assert_allclose(fit.sigma[:, 1], 2e-5, rtol=0.2)
    assert np.all(np.isnan(fit.sigma[:, 2]))
    assert np.all(np.abs(np.asarray(fit.args["dipole"]) - SATELLITE_DIPOLE) < Z * fit.stderr.args["dipole"])


@pytest.mark.slow
def test_principal_moments_with_known_axes(satellite):
    # free_inertia="moments": inertia0's axes held, its three moments fitted and reported.
    experiments, _, _ = satellite
    moments, axes = np.linalg.eigh(SATELLITE_INERTIA)
    start = axes @ np.diag(moments * np.array([1.1, 0.95, 1.05])) @ axes.T  # same order of moments
    fit = jaxrot.identify(
        experiments,
        torque=dipole_torque,
        args={"dipole": jnp.zeros(3)},
        free_args={"dipole": True},
        inertia0=start,
        free_inertia="moments",
    )
    assert fit.converged and fit.unidentified == ()
    assert fit.names[:3] == ("moments[0]", "moments[1]", "moments[2]")
    fitted = np.einsum("ji,jk,ki->i", axes, np.asarray(fit.inertia), axes)
    se = np.sqrt(np.diag(fit.covariance))[:3]
    assert np.all(np.abs(fitted - moments) < Z * se)
    np.testing.assert_allclose(np.asarray(fit.inertia), axes @ np.diag(fitted) @ axes.T, atol=1e-12)


@pytest.mark.slow
def test_tracked_axis_heavy_top_centre_of_mass():
    # A heavy asymmetric top seen only through one body axis: its centre-of-mass offset is fitted.
    inertia = jnp.diag(jnp.array([1.0, 1.4, 0.7]))
    gravity = jnp.array([0.0, 0.0, -1.0])

    def torque(t, q, omega, args):
        return jnp.cross(quat.rotate(q, args["offset"]), gravity)

    offset = jnp.array([0.02, -0.01, 0.1])
    q0 = quat.exp(jnp.array([0.3, -0.2, 0.1]))
    omega0 = jnp.array([0.2, -0.1, 3.0])
    t = jnp.linspace(0.0, 6.0, 121)
    ref = jaxrot.reference_rollout(
        jaxrot.RotState(q0, omega0), inertia, t, torque=torque, args={"offset": offset}
    )
    axis = jnp.array([0.0, 0.0, 1.0])
    rng = np.random.default_rng(1)
    sigma = 1e-3
    seen = np.asarray(quat.rotate(ref.q, axis))
    noisy = seen + np.cross(rng.normal(size=(121, 3)) * sigma, seen)
    noisy /= np.linalg.norm(noisy, axis=-1, keepdims=True)
    experiment = jaxrot.Experiment(t, direction=noisy, body_vector=axis, sigma_direction=sigma)
    fit = jaxrot.identify(
        experiment,
        torque=torque,
        args={"offset": jnp.array([0.0, 0.0, 0.05])},
        free_args={"offset": True},
        inertia0=inertia,
        free_inertia=False,
        q0=np.asarray(quat.multiply(quat.exp(jnp.array([0.02, 0.0, -0.03])), q0))[None],
        omega0=np.asarray(omega0 + 0.05)[None],
    )
    assert fit.converged
    assert np.all(np.abs(np.asarray(fit.args["offset"]) - np.asarray(offset)) < Z * fit.stderr.args["offset"])
    assert np.all(fit.stderr.inertia == 0)


@pytest.mark.slow
def test_gyro_with_dropouts_irregular_times_and_positive_damping():
    # Gyro only, a known control torque fixes the scale, a damping coefficient declared positive.
    inertia = jnp.array([[2.0, 0.1, 0.0], [0.1, 3.0, -0.2], [0.0, -0.2, 4.0]])

    def damping(t, q, omega, args):
        return -args["c"] * omega

    rng = np.random.default_rng(2)
    t = np.sort(rng.uniform(0.0, 8.0, 90))
    t_c = np.linspace(0.0, 8.0, 9)
    tau_c = rng.normal(size=(9, 3))

    def torque(tt, q, omega, args):
        control = jax.vmap(lambda col: jnp.interp(tt, jnp.asarray(t_c), col), in_axes=1)(jnp.asarray(tau_c))
        return damping(tt, q, omega, args) + control

    ref = jaxrot.reference_rollout(
        jaxrot.RotState(jnp.array([1.0, 0, 0, 0]), jnp.array([0.5, -0.3, 0.8])),
        inertia,
        jnp.asarray(t),
        torque=torque,
        args={"c": 0.05},
    )
    sigma = 1e-3
    gyro = np.asarray(quat.rotate(quat.conjugate(ref.q), ref.omega)) + rng.normal(size=(90, 3)) * sigma
    gyro[[5, 17, 40]] = np.nan  # dropouts
    q_obs = np.asarray(ref.q).copy()
    q_obs[::3] = np.nan  # the star tracker sees every third sample only... and then not at all:
    q_obs[:] = np.nan
    q_obs[0] = np.asarray(ref.q[0])  # one orientation fix at the start
    experiment = jaxrot.Experiment(
        t, q=q_obs, omega_body=gyro, sigma_q=1e-4, sigma_omega=sigma, control=(t_c, tau_c)
    )
    fit = jaxrot.identify(
        experiment,
        torque=damping,
        args={"c": jnp.array(0.2)},
        free_args={"c": "positive"},
        inertia0=jnp.diag(jnp.array([2.5, 2.5, 3.5])),
    )
    assert fit.converged and float(fit.args["c"]) > 0
    assert abs(float(fit.args["c"]) - 0.05) < Z * float(fit.stderr.args["c"])
    assert np.all(np.abs(np.asarray(fit.inertia) - np.asarray(inertia)) < Z * fit.stderr.inertia)
    assert np.isnan(fit.residuals[0]["omega_body"][5]).all()


def test_jacobian_is_finite_at_a_sphere_at_rest():
    # Zero angular velocity and a spherical start: the Taylor branches keep every derivative finite.
    t = np.linspace(0.0, 1.0, 5)
    q = np.tile([1.0, 0, 0, 0], (5, 1))
    experiment = jaxrot.Experiment(t, q=q, omega_body=np.zeros((5, 3)), sigma_q=1e-3, sigma_omega=1e-3)
    with pytest.warns(UserWarning, match="do not determine"):  # a body at rest shows no inertia
        fit = jaxrot.identify(experiment, inertia0=jnp.eye(3), dt=0.25, max_iter=1)
    assert "inertia[0,0]" in fit.unidentified
    assert np.all(np.isfinite(np.asarray(fit.inertia)))
    assert np.all(np.isfinite(fit.loss_history))


@pytest.mark.parametrize("sensors", [None, "all"])
def test_per_experiment_jacobian_is_the_full_forward_jacobian(sensors):
    """`identify` pushes through each experiment only the tangents it depends on (the shared head
    and its own block); the zero blocks are filled in. With sensor parameters, the rollout carries
    only the tangents that move it and the readings are differentiated through the nodes'
    linearisation (`_jacobian.residuals_jacobian_factor`). The result must be ``jax.jacfwd`` of the
    whole residual vector: the same operations on each tangent, batched differently, so entries
    agree to reassociation only: ~10³ operations per entry (20 steps of a few dozen) at float64's
    1.1e-16, inside 1e-11 of the largest entry. The model is built by identify's own stages
    (check → start → problem), without compiling the fit. The triangular factor of ``[J | r]`` made
    from each experiment's rows (`_jacobian._block_factor`) is a QR factor of the whole: ``RᵀR = AᵀA``
    for ``A = [J | r]``, to a backward-stable QR's round-off, a small multiple of ``eps ‖A‖²``
    (1e-13 ‖A‖²_F is 450 eps: the reflections of two QRs of ~150 rows and 17 columns)."""
    from jaxrot._fit._identify._check import check_arguments
    from jaxrot._fit._identify._jacobian import n_dynamic, residuals_jacobian_factor
    from jaxrot._fit._identify._model import n_head, n_own, residuals, states
    from jaxrot._fit._identify._problem import build_problem
    from jaxrot._fit._identify._start import starting_point

    def torque(t, q, omega, args):
        return args["gain"] * jnp.array([0.0, 0.01, 0.02]) - 0.05 * omega

    experiments = []
    for w in ([0.3, 0.1, 1.0], [-0.5, 0.8, 0.2]):
        state = jaxrot.RotState(jnp.array([1.0, 0, 0, 0]), jnp.array(w))
        record = jaxrot.rollout(
            "zhao", state, jnp.array([1.0, 1.5, 2.0]), 0.05, 20, torque=torque,
            args={"gain": jnp.array(1.0)}, save_every=4,
        )  # fmt: skip
        omega_body = quat.rotate(quat.conjugate(record.q), record.omega)
        experiments.append(
            jaxrot.Experiment(record.t, q=record.q, omega_body=omega_body, sigma_q=1e-3, sigma_omega=1e-3)
        )
    settings = check_arguments(
        experiments, torque=torque, args={"gain": jnp.array(0.8)}, free_args={"gain": True}, inertia0=None,
        free_inertia=True, scheme="zhao", dt=0.05, q0=None, omega0=None, max_iter=10, ftol=1e-10,
        rcond=None, sensors=None if sensors is None else dict.fromkeys(
            ("gyro_bias", "gyro_scale", "gyro_delay", "tracker_mount", "tracker_delay"), True),
    )  # fmt: skip
    problem = build_problem(settings, starting_point(settings))
    phi, model = jnp.asarray(problem.phi0), problem.model
    if sensors is not None:  # off the ideal values, so that every sensor term is exercised
        phi = phi + 0.01 * jnp.sin(jnp.arange(phi.size))
    # Two programs, not five (each compiles in seconds and runs in milliseconds): the one the fit's
    # step evaluates (`residuals_and_jacobian` is its first three values, sliced), and the reference,
    # jacfwd of the whole residual vector, whose plain residuals and states are aux outputs of its
    # primal pass: the forward model, in a program other than the one under test.
    r, jac, (q, omega), factor = jax.jit(residuals_jacobian_factor)(phi, model)

    def reference(p):
        values = residuals(p, model)
        return values, (values, states(p, model))

    full, (r_ref, (q_ref, omega_ref)) = jax.jit(jax.jacfwd(reference, has_aux=True))(phi)
    head, own = n_head(model.layout), n_own(model.layout)
    assert n_dynamic(model.layout) == (6 + 1, 6)
    assert (head, own) == ((6 + 1, 6) if sensors is None else (6 + 1 + 3 + 1 + 3 + 1, 6 + 3))
    both = jnp.concatenate([jac, r[:, None]], axis=1)
    np.testing.assert_allclose(
        factor.T @ factor, both.T @ both, rtol=0, atol=1e-13 * float(jnp.sum(both * both))
    )
    assert jac.shape == full.shape == (r.size, head + 2 * own)
    # The values ride along as jacfwd's primal, compiled in another program: each of the 20 steps
    # rounds the state by a few eps (~1e-15 rad), whitened by σ = 1e-3: 1e-11 is 10× that margin.
    np.testing.assert_allclose(r, r_ref, rtol=0, atol=1e-11)
    np.testing.assert_allclose(jac, full, rtol=0, atol=1e-11 * float(jnp.max(jnp.abs(full))))
    # The modelled states that ride along (the fit reports them without another program) are the
    # forward model's, to the same 20 steps' round-off (a few eps each, unwhitened: 1e-13).
    np.testing.assert_allclose(q, q_ref, rtol=0, atol=1e-13)
    np.testing.assert_allclose(omega, omega_ref, rtol=0, atol=1e-13)
    # The blocks the rollouts did not compute are the zeros they must be: experiment 0's rows do
    # not move with experiment 1's block.
    rows = r.size // 2
    assert float(jnp.max(jnp.abs(full[:rows, head + own :]))) == 0.0


@pytest.mark.parametrize("hold", ["linear", "previous"])
def test_control_in_each_step_is_the_sampled_control(hold):
    """Inside each model step the control is ``value + slope (t − start)``: `np.interp` of the samples
    (``"linear"``), or the sample at or before ``t``, zero before the first (``"previous"``). Steps
    land on every control time inside the record, so no step straddles a jump or a kink. Each value
    is one interpolation plus one product: within 8 eps of the largest sample."""
    from jaxrot._fit._identify._controls import step_grid

    rng = np.random.default_rng(5)
    t = np.concatenate([[0.0], np.sort(rng.uniform(0.0, 10.0, 30)), [10.0]])
    t_c = np.sort(rng.uniform(-1.0, 11.0, 17))
    tau_c = rng.normal(size=(17, 3))
    grid = step_grid(t, (t_c, tau_c), hold, max_step=0.3)
    ends = grid.start + grid.length
    np.testing.assert_allclose(ends[:-1], grid.start[1:], rtol=0, atol=1e-13)
    assert grid.length.max() <= 0.3 and abs(ends[-1] - 10.0) < 1e-13
    nodes = np.concatenate([grid.start, ends[-1:]])
    inside = t_c[(t_c > 0) & (t_c < 10)]
    assert np.all(np.min(np.abs(inside[:, None] - nodes[None, :]), axis=1) < 1e-12)  # steps land on them
    np.testing.assert_allclose(nodes[grid.sample_node], t, rtol=0, atol=1e-13)
    fraction = rng.uniform(0.0, 1.0, grid.start.size)
    times = grid.start + fraction * grid.length
    got = grid.value + grid.slope * (times - grid.start)[:, None]
    if hold == "linear":
        expected = np.stack([np.interp(times, t_c, tau_c[:, i]) for i in range(3)], axis=-1)
    else:
        index = np.searchsorted(t_c, times, side="right") - 1
        expected = np.where(index[:, None] >= 0, tau_c[np.maximum(index, 0)], 0.0)
    np.testing.assert_allclose(got, expected, rtol=0, atol=8 * np.finfo(float).eps * np.abs(tau_c).max())


@pytest.mark.slow
def test_a_model_error_above_round_off_still_stops_converged():
    """Noise-free satellite data fitted with rkmk_dopri5 at three steps per sample: the model error
    (~2e-10 rad against σ = 1e-4) leaves the objective at ~7e-9, where ``ftol ×`` it is below its
    own round-off. The fit must still stop converged in a few iterations (it once stalled, accepting
    unchanged points, until ``max_iter``: 100 s)."""
    experiments, _ = satellite_experiments(0, noise=False)
    fit = jaxrot.identify(
        experiments, torque=dipole_torque, args={"dipole": jnp.zeros(3)}, free_args={"dipole": True},
        scheme="rkmk_dopri5", dt=5.0 / 3,
    )  # fmt: skip
    assert fit.converged and fit.n_iterations <= 8
    assert fit.loss < 1e-6  # the model error only: nothing of the data is left unfitted


def _ok_experiment():
    return jaxrot.Experiment(np.linspace(0, 1, 5), omega_body=np.ones((5, 3)))


@pytest.mark.parametrize(
    "make, match",
    [
        (
            lambda: jaxrot.Experiment(np.linspace(0, 1, 5), q=np.tile([1.0, 0, 0, 0], (4, 1))),
            "4 rows but `t` has 5",
        ),
        (lambda: jaxrot.Experiment(np.array([0.0, 2.0, 1.0]), omega_body=np.ones((3, 3))), "unsorted"),
        (lambda: jaxrot.Experiment(np.array([0.0, 1.0, 1.0]), omega_body=np.ones((3, 3))), "duplicate"),
        (
            lambda: jaxrot.Experiment(np.linspace(0, 1, 3), omega_body=np.ones((3, 3)), sigma_omega=0.0),
            "sigma_omega",
        ),
        (
            lambda: jaxrot.Experiment(np.linspace(0, 1, 3), omega_body=np.ones((3, 3)), sigma_q=-1.0),
            "sigma_q",
        ),
        (lambda: jaxrot.Experiment(np.linspace(0, 1, 3)), "no observation"),
        (
            lambda: jaxrot.Experiment(np.linspace(0, 1, 3), omega_body=np.full((3, 3), np.nan)),
            "no observation",
        ),
        (lambda: jaxrot.Experiment(np.linspace(0, 1, 3), direction=np.ones((3, 3))), "body_vector"),
        (lambda: jaxrot.Experiment(np.linspace(0, 1, 3), q=np.ones((3, 4))), "unit quaternions"),
        (
            lambda: jaxrot.identify(
                _ok_experiment(),
                torque=lambda t, q, w, a: a["k"] * w,
                args={"k": 1.0},
                free_args={"kk": True},
                inertia0=jnp.eye(3),
            ),
            "not in `args`",
        ),
        (lambda: jaxrot.identify(_ok_experiment()), "inertia0"),
        (lambda: jaxrot.identify(_ok_experiment(), inertia0=jnp.eye(3), free_inertia="axes"), "free_inertia"),
        (lambda: jaxrot.identify([]), "experiments"),
        (
            lambda: jaxrot.identify(_ok_experiment(), inertia0=jnp.diag(jnp.array([1.0, 1.0, 3.0]))),
            "triangle",
        ),
    ],
)
def test_bad_input_is_a_value_error_before_compilation(make, match):
    with pytest.raises(ValueError, match=match):
        make()
