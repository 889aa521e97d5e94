"""`identify`'s second stage: where the fit starts, and the model's largest step.

The tensor comes from the linear angular-momentum balance (`_initial.linear_estimate`)
of the experiment with the most orientation samples, each experiment's initial state
from its first samples (or, for that experiment, from the balance's momentum), and the
step from the largest angular velocity seen. Observations enter with the held sensor
parameters taken out; fitted ones start ideal.
"""

from typing import NamedTuple

import jax
import numpy as np

from ... import quaternion as quat
from ..._validation import sign_continuous
from .._initial import estimate_omega, linear_estimate, multiply_np, rotate_np
from ._controls import step_grid
from ._sensors import corrected_gyro


# The default step: see `identify`'s docstring for the measurements behind it.
DEFAULT_STEP_ANGLE = 0.6  # rad turned per step at the largest |ω| seen


class Start(NamedTuple):
    """The starting point of the fit."""

    inertia: np.ndarray  # (3, 3): the estimate, or inertia0
    trace0: float  # the trace a scale-free tensor keeps
    q: np.ndarray  # (k, 4) each experiment's initial orientation
    omega: np.ndarray  # (k, 3) and world angular velocity
    max_step: float  # the model's largest step
    speed: float  # the largest |ω| of the starts (for the round-off floor)


def experiment_args(settings, j):
    """The user's ``args`` as experiment ``j`` sees them (its own values of per-experiment leaves)."""
    values = [
        leaf.value if leaf.per_experiment is None else leaf.per_experiment[j] for leaf in settings.leaves
    ]
    return jax.tree_util.tree_unflatten(settings.treedef, values)


def finite_rows(x):
    """Indices of the rows of ``x`` with no NaN (none for an absent kind)."""
    return np.zeros(0, int) if x is None else np.flatnonzero(np.all(np.isfinite(x), axis=-1))


def body_orientations(settings, j):
    """Experiment ``j``'s tracker readings as body orientations: a held mounting rotation taken out."""
    q = settings.experiments[j].q
    mount = [s for s in settings.sensors if s.name == "tracker_mount" and not s.fitted]
    if q is None or not mount:
        return q
    undo = np.asarray(quat.exp(-mount[0].value))
    return multiply_np(np.nan_to_num(q), np.broadcast_to(undo, q.shape)) + 0 * q  # NaN rows stay NaN


def gyro_rates(settings, j):
    """Experiment ``j``'s gyro readings as body angular velocities (held bias and scale taken out)."""
    omega = settings.experiments[j].omega_body
    return None if omega is None else corrected_gyro(omega, settings.sensors, j)


def _rotation_between(a, b):
    """A unit quaternion turning unit vector ``a`` onto ``b`` (the shortest arc)."""
    c = float(np.dot(a, b))
    if c < -1 + 1e-12:
        axis = np.cross(a, [1.0, 0, 0])
        axis = axis if np.linalg.norm(axis) > 1e-6 else np.cross(a, [0, 1.0, 0])
        return np.array([0.0, *(axis / np.linalg.norm(axis))])
    q = np.array([1 + c, *np.cross(a, b)])
    return q / np.linalg.norm(q)


def _first_orientation(settings, j):
    e, q = settings.experiments[j], body_orientations(settings, j)
    rows = finite_rows(q)
    if rows.size:
        return np.asarray(q[rows[0]], np.float64)
    rows = finite_rows(e.direction)
    if rows.size:
        return _rotation_between(e.body_vector.astype(np.float64), e.direction[rows[0]].astype(np.float64))
    return np.array([1.0, 0, 0, 0])


def _first_omega(settings, j, q_start):
    e, gyro, q = settings.experiments[j], gyro_rates(settings, j), body_orientations(settings, j)
    rows = finite_rows(gyro)
    if rows.size:
        return rotate_np(q_start, gyro[rows[0]])
    rows = finite_rows(q)
    if rows.size >= 3:
        return estimate_omega(e.t[rows[:3]], sign_continuous(q[rows[:3]]))[0]
    return np.zeros(3)


def control_impulse(t, q, control, hold, frame):
    """World angular impulse of a control from ``t[0]`` to each sample time ``(n, 3)``: exact for a world
    frame control; a body-frame one is turned by the orientation ``q`` at the sample before each step."""
    n = t.shape[0]
    if control is None:
        return np.zeros((n, 3))
    grid = step_grid(t, control, hold, np.inf)
    per_step = grid.value * grid.length[:, None] + 0.5 * grid.slope * grid.length[:, None] ** 2
    if frame == "body":
        before = np.clip(np.searchsorted(t, grid.start, side="right") - 1, 0, n - 1)
        per_step = rotate_np(q[before], per_step)
    total = np.concatenate([np.zeros((1, 3)), np.cumsum(per_step, axis=0)])
    return total[grid.sample_node]


def starting_point(settings) -> "Start":
    """The `Start` of the fit (see the module's docstring)."""
    k, experiments = settings.k, settings.experiments
    q_starts = np.stack([_first_orientation(settings, j) for j in range(k)])
    omega_starts = np.stack([_first_omega(settings, j, q_starts[j]) for j in range(k)])
    if settings.inertia0 is None:
        best = max(range(k), key=lambda j: finite_rows(experiments[j].q).size)
        inertia, momentum = _inertia_estimate(settings, best)
        trace0 = 1.0
        if (
            finite_rows(experiments[best].q)[0] == 0
            and momentum is not None
            and np.all(np.isfinite(momentum))
        ):
            # ω₀ = R₀ I⁻¹ R₀ᵀ L₀ from the momentum fitted to all samples of that record (not differences).
            q_first = q_starts[best]
            body = np.linalg.solve(inertia, rotate_np(q_first * np.array([1.0, -1, -1, -1]), momentum))
            candidate = rotate_np(q_first, body)
            if np.all(np.isfinite(candidate)):
                omega_starts[best] = candidate
    else:
        inertia, trace0 = settings.inertia0, float(np.trace(settings.inertia0))
    if settings.q0 is not None:
        q_starts = settings.q0
    if settings.omega0 is not None:
        omega_starts = settings.omega0
    speed = float(np.max(np.linalg.norm(omega_starts, axis=-1), initial=0.0))
    max_step = settings.dt if settings.dt is not None else _default_step(settings, speed)
    return Start(inertia, trace0, q_starts, omega_starts, max_step, speed)


def _inertia_estimate(settings, j):
    """The linear estimate ``(tensor (3, 3), world momentum (3,) or None)`` from experiment ``j``; a
    scale-free (torque-free) estimate has unit trace."""
    e = settings.experiments[j]
    q_body = body_orientations(settings, j)
    gyro = gyro_rates(settings, j)
    rows = finite_rows(q_body)
    q_rows = sign_continuous(q_body[rows])
    if gyro is not None and finite_rows(gyro).size == e.t.shape[0] and rows.size == e.t.shape[0]:
        omega_world = rotate_np(q_rows, gyro)
    else:
        omega_world = estimate_omega(e.t[rows], q_rows)
    t_rows = e.t[rows].astype(np.float64)
    impulse = None
    if e.control is not None:
        impulse = control_impulse(t_rows, q_rows, e.control, e.control_hold, e.control_frame)
    torque = settings.torque
    if torque is None and impulse is None:
        estimate, momentum = linear_estimate(t_rows, q_rows, omega_world, None, None, settings.dtype)
    else:
        estimate, momentum = linear_estimate(
            t_rows, q_rows, omega_world, torque, experiment_args(settings, j), settings.dtype,
            extra_impulse=impulse,
        )  # fmt: skip
    return 0.5 * (estimate + estimate.T), momentum


def _default_step(settings, speed):
    """``DEFAULT_STEP_ANGLE`` over the largest ``|ω|`` of the starts, gyros and differenced orientations;
    the largest sample spacing for a body at rest."""
    speeds = [speed]
    for j, e in enumerate(settings.experiments):
        gyro = gyro_rates(settings, j)
        rows = finite_rows(gyro)
        if rows.size:
            speeds.append(np.linalg.norm(gyro[rows], axis=-1).max())
        q_body = body_orientations(settings, j)
        rows = finite_rows(q_body)
        if rows.size >= 3:
            speeds.append(
                np.linalg.norm(estimate_omega(e.t[rows], sign_continuous(q_body[rows])), axis=-1).max()
            )
    w_max = float(max(speeds))
    spacing = max(float(np.max(np.diff(e.t))) for e in settings.experiments)
    return DEFAULT_STEP_ANGLE / w_max if w_max > 0 else spacing
