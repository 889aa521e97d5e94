"""`jaxrot.identify` on real telemetry: held and body-frame controls, sensor parameters, per-experiment
conditions, and the report.

Data come from the package's reference solver (diffrax Dopri8 at 1e-12, steps landing on the control
times) through the sensor models of `_telemetry.sensor_experiments`. Recovery is checked as
|estimate − truth| < 4 standard errors (each such event has probability 6e-5 for a calibrated fit,
see test_identify.py); noise-free data are fitted to 1e-6 relative or better, at a step (a quarter of
the sample spacing) where the default scheme's own error (fifth order) is far below that.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _telemetry import (
    CONTROLS,
    SATELLITE_DIPOLE,
    SATELLITE_INERTIA,
    TRUE_SENSORS,
    dipole_torque,
    sensor_experiments,
    sensor_torque,
)

import jaxrot
from jaxrot import quaternion as quat


Z = 4.0
THRUSTERS = ((0.0, 0.0, 0.0), (5e-7, -3e-7, 2e-7), (0.0, 0.0, 0.0))  # N m, world frame: manoeuvre 1 only
DRAGS = (2e-5, 4e-5, 1e-5)  # N m s: the drag differs between manoeuvres (a payload moved)


def _fit_everything(seed, noise, n, dt=None):
    """Three manoeuvres (world/linear, body/held, world/held controls) through all five sensor flaws,
    a thruster known in manoeuvre 1 only, a drag fitted per manoeuvre."""
    experiments, truth = sensor_experiments(
        seed, sensors=TRUE_SENSORS, noise=noise, n=n, thrusters=THRUSTERS, drags=DRAGS, known_thrusters=(1,)
    )
    fit = jaxrot.identify(
        experiments,
        torque=sensor_torque,
        args={"dipole": jnp.zeros(3), "thruster": jnp.zeros(3), "drag": jnp.asarray(0.0)},
        free_args={"dipole": True, "drag": "per_experiment"},
        sensors={name: True for name in TRUE_SENSORS},
        dt=dt,
    )
    return experiments, truth, fit


@pytest.fixture(scope="module")
def noise_free():
    return _fit_everything(0, noise=False, n=61, dt=2.5)


def _errors(fit, truth):
    """(name, estimate, truth) of every physical parameter of `_fit_everything`."""
    rows = [("inertia", np.asarray(fit.inertia), SATELLITE_INERTIA)]
    rows.append(("dipole", np.asarray(fit.args["dipole"]), SATELLITE_DIPOLE))
    rows.append(("drag", np.asarray(fit.args["drag"]), np.asarray(DRAGS)))
    rows += [(name, np.asarray(fit.sensors[name]), value) for name, value in TRUE_SENSORS.items()]
    rows.append(("omega0", np.asarray(fit.omega0), np.stack(truth["omega0"])))
    return rows


def test_noise_free_real_sensors_are_fitted_to_1e_6_relative(noise_free):
    experiments, truth, fit = noise_free
    assert fit.converged and fit.unidentified == ()
    for name, estimate, true in _errors(fit, truth):
        np.testing.assert_allclose(estimate, true, rtol=1e-6, atol=0, err_msg=name)
    angles = quat.angle_between(fit.q0, jnp.asarray(np.stack(truth["q0"])))
    assert float(jnp.max(angles)) < 1e-8
    # The held per-experiment thruster went in as given, the fitted drag came out per experiment.
    assert fit.args["drag"].shape == (3,) and fit.args["thruster"].shape == (3, 3)
    np.testing.assert_array_equal(np.asarray(fit.args["thruster"]), np.asarray(THRUSTERS))
    assert np.all(fit.stderr.args["thruster"] == 0) and np.all(fit.stderr.args["drag"] > 0)
    assert set(fit.sensors) == set(TRUE_SENSORS) and fit.sensors["gyro_bias"].shape == (3, 3)
    assert {"sensors.gyro_bias[2,1]", "sensors.gyro_delay", "args.drag[1]"} <= set(fit.names)


def test_a_far_start_runs_the_windows_and_a_close_one_the_whole_record(noise_free):
    """The all-flaws start is 1.5–2.0 rad off the data (far: over `CLOSE_ANGLE`), so the fit runs its
    windows; restarted at its own optimum (close) it skips them and stays there (to 1e-10 relative:
    Gauss–Newton's step at the optimum of noise-free data is round-off). The same compiled loop as the
    fixture's (``use_windows`` and the start are runtime values)."""
    from jaxrot._fit._identify._check import check_arguments
    from jaxrot._fit._identify._problem import build_problem
    from jaxrot._fit._identify._solve import solve
    from jaxrot._fit._identify._start import starting_point

    experiments, _, fit = noise_free
    settings = check_arguments(
        experiments, torque=sensor_torque,
        args={"dipole": jnp.zeros(3), "thruster": jnp.zeros(3), "drag": jnp.asarray(0.0)},
        free_args={"dipole": True, "drag": "per_experiment"}, inertia0=None, free_inertia=True, scheme=None,
        dt=2.5, q0=None, omega0=None, max_iter=100, ftol=1e-10, rcond=None,
        sensors={name: True for name in TRUE_SENSORS},
    )  # fmt: skip
    start = starting_point(settings)
    problem = build_problem(settings, start)
    far = solve(problem, settings, start.speed)
    assert far.windowed and far.converged and far.n_iterations == fit.n_iterations
    close = solve(problem._replace(phi0=far.phi), settings, start.speed)
    assert not close.windowed and close.converged
    np.testing.assert_allclose(close.phi, far.phi, rtol=1e-10, atol=1e-10 * np.max(np.abs(far.phi)))


def test_summary_and_residual_figure(noise_free):
    _, _, fit = noise_free
    text = fit.summary()
    for name in fit.names:
        if not name.startswith("q0["):
            assert name in text
    assert "unidentified: none" in text and "lag-1" in text and "q0[2] = [" in text
    # The default scheme with its chart, and units a person reads (the legend defines [t] and [τ]).
    assert "scheme rkmk_dopri5 (cayley chart)" in text
    assert "inertia[0,0]" in text and "[τ]·[t]²" in text and "M L²" not in text
    assert "sensors.gyro_delay" in text and " [t]" in text and "rad/[t]" in text and "units: [t]" in text
    assert fit.reliable and fit.problems == () and "NOT RELIABLE" not in text
    figure = fit.plot_residuals()
    assert len(figure.axes) == 3 * 2  # experiments × sensors (tracker, gyro)
    titles = [ax.get_title() for ax in figure.axes]
    assert titles[0].startswith("experiment 0, tracker") and titles[-1].startswith("experiment 2, gyro")


def test_a_scalar_gyro_scale_is_one_factor_for_the_three_axes():
    from jaxrot._fit._identify._sensors import check_sensors

    (sensor,) = check_sensors({"gyro_scale": 1.02}, [_gyro_experiment()])
    assert not sensor.fitted
    np.testing.assert_array_equal(sensor.value, [1.02, 1.02, 1.02])


def test_the_summary_names_the_scheme_with_its_chart():
    from jaxrot._fit._identify._report import scheme_label

    assert scheme_label(jaxrot.schemes.RKMKDopri5(chart="cayley")) == "rkmk_dopri5 (cayley chart)"
    assert scheme_label("rkmk_dopri5") == "rkmk_dopri5 (exp chart)"
    assert scheme_label("zhao") == "zhao"


def test_residual_statistics_tell_white_noise_from_a_model_error():
    """Whitened white noise: RMS 1 ± 1/√(2·3n) and lag-one autocorrelation 0 ± 1/√(3n) (n = 2000:
    ±0.009 and ±0.013, checked at 5 sd); a slow drift (a random walk, what an unmodelled bias leaves)
    correlates consecutive residuals near 1."""
    from jaxrot._fit._identify._report import residual_statistics

    rng = np.random.default_rng(0)
    white = rng.normal(size=(2000, 3))
    white[17] = np.nan  # a dropout is skipped
    n, rms, lag = residual_statistics(white)
    assert n == 1999 and abs(rms - 1) < 5 * 0.009 and abs(lag) < 5 * 0.013
    walk = np.cumsum(rng.normal(size=(2000, 3)), axis=0) / 30
    assert residual_statistics(walk)[2] > 0.95


@pytest.mark.parametrize(
    "scheme, order, floor",
    [(jaxrot.schemes.RKMKDopri5(chart="cayley"), 5, 1e-9), ("splitting", 2, 1e-3)],
    ids=["default", "splitting"],
)
def test_held_body_frame_control_keeps_the_schemes_order(scheme, order, floor):
    """A body-frame torque held between switches that fall between samples: the model's steps land on
    the switches, so a scheme keeps its order (a step across a jump would be first order). The
    model's states at the true parameters against the reference (steps on the switches too), at 2,
    4, 8, 16 steps per sample: the log-log slope within 0.3 of the order. The default scheme, and a
    splitting, whose carried end-of-step torque is stale across a switch (re-evaluated there)."""
    from jaxrot._fit._identify._check import check_arguments
    from jaxrot._fit._identify._model import states
    from jaxrot._fit._identify._problem import build_problem
    from jaxrot._fit._identify._start import starting_point

    inertia = np.array([[1.0, 0.1, 0.0], [0.1, 1.6, -0.05], [0.0, -0.05, 2.1]])
    q0, omega0 = quat.exp(jnp.array([0.2, -0.1, 0.4])), jnp.array([0.4, -0.3, 1.1])
    t = np.linspace(0.0, 4.0, 9)
    t_c = np.array([0.13, 0.71, 1.37, 2.05, 2.93, 3.41])
    tau_c = np.random.default_rng(3).normal(size=(6, 3)) * 0.5

    def held(time, q, omega, args):
        index = jnp.searchsorted(args["t_c"], time, side="right") - 1
        return quat.rotate(q, jnp.where(index >= 0, args["tau_c"][jnp.maximum(index, 0)], 0.0))

    ref = jaxrot.reference_rollout(
        jaxrot.RotState(q0, omega0), jnp.asarray(inertia), jnp.asarray(t), torque=held,
        args={"t_c": jnp.asarray(t_c), "tau_c": jnp.asarray(tau_c)}, jump_ts=jnp.asarray(t_c),
    )  # fmt: skip
    experiment = jaxrot.Experiment(
        t,
        q=np.asarray(ref.q),
        sigma_q=1.0,
        control=(t_c, tau_c),
        control_frame="body",
        control_hold="previous",
    )
    errors, steps = [], []
    for per_sample in (2, 4, 8, 16):
        settings = check_arguments(
            experiment, torque=None, args=None, free_args=None, inertia0=inertia, free_inertia=False,
            scheme=scheme, dt=0.5 / per_sample,
            q0=np.asarray(q0)[None], omega0=np.asarray(omega0)[None], max_iter=1, ftol=0.0, rcond=None,
            sensors=None,
        )  # fmt: skip
        problem = build_problem(settings, starting_point(settings))
        q_model, _ = jax.jit(states)(jnp.asarray(problem.phi0), problem.model)
        errors.append(float(jnp.max(quat.angle_between(q_model[0], ref.q))))
        steps.append(problem.max_step)
    slope = np.polyfit(np.log(steps), np.log(errors), 1)[0]
    assert abs(slope - order) < 0.3, (slope, errors)
    assert errors[-1] < floor


def test_a_bias_the_data_cannot_tell_from_the_spin_is_named():
    """A steady spin about a principal axis, one tracker fix at the start and a gyro: the gyro reads
    spin + bias along the axis, and nothing else tells the two apart (a transverse bias is not
    confused: a transverse change of ω would make the body nutate). Both are named."""
    inertia = jnp.array([1.0, 1.5, 2.0])
    spin = jaxrot.RotState(jnp.array([1.0, 0, 0, 0]), jnp.array([0.0, 0.0, 0.8]))
    record = jaxrot.rollout("rkmk4", spin, inertia, 0.05, 200, save_every=10)
    gyro = np.asarray(quat.rotate(quat.conjugate(record.q), record.omega)) + np.array([1e-3, -2e-3, 3e-3])
    q_obs = np.full((21, 4), np.nan)
    q_obs[0] = np.asarray(record.q[0])
    experiment = jaxrot.Experiment(record.t, q=q_obs, omega_body=gyro, sigma_q=1e-4, sigma_omega=1e-4)
    with pytest.warns(UserWarning, match="do not determine"):
        fit = jaxrot.identify(
            experiment, inertia0=inertia, free_inertia=False, sensors={"gyro_bias": True}, dt=0.1
        )
    assert set(fit.unidentified) == {"omega0[0,2]", "sensors.gyro_bias[0,2]"}
    assert np.isinf(fit.stderr.sensors["gyro_bias"][0, 2]) and np.isinf(fit.stderr.omega0[0, 2])
    np.testing.assert_allclose(np.asarray(fit.sensors["gyro_bias"][0, :2]), [1e-3, -2e-3], atol=1e-7)
    np.testing.assert_allclose(float(fit.omega0[0, 2] + fit.sensors["gyro_bias"][0, 2]), 0.803, atol=1e-7)
    assert "unidentified (the data do not determine them): omega0[0,2]" in fit.summary()


def _gyro_experiment(**kwargs):
    return jaxrot.Experiment(np.linspace(0, 1, 5), omega_body=np.ones((5, 3)), **kwargs)


def _fit(experiments, **kwargs):
    kwargs = {"inertia0": jnp.eye(3), **kwargs}
    return jaxrot.identify(experiments, **kwargs)


@pytest.mark.parametrize(
    "make, match",
    [
        (lambda: _fit(_gyro_experiment(), sensors={"gyro_bais": True}), "does not model"),
        (lambda: _fit(_gyro_experiment(), sensors=["gyro_bias"]), "must be a dict"),
        (
            lambda: _fit(
                jaxrot.Experiment(np.linspace(0, 1, 5), q=np.tile([1.0, 0, 0, 0], (5, 1))),
                sensors={"gyro_scale": True},
            ),
            "no experiment has omega_body",
        ),  # fmt: skip
        (lambda: _fit(_gyro_experiment(), sensors={"tracker_delay": True}), "no experiment has q"),
        (lambda: _fit(_gyro_experiment(), sensors={"gyro_bias": np.zeros(3)}), r"shape \(1, 3\)"),
        (lambda: _fit(_gyro_experiment(), sensors={"gyro_scale": False}), "Leave the key out"),
        (lambda: _fit(_gyro_experiment(), sensors={"gyro_scale": np.array([1.0, 0.0, 1.0])}), "nonzero"),
        (
            lambda: _fit(
                [
                    _gyro_experiment(),
                    jaxrot.Experiment(np.linspace(0, 1, 5), q=np.tile([1.0, 0, 0, 0], (5, 1))),
                ],
                sensors={"gyro_bias": True},
            ),
            "experiment 1 has no omega_body",
        ),  # fmt: skip
        (
            lambda: _gyro_experiment(control=(np.arange(2.0), np.ones((2, 3))), control_frame="bdy"),
            "control_frame",
        ),
        (
            lambda: _gyro_experiment(control=(np.arange(2.0), np.ones((2, 3))), control_hold="zoh"),
            "control_hold",
        ),
        (
            lambda: _gyro_experiment(control=(np.arange(2.0), np.ones((2, 2))), control_frame="body"),
            r"\(2, 3\) of body-frame torques",
        ),
        (lambda: _fit(_gyro_experiment(), sensors={"gyro_scale": 0.0}), "nonzero"),  # a scalar: all axes
        (lambda: _gyro_experiment(args=[1.0]), "must be a dict"),
        (
            lambda: _fit(
                _gyro_experiment(args={"mass": 2.0}),
                torque=lambda t, q, w, a: a["k"] * w,
                args={"k": jnp.asarray(1.0)},
            ),
            "not in identify's `args`",
        ),  # fmt: skip
        (
            lambda: _fit(
                _gyro_experiment(args={"k": jnp.ones(2)}),
                torque=lambda t, q, w, a: a["k"] * w,
                args={"k": jnp.asarray(1.0)},
            ),
            "has shape",
        ),  # fmt: skip
        (
            lambda: _fit(
                _gyro_experiment(args={"k": 2.0}),
                torque=lambda t, q, w, a: a["k"] * w,
                args={"k": jnp.asarray(1.0)},
                free_args={"k": True},
            ),
            "per_experiment",
        ),  # fmt: skip
        (
            lambda: _fit(
                _gyro_experiment(),
                torque=lambda t, q, w, a: a["k"] * w,
                args={"k": jnp.asarray(1.0)},
                free_args={"k": "per_body"},
            ),
            "per_experiment",
        ),  # fmt: skip
    ],
)
def test_bad_sensor_control_and_condition_input_is_a_value_error(make, match):
    with pytest.raises(ValueError, match=match):
        make()


@pytest.mark.slow
def test_noisy_real_sensors_within_their_standard_errors():
    """The fit of the noise-free test on noisy data (σ_q = 1e-4 rad, σ_ω = 2e-5 rad/s, 121 samples):
    every parameter within 4 standard errors, and the loss the χ² of the noise."""
    experiments, truth, fit = _fit_everything(1, noise=True, n=121)
    assert fit.converged and fit.unidentified == ()
    se = {
        "inertia": fit.stderr.inertia, "dipole": fit.stderr.args["dipole"], "drag": fit.stderr.args["drag"],
        "omega0": fit.stderr.omega0, **fit.stderr.sensors,
    }  # fmt: skip
    for name, estimate, true in _errors(fit, truth):
        assert np.all(np.abs(estimate - true) < Z * se[name]), name
    m = sum(int(np.sum(np.isfinite(r))) for parts in fit.residuals for r in parts.values())
    n = len(fit.names) - 3  # the labelled inertia has 6 entries, each q0 3: as many as φ
    assert abs(fit.loss - (m - n)) < 5 * np.sqrt(2 * (m - n))


@pytest.mark.slow
@pytest.mark.parametrize("controls", [CONTROLS[3:] + CONTROLS[:1], CONTROLS[1:3]])
def test_each_control_option_alone_is_recovered(controls):
    """Ideal sensors, the satellite of test_identify.py with each combination of control frame and
    hold (body/linear with world/linear, then body/held with world/held): inertia and dipole within
    4 standard errors."""
    experiments, _ = sensor_experiments(2, controls=controls)
    fit = jaxrot.identify(
        experiments, torque=dipole_torque, args={"dipole": jnp.zeros(3)}, free_args={"dipole": True}
    )
    assert fit.converged and fit.unidentified == ()
    assert np.all(np.abs(np.asarray(fit.inertia) - SATELLITE_INERTIA) < Z * fit.stderr.inertia)
    assert np.all(np.abs(np.asarray(fit.args["dipole"]) - SATELLITE_DIPOLE) < Z * fit.stderr.args["dipole"])
