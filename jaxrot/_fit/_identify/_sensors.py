"""Sensor parameters of `identify`: gyro bias, scale and delay; star-tracker mounting and delay.

Observation models (whitened like every residual), with ``q(t)``, ``ω_b(t)`` the modelled
orientation and body-frame angular velocity:

- gyro reading    = ``gyro_scale ⊙ ω_b(t − gyro_delay) + gyro_bias`` (one bias per experiment);
- tracker reading = ``q(t − tracker_delay) ⊗ exp(tracker_mount)`` (the tracker's frame, a fixed
  rotation ``tracker_mount`` of the body frame, given as a rotation vector).

Each is fitted (``True``: from its ideal value, no bias, unit scale, no delay, no mounting
rotation) or held at a given value.
"""

from typing import NamedTuple

import numpy as np


class SensorKind(NamedTuple):
    shape: tuple  # of one value; () for a scalar
    ideal: float  # the perfect sensor's value, every fitted parameter's start
    observes: str  # the Experiment attribute the sensor produces
    per_experiment: bool
    unit: str  # for the report


# The report's units. identify has no unit system of its own: [t] is the unit of Experiment.t,
# [τ] that of the torque model and the controls (so an inertia fixed by them is in [τ]·[t]²).
TIME_UNIT = "[t]"
RATE_UNIT = "rad/[t]"
INERTIA_UNIT = "[τ]·[t]²"
ARGS_UNIT = "(args')"  # the torque model's own units
UNIT_LEGEND = "units: [t] of Experiment.t, [τ] of the torque model and controls, (args') the torque model's"

SENSORS = {
    "gyro_bias": SensorKind((3,), 0.0, "omega_body", True, RATE_UNIT),
    "gyro_scale": SensorKind((3,), 1.0, "omega_body", False, "1"),
    "gyro_delay": SensorKind((), 0.0, "omega_body", False, TIME_UNIT),
    "tracker_mount": SensorKind((3,), 0.0, "q", False, "rad"),
    "tracker_delay": SensorKind((), 0.0, "q", False, TIME_UNIT),
}


class Sensor(NamedTuple):
    """One sensor parameter as `identify` uses it."""

    name: str
    fitted: bool
    value: np.ndarray  # held value, or the ideal start; (k, *shape) when per experiment

    @property
    def kind(self) -> SensorKind:
        return SENSORS[self.name]

    @property
    def size(self) -> int:
        """Entries in φ: per experiment for a per-experiment parameter, else in the shared head."""
        return int(np.prod(self.kind.shape, dtype=int)) if self.fitted else 0


def check_sensors(sensors, experiments) -> tuple:
    """`Sensor`s in the fixed order of `SENSORS` from ``identify``'s ``sensors`` dict (ValueError if bad)."""
    if sensors is None:
        return ()
    if not isinstance(sensors, dict):
        raise ValueError(f"`sensors` must be a dict naming sensor parameters; got {type(sensors).__name__}.")
    unknown = sorted(set(sensors) - set(SENSORS))
    if unknown:
        raise ValueError(
            f"`sensors` names {unknown}, which identify does not model; the sensor parameters are "
            f"{list(SENSORS)}."
        )
    k = len(experiments)
    checked = []
    for name, kind in SENSORS.items():
        if name not in sensors:
            continue
        if not any(e.counts[kind.observes] for e in experiments):
            raise ValueError(
                f"`sensors[{name!r}]` models the {kind.observes} sensor, but no experiment has "
                f"{kind.observes} data: drop it, or add that data."
            )
        shape = ((k,) if kind.per_experiment else ()) + kind.shape
        given = sensors[name]
        if given is True:
            if kind.per_experiment:
                blind = [i for i, e in enumerate(experiments) if not e.counts[kind.observes]]
                if blind:
                    raise ValueError(
                        f"`sensors[{name!r}]` is fitted per experiment, but experiment {blind[0]} has no "
                        f"{kind.observes} data to fit it from: hold it (an array of shape {shape})."
                    )
            checked.append(Sensor(name, True, np.full(shape, kind.ideal)))
            continue
        if given is False or given is None or isinstance(given, str):
            raise ValueError(
                f"`sensors[{name!r}]` must be True (fitted) or an array of shape {shape} (held); got "
                f"{given!r}. Leave the key out for an ideal sensor."
            )
        value = np.asarray(given, np.float64)
        if name == "gyro_scale" and value.shape == ():
            value = np.full(shape, value)  # one scale factor for the three axes
        if value.shape != shape or not np.all(np.isfinite(value)):
            what = "one row per experiment" if kind.per_experiment else "shared by the experiments"
            raise ValueError(
                f"`sensors[{name!r}]` must be True (fitted) or a finite array of shape {shape} ({what}); "
                f"got shape {value.shape}."
            )
        checked.append(Sensor(name, False, value))
    return tuple(checked)


def sensor_labels(sensor: Sensor, experiment=None) -> list:
    """Covariance labels of a fitted sensor parameter (of one experiment if per experiment)."""
    base = f"sensors.{sensor.name}"
    if sensor.kind.shape == ():
        return [base]
    prefix = "" if experiment is None else f"{experiment},"
    return [f"{base}[{prefix}{i}]" for i in range(sensor.kind.shape[0])]


def corrected_gyro(omega_body, sensors, experiment):
    """Gyro readings ``(n, 3)`` of one experiment with the held bias and scale taken out: the start's
    angular velocity. Fitted ones are at their ideal values there."""
    by_name = {s.name: s for s in sensors}
    out = np.asarray(omega_body, np.float64)
    if "gyro_bias" in by_name:
        out = out - by_name["gyro_bias"].value[experiment]
    if "gyro_scale" in by_name:
        out = out / by_name["gyro_scale"].value
    return out
