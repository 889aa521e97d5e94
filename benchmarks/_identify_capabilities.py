"""What `jaxrot.identify` and `mujoco.sysid` can each express, as `benchmarks/identify_mujoco.py` uses them.

Plain data (no imports), read by the benchmark (which writes it beside its rows), by the docs' table
hook (docs/_hooks/_tables_identify.py) and by tests/test_results_identify.py, which checks every cell:
its ``api`` names something that exists (an `identify` or `Experiment` keyword or sensor key, an
attribute of `Identification`; an attribute of ``mujoco.sysid`` or a keyword of its ``residual``),
and its ``usage`` is a string in the code that drives that tool on MuJoCo's data
(`DRIVERS`), so each claim is code that runs in the benchmark. A cell without an ``api`` is a "no".
"""

# The files whose code backs the cells (usage strings are looked up in them), per tool.
DRIVERS = {
    # MuJoCo's data, and the satellite of identify_speed's diffrax + optimistix comparison (its controls
    # interpolated: tests/_telemetry.py's CONTROLS).
    "jaxrot": ("benchmarks/identify_mujoco.py", "benchmarks/identify_speed.py", "tests/_telemetry.py"),
    "sysid": ("tests/_mujoco_sysid.py", "tests/_mujoco_sysid_sensors.py"),
}


def _cell(text, api=None, usage=None):
    return {"text": text, "api": api, "usage": usage}


# (what, jaxrot's cell, sysid's cell). jaxrot api forms: "identify:name" (a keyword), "Experiment:name",
# "sensors:name" (a key of identify's sensors), "Identification.name". sysid api forms: "a.b" (an
# attribute path of mujoco.sysid), "residual:name" (a keyword of mujoco.sysid.residual).
CAPABILITIES = (
    (
        "gyro bias, one per manoeuvre",
        _cell('`sensors["gyro_bias"]` (one row per experiment)', "sensors:gyro_bias", '"gyro_bias"'),
        _cell(
            "`SignalTransform.bias`: one parameter for all trajectories; one per manoeuvre takes a "
            "transform per manoeuvre and a `modify_residual` callback that tells them apart",
            "SignalTransform.bias",
            "transform.bias(",
        ),
    ),
    (
        "gyro scale factor",
        _cell('`sensors["gyro_scale"]`', "sensors:gyro_scale", '"gyro_scale"'),
        _cell("`SignalTransform.gain`", "SignalTransform.gain", "transform.gain("),
    ),
    (
        "sensor delay",
        _cell(
            '`sensors["gyro_delay"]`, `sensors["tracker_delay"]`: the model stepped to `t − delay`',
            "sensors:tracker_delay",
            '"tracker_delay"',
        ),
        _cell(
            "`SignalTransform.delay`: the prediction interpolated linearly between steps, within box bounds",
            "SignalTransform.delay",
            "transform.delay(",
        ),
    ),
    (
        "tracker mounted at a rotation of the body",
        _cell('`sensors["tracker_mount"]`', "sensors:tracker_mount", '"tracker_mount"'),
        _cell(
            "a `Parameter` whose modifier writes the sensor site's `quat` (the model recompiled), about a "
            "base rotation: MuJoCo takes a site within ~1e-6 of its body's orientation for the body's",
            "Parameter",
            "spec.site(",
        ),
    ),
    (
        "controls held over each step",
        _cell('`Experiment(control_hold="previous")`', "Experiment:control_hold", 'control_hold="previous"'),
        _cell(
            "MuJoCo's `ctrl`, held over each time step (`ModelSequences`)",
            "ModelSequences",
            "ModelSequences(",
        ),
    ),
    (
        "controls interpolated between samples",
        _cell('`Experiment(control_hold="linear")` (the default)', "Experiment:control_hold", '"linear")'),
        _cell("no: resampled onto the time step (`TimeSeries.resample`), then held within each step"),
    ),
    (
        "each manoeuvre's initial state fitted",
        _cell("always (`q0`, `omega0` give the start; default: the first samples)", "identify:q0", "q0"),
        _cell(
            "not by default (the first samples); fitted through a `custom_rollout` that builds each "
            "rollout's initial state from parameters",
            "residual:custom_rollout",
            "custom_rollout=",
        ),
    ),
    (
        "covariance of the fit",
        _cell(
            "`Identification.covariance`, `stderr`: (JᵀJ)⁻¹ of residuals whitened by the given σ",
            "Identification.covariance",
            "stderr",
        ),
        _cell(
            "`calculate_intervals`: s² (JᵀJ)⁻¹ with one pooled s², residuals scaled by each column's norm",
            "calculate_intervals",
            "calculate_intervals(",
        ),
    ),
)
