"""`mujoco.sysid` fitting the inertia *and the sensors' flaws* to `_mujoco_telemetry.sensor_manoeuvres`.

The data: MuJoCo's free body (`_mujoco_telemetry`) seen through real sensors, a gyro bias per
manoeuvre, a gyro scale factor and delay, a star tracker mounted at a small rotation of the body
frame and with a delay of its own (`_mujoco_telemetry.TRUE_SENSORS`). What a careful user of sysid
writes to fit all of them, beside the inertia and each manoeuvre's initial state of `_mujoco_sysid`
(every flaw has a sysid expression; `SYSID_EXPRESSES` names the API each one uses):

- **tracker mount**: a model parameter. The ``framequat`` sensor reads a site ``tracker`` of the body
  (``q ⊗ q_site``, MuJoCo's frame composition), and a sysid ``Parameter`` with a modifier writes the
  site's ``quat`` as ``exp(mount) ⊗ R₀`` before each compile. ``R₀`` = `TRACKER_BASE`, a quarter
  turn, is the tracker's nominal mounting, and its readings are given in that frame (``q_obs ⊗ R₀``):
  MuJoCo's compiler gives a site whose orientation is within ~1e-6 of its body's the body's own
  orientation (``site_sameframe``), so about an identity base, sysid's finite-difference steps of
  1.5e-8 rad see no change and the mount's column is zero (measured: the fit left it at 0, its
  standard error 190 rad);
- **gyro scale, gyro delay, tracker delay**: sysid's ``SignalTransform`` (``gain`` on the predicted
  gyro, ``delay`` on each sensor: the prediction resampled at ``t − delay``, linear between MuJoCo
  steps of 1 ms; at 0.35 rad/s that interpolation errs by (ω·dt)²/8 ≈ 2e-8, far under σ = 1e-4);
- **gyro bias per manoeuvre**: ``SignalTransform.bias`` takes one ``Parameter`` for every
  trajectory, so each manoeuvre gets a transform with its own bias, and a ``modify_residual``
  callback hands each trajectory to its manoeuvre's transform (told apart by their data);
- **delay bounds**: sysid's transform keeps the samples whose delayed reading falls inside the
  prediction for any delay in the bounds; the rollout starts with the controls at ``t_c[0]``, one
  sample spacing (10 ms) before the first sample, so the bounds are ± `DELAY_BOUND` = 9.5 ms (the
  true delays are 4 and 7 ms) and the controls are held `PAD` steps past the last sample;
- **initial state**: at the controls' start, from the first samples (its offset is fitted: ± 0.1 rad,
  the mount's 0.023 rad and 10 ms of turning at 0.35 rad/s inside).

The residuals, optimiser and intervals are sysid's defaults, as in `_mujoco_sysid`.
"""

import time

import numpy as np
from _mujoco_sysid import (
    INERTIA0,
    OMEGA0_BOUND,
    SysidProblem,
    _inertia_parameter,
    _initial_state_rollout,
    _quat_exp,
    _quat_mul,
    _require_sysid,
    _sequences,
    _theta_of,
    fit_problem,
    mujoco,
    sysid,
)
from _mujoco_telemetry import model_xml


DELAY_BOUND = 0.0095  # s: under the 10 ms between the controls' start and the first sample
TRACKER_BASE = np.array([np.sqrt(0.5), 0.0, 0.0, np.sqrt(0.5)])  # a quarter turn about body z
PAD = 13  # held control steps past the last one: the prediction reaches ≥ DELAY_BOUND past the last sample
MOUNT_BOUND = 0.1  # rad per axis of the tracker's mounting rotation vector
SCALE_BOUND = 0.1  # gyro scale within 1 ± 0.1
BIAS_BOUND = 0.05  # rad/s per axis
Q0_BOUND = 0.1  # rad: the start's orientation offset (module docstring)

# The flaws this module fits, each with the sysid name it uses: the benchmark's real-sensor row lists
# them as fitted (and any flaw missing here as left out); benchmarks/_identify_capabilities.py is the
# table a person reads, its names checked against mujoco.sysid by tests/test_results_identify.py.
SYSID_EXPRESSES = {
    "gyro_bias": "SignalTransform.bias",
    "gyro_scale": "SignalTransform.gain",
    "gyro_delay": "SignalTransform.delay",
    "tracker_mount": "Parameter",  # with a modifier writing the tracker site's quat
    "tracker_delay": "SignalTransform.delay",
}


def sensor_model_xml(inertia=INERTIA0):
    """`_mujoco_telemetry.model_xml` with the orientation sensor on a site ``tracker`` of the body."""
    xml = model_xml(inertia)
    for old, new in (
        ('<site name="imu"/>', '<site name="imu"/>\n      <site name="tracker" quat="{}"/>'),
        ('objtype="xbody" objname="body"', 'objtype="site" objname="tracker"'),
    ):
        assert xml.count(old) == 1, old
        xml = xml.replace(old, new.format(" ".join(repr(float(x)) for x in TRACKER_BASE)))
    return xml


def sysid_sensor_problem(manoeuvres, *, inertia0=INERTIA0):
    """The sysid problem of the module docstring, from ``inertia0``, ideal sensors and the first samples."""
    _require_sysid()
    spec = mujoco.MjSpec.from_string(sensor_model_xml(inertia0))
    model = spec.compile()
    theta0 = _theta_of(inertia0)

    def write_mount(spec, param):
        spec.site("tracker").quat = _quat_mul(_quat_exp(np.asarray(param.value)), TRACKER_BASE)

    def box(name, nominal, bound, **kw):
        nominal = np.atleast_1d(np.asarray(nominal, dtype=float))
        return sysid.Parameter(name, nominal, nominal - bound, nominal + bound, **kw)

    params = sysid.ParameterDict()
    params.add(_inertia_parameter(theta0))
    params.add(box("tracker_mount", np.zeros(3), MOUNT_BOUND, modifier=write_mount))
    params.add(box("gyro_scale", np.ones(3), SCALE_BOUND))
    params.add(box("gyro_delay", 0.0, DELAY_BOUND))
    params.add(box("tracker_delay", 0.0, DELAY_BOUND))
    first_q = [m.q[0] for m in manoeuvres]  # the body's orientation, the start of the initial states
    # The tracker's readings in its nominal frame (module docstring): what sysid compares.
    manoeuvres = [m._replace(q=np.array([_quat_mul(q, TRACKER_BASE) for q in m.q])) for m in manoeuvres]
    first_omega = [m.omega_body[0] for m in manoeuvres]
    transforms = {}
    for j, (m, w) in enumerate(zip(manoeuvres, first_omega, strict=True)):
        params.add(box(f"q0_offset_{j}", np.zeros(3), Q0_BOUND))
        params.add(box(f"omega0_{j}", w, OMEGA0_BOUND))
        params.add(box(f"gyro_bias_{j}", np.zeros(3), BIAS_BOUND))
        transform = sysid.SignalTransform()
        transform.delay("orientation", params["tracker_delay"])
        transform.delay("gyro", params["gyro_delay"])
        transform.gain("gyro", params["gyro_scale"], target="predicted")
        transform.bias("gyro", params[f"gyro_bias_{j}"], target="predicted")
        # sysid's measured series is the one given, shifted to MuJoCo's stamps (t + dt): keyed by its data.
        transforms[np.hstack([m.q[0], m.omega_body[0]]).tobytes()] = transform
    sequences, measured_initial_states = _sequences(spec, model, manoeuvres, min_pad=PAD)

    def modify_residual(params, predicted, measured, model, return_pred_all, **kwargs):
        transform = transforms[np.asarray(measured.data[0], dtype=float).tobytes()]
        res, predicted, measured = transform.apply(
            params, predicted, measured, model, return_pred_all, **kwargs
        )
        # sysid 4.0 then checks `predicted.signal_mapping != measured.signal_mapping`: two dicts of
        # (type, index array) that are equal but not the same objects, so `!=` compares the arrays and
        # raises for any sensor of more than one column; handing back one mapping passes the check.
        return res, sysid.TimeSeries(predicted.times, predicted.data, measured.signal_mapping), measured

    custom_rollout = _initial_state_rollout(model, measured_initial_states, first_q)
    residual_fn = sysid.build_residual_fn(
        models_sequences=[sequences], custom_rollout=custom_rollout, modify_residual=modify_residual
    )
    return SysidProblem(params, residual_fn, theta0, first_q, first_omega)


SENSOR_NAMES = ("tracker_mount", "gyro_scale", "gyro_delay", "tracker_delay")


def sysid_sensor_fit(manoeuvres, *, inertia0=INERTIA0, max_iters=100):
    """Fit the inertia, each manoeuvre's initial state and the sensors' flaws with ``mujoco.sysid``.

    Returns `_mujoco_sysid.SysidFit`; its ``extra`` holds the fitted ``tracker_mount`` ``(3,)`` (rad),
    ``gyro_scale`` ``(3,)``, ``gyro_delay`` ``(1,)`` and ``tracker_delay`` ``(1,)`` (s), and
    ``gyro_bias`` ``(k, 3)`` (rad/s, one row per manoeuvre).
    """
    start = time.perf_counter()
    problem = sysid_sensor_problem(manoeuvres, inertia0=inertia0)
    biases = tuple(f"gyro_bias_{j}" for j in range(len(manoeuvres)))
    fit = fit_problem(problem, start, max_iters=max_iters, extra=SENSOR_NAMES + biases)
    extra = {name: fit.extra[name] for name in SENSOR_NAMES}
    extra["gyro_bias"] = np.stack([fit.extra[name] for name in biases])
    return fit._replace(extra=extra)
