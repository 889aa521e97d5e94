"""`Experiment`: one manoeuvre's telemetry, checked when it is made."""

import jax
import numpy as np

from ..._core._checks import QUATERNION_NORM_TOL, is_concrete


# The observation kinds: (attribute, its noise attribute, residual components, informative ones).
KINDS = (("q", "sigma_q", 3, 3), ("omega_body", "sigma_omega", 3, 3), ("direction", "sigma_direction", 3, 2))
# How a sampled control torque acts: the frame of its samples, and how it runs between them.
CONTROL_FRAMES = ("world", "body")
CONTROL_HOLDS = ("linear", "previous")


def _array(x, name, shape_text, width):
    if not is_concrete(x):
        raise ValueError(f"`{name}` must be a concrete array: identify runs eagerly (not under jit).")
    x = np.asarray(x)
    if not np.issubdtype(x.dtype, np.number) or np.iscomplexobj(x):
        raise ValueError(f"`{name}` must be a real array {shape_text}; got dtype {x.dtype}.")
    if width is None:
        if x.ndim != 1:
            raise ValueError(f"`{name}` must be a 1-D array {shape_text}; got shape {x.shape}.")
    elif x.ndim != 2 or x.shape[1] != width:
        raise ValueError(f"`{name}` must be an array {shape_text}; got shape {x.shape}.")
    return x


def _sigma(value, name):
    if value is None:
        return None
    value = float(value)
    if not (np.isfinite(value) and value > 0):
        raise ValueError(
            f"`{name}` must be a noise standard deviation > 0 (or None: estimated from the residuals); "
            f"got {value}."
        )
    return value


def _times(t, name):
    if not np.all(np.isfinite(t)):
        raise ValueError(f"`{name}` contains NaN or infinite values.")
    steps = np.diff(t)
    if np.any(steps <= 0):
        k = int(np.argmax(steps <= 0))
        what = "duplicate" if steps[k] == 0 else "unsorted"
        raise ValueError(
            f"`{name}` must be strictly increasing; {name}[{k}] = {t[k]} and {name}[{k + 1}] = {t[k + 1]} "
            f"are {what}. Sort the samples (and merge duplicates)."
        )


def _known_args(args):
    """``args`` as a dict of concrete float arrays (checked against identify's ``args`` there)."""
    if args is None:
        return {}
    if not isinstance(args, dict) or not all(isinstance(key, str) for key in args):
        raise ValueError(
            "`args` must be a dict naming some keys of identify's `args` with this experiment's known "
            f"values; got {type(args).__name__}."
        )
    known = {}
    for key, value in args.items():
        leaves = jax.tree_util.tree_leaves(value)
        if not all(is_concrete(leaf) for leaf in leaves):
            raise ValueError(f"`args[{key!r}]` must be concrete: identify runs eagerly (not under jit).")
        value = jax.tree_util.tree_map(np.asarray, value)
        if not all(np.all(np.isfinite(leaf)) for leaf in jax.tree_util.tree_leaves(value)):
            raise ValueError(f"`args[{key!r}]` must be finite.")
        known[key] = value
    return known


class Experiment:
    """One manoeuvre's data for `jaxrot.identify`: sample times, observations, noise, known torque.

    Every observation array has one row per sample time; a NaN anywhere in a row
    skips that sample of that kind (a dropout), so each kind may cover a
    different subset of the times.

    Args:
        t: sample times ``(n,)``, strictly increasing (any spacing), ``n ≥ 2``.
        q: observed orientations ``(n, 4)`` (scalar first, body → world; unit,
            either sign), e.g. from a star tracker.
        omega_body: gyro readings ``(n, 3)``: the angular velocity in the
            **body** frame (rad/time).
        direction: observed world-frame unit vectors ``(n, 3)`` of the body-fixed
            unit vector ``body_vector`` ``(3,)`` (one tracked axis, a magnetometer);
            the rotation about that axis is left to the dynamics.
        sigma_q, sigma_omega, sigma_direction: noise standard deviation of each
            kind (rad per axis; rad/time per component; rad per perpendicular
            axis). None: estimated from the residuals of that kind.
        control: ``(t_c, tau_c)``, a known torque sampled at increasing ``t_c``
            ``(m,)``, ``tau_c`` ``(m, 3)``, added to the torque model.
        control_frame: ``"world"`` (default): ``tau_c`` is a world-frame torque;
            ``"body"``: a body-frame one (a body-fixed actuator: reaction wheel,
            magnetorquer, thruster), turned with the body.
        control_hold: ``"linear"`` (default): interpolated linearly between the
            samples and held at the end values outside ``t_c``; ``"previous"``: each
            sample holds from its time until the next (a zero-order hold, as flight
            software and MuJoCo apply commands), no torque before ``t_c[0]``. Either
            way the model's steps land on the control times, so a held torque's
            jumps fall between steps and every stage of a step sees the sample held
            over that step.
        args: this experiment's known values of some of `jaxrot.identify`'s ``args``:
            a dict naming a subset of its keys (a payload moved, a thruster used in
            this run only); the others take ``identify``'s values. Checked against
            ``args`` when ``identify`` runs.

    Raises:
        ValueError: an array whose length disagrees with ``t``, unsorted or
            duplicate times, a σ ≤ 0, non-unit quaternions, ``direction`` without
            ``body_vector``, no observation at all, an unknown ``control_frame`` or
            ``control_hold``, or ``args`` that is not a dict of finite arrays.

    Example:
        >>> import numpy as np, jaxrot
        >>> t = np.linspace(0.0, 1.0, 11)
        >>> gyro = np.tile([0.1, 0.0, 1.0], (11, 1))
        >>> jaxrot.Experiment(t, omega_body=gyro, sigma_omega=1e-3)
        Experiment(n=11, omega_body: 11 samples (sigma 0.001))
    """

    def __init__(
        self,
        t,
        *,
        q=None,
        omega_body=None,
        direction=None,
        body_vector=None,
        sigma_q=None,
        sigma_omega=None,
        sigma_direction=None,
        control=None,
        control_frame="world",
        control_hold="linear",
        args=None,
    ):
        t = _array(t, "t", "of sample times (n,)", None)
        _times(t, "t")
        n = t.shape[0]
        if n < 2:
            raise ValueError(f"`t` must hold at least 2 sample times; got {n}.")
        arrays = {}
        for name, value, width in (("q", q, 4), ("omega_body", omega_body, 3), ("direction", direction, 3)):
            if value is None:
                arrays[name] = None
                continue
            value = _array(value, name, f"({n}, {width}), one row per sample time in t", width)
            if value.shape[0] != n:
                raise ValueError(
                    f"`{name}` has {value.shape[0]} rows but `t` has {n} sample times: one row per time "
                    "(NaN rows for missing samples)."
                )
            if np.any(np.isinf(value)):
                raise ValueError(f"`{name}` contains infinite values; mark missing samples with NaN.")
            arrays[name] = value
        if body_vector is not None:
            body_vector = np.asarray(body_vector)
            if body_vector.shape != (3,) or not np.all(np.isfinite(body_vector)):
                raise ValueError(
                    f"`body_vector` must be a finite (3,) vector; got shape {body_vector.shape}."
                )
            if abs(float(np.linalg.norm(body_vector)) - 1) > QUATERNION_NORM_TOL:
                raise ValueError("`body_vector` must be a unit vector (normalise it).")
        if (arrays["direction"] is None) != (body_vector is None):
            raise ValueError(
                "`direction` and `body_vector` go together: the observed world directions (n, 3) of the "
                "body-fixed unit vector body_vector (3,)."
            )
        for name in ("q", "direction"):
            x = arrays[name]
            if x is None:
                continue
            rows = np.all(np.isfinite(x), axis=-1)
            worst = float(np.max(np.abs(np.linalg.norm(x[rows], axis=-1) - 1), initial=0.0))
            if worst > QUATERNION_NORM_TOL:
                raise ValueError(
                    f"`{name}` must hold unit {'quaternions' if name == 'q' else 'vectors'} "
                    f"(| |x| - 1 | <= {QUATERNION_NORM_TOL:g}); the worst is off by {worst:.3g}. "
                    "Normalise them."
                )
        counts = {
            name: 0 if x is None else int(np.sum(np.all(np.isfinite(x), axis=-1)))
            for name, x in arrays.items()
        }
        if sum(counts.values()) == 0:
            raise ValueError(
                "The experiment has no observation: give at least one of q, omega_body or direction "
                "(with body_vector), with at least one sample that is not NaN."
            )
        if control is not None:
            if not (isinstance(control, tuple | list) and len(control) == 2):
                raise ValueError("`control` must be a pair (t_c (m,), tau_c (m, 3)) or None.")
            t_c = _array(control[0], "control[0]", "of control times (m,)", None)
            _times(t_c, "control[0]")
            frame = "body-frame" if control_frame == "body" else "world-frame"  # the samples' frame
            tau_c = _array(control[1], "control[1]", f"({t_c.shape[0]}, 3) of {frame} torques", 3)
            if tau_c.shape[0] != t_c.shape[0] or not np.all(np.isfinite(tau_c)):
                raise ValueError(
                    f"`control[1]` must be finite {frame} torques ({t_c.shape[0]}, 3), one row per "
                    f"control time (control_frame={control_frame!r}); got shape {tau_c.shape}."
                )
            control = (t_c, tau_c)
        if control_frame not in CONTROL_FRAMES:
            raise ValueError(
                f"`control_frame` must be 'world' (world-frame torque samples) or 'body' (a body-fixed "
                f"actuator's); got {control_frame!r}."
            )
        if control_hold not in CONTROL_HOLDS:
            raise ValueError(
                f"`control_hold` must be 'linear' (interpolated) or 'previous' (each sample held until the "
                f"next, a zero-order hold); got {control_hold!r}."
            )
        self.t = t
        self.q = arrays["q"]
        self.omega_body = arrays["omega_body"]
        self.direction = arrays["direction"]
        self.body_vector = body_vector
        self.sigma_q = _sigma(sigma_q, "sigma_q")
        self.sigma_omega = _sigma(sigma_omega, "sigma_omega")
        self.sigma_direction = _sigma(sigma_direction, "sigma_direction")
        self.control = control
        self.control_frame = control_frame
        self.control_hold = control_hold
        self.args = _known_args(args)
        self.counts = counts

    def __repr__(self):
        parts = [f"n={self.t.shape[0]}"]
        for name, sigma_name, _, _ in KINDS:
            if self.counts[name]:
                sigma = getattr(self, sigma_name)
                noise = "estimated" if sigma is None else f"{sigma:g}"
                parts.append(f"{name}: {self.counts[name]} samples (sigma {noise})")
        if self.control is not None:
            parts.append(
                f"control: {self.control[0].shape[0]} samples ({self.control_frame} frame, "
                f"{self.control_hold})"
            )
        if self.args:
            parts.append(f"args: {sorted(self.args)}")
        return f"Experiment({', '.join(parts)})"
