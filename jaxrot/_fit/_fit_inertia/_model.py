"""`fit_inertia`'s set-up: the checked observations (`Settings`), and the `Model` the residuals roll out.

The `Model` holds the observations cut into padded `Segments` and the static configuration
of the rollout (scheme, torque, steps, checkpointing, weights).
"""

import math
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..._integrate._bind import INERTIAL, scheme_for_call
from ..._validation import check_int, check_observed, check_torque
from .._initial import estimate_omega


# The default time step turns the body by at most this angle (radians) per step.
DEFAULT_STEP_ANGLE = 0.01


class Segments(NamedTuple):
    """Observations cut into ``K`` segments, each padded to ``P`` intervals (+ chunk padding)."""

    t: jax.Array  # (K, P + 1)      padded by repeating the last time: dt = 0 steps are no-ops
    q: jax.Array  # (K, P + 1, 4)
    omega: jax.Array | None  # (K, P + 1, 3)
    weight: jax.Array  # (K, P + 1)  1 for an observation counted here, 0 otherwise
    q_start: jax.Array  # (K, 4) observed orientation at each segment start


class Model(eqx.Module):
    """What the residuals need: the segmented data and the static configuration of the rollout."""

    data: Segments
    args: object
    scheme: object = eqx.field(static=True)
    torque: object = eqx.field(static=True)
    substeps: int = eqx.field(static=True)
    n_outer: int = eqx.field(static=True)
    n_inner: int = eqx.field(static=True)
    checkpoint: bool = eqx.field(static=True)
    unit_trace: bool = eqx.field(static=True)
    omega_weight: float = eqx.field(static=True)
    continuity_weight: float = eqx.field(static=True)
    spacing: float = eqx.field(static=True)  # mean observation interval: scales ω mismatches to rad


class Settings(NamedTuple):
    """The checked observations (float64 NumPy arrays) and what the set-up derived from them: what the start
    and the result read."""

    t: np.ndarray  # (n,)
    q: np.ndarray  # (n, 4) unit, sign-continuous
    omega: np.ndarray | None  # (n, 3) world frame, if observed
    omega_estimate: np.ndarray  # (n, 3) the observed omega, or estimated from q (`estimate_omega`)
    bounds: np.ndarray  # (K + 1,) observation index of each segment's start, and of the last one
    dtype: np.dtype  # the float dtype the fit runs in


def build_model(
    observed,
    *,
    torque,
    args,
    segments,
    unit_trace,
    scheme="zhao",
    dt=None,
    substeps=None,
    checkpoint=True,
    checkpoint_every=None,
    omega_weight=1.0,
    continuity_weight=100.0,
    omega_estimate=None,
    normalize=False,
):
    """The `Model` (validated, padded data and the static configuration) and the `Settings`."""
    scheme, _ = scheme_for_call(scheme, INERTIAL)  # a body in vacuum: the model fit_inertia fits
    check_torque(torque)
    t, q, omega, dtype = check_observed(observed, normalize)
    n = t.shape[0]
    segments = check_int(segments, "segments")
    if segments > n - 1:
        raise ValueError(
            f"`segments` must be <= the number of observation intervals ({n - 1}); got {segments}."
        )
    if omega_estimate is None:
        omega_estimate = omega if omega is not None else estimate_omega(t, q)
    spacing = float(np.max(np.diff(t)))
    if substeps is not None:
        if dt is not None:
            raise ValueError("Pass `dt` or `substeps`, not both.")
        substeps = check_int(substeps, "substeps")
    else:
        if dt is None:
            w_max = float(np.max(np.linalg.norm(omega_estimate, axis=-1)))
            dt = DEFAULT_STEP_ANGLE / w_max if w_max > 0 else spacing
        dt = float(dt)
        if not np.isfinite(dt) or dt <= 0:
            raise ValueError(f"`dt` must be a finite time step > 0; got {dt}.")
        substeps = max(1, math.ceil(spacing / dt * (1 - 1e-12)))

    bounds = np.round(np.linspace(0, n - 1, segments + 1)).astype(int)
    n_intervals = int(np.max(np.diff(bounds)))
    n_steps = n_intervals * substeps
    if checkpoint:
        n_inner = (
            check_int(checkpoint_every, "checkpoint_every")
            if checkpoint_every is not None
            else max(1, math.ceil(math.sqrt(n_steps)))
        )
        n_outer = math.ceil(n_steps / n_inner)
    else:
        n_inner, n_outer = 1, n_steps
    length = math.ceil(n_outer * n_inner / substeps) + 1  # padded observation slots per segment

    ts, qs, ws, weights = [], [], [], []
    for s in range(segments):
        lo, hi = bounds[s], bounds[s + 1]
        idx = np.minimum(np.arange(lo, lo + length), hi)
        weight = (np.arange(lo, lo + length) <= hi).astype(np.float64)
        if s < segments - 1:
            weight[hi - lo] = 0.0  # the boundary sample is counted by the next segment
        ts.append(t[idx])
        qs.append(q[idx])
        weights.append(weight)
        if omega is not None:
            ws.append(omega[idx])
    data = Segments(
        t=jnp.asarray(np.stack(ts), dtype),
        q=jnp.asarray(np.stack(qs), dtype),
        omega=None if omega is None else jnp.asarray(np.stack(ws), dtype),
        weight=jnp.asarray(np.stack(weights), dtype),
        q_start=jnp.asarray(q[bounds[:-1]], dtype),
    )
    model = Model(
        data=data,
        args=args,
        scheme=scheme,
        torque=torque,
        substeps=substeps,
        n_outer=n_outer,
        n_inner=n_inner,
        checkpoint=bool(checkpoint),
        unit_trace=unit_trace,
        omega_weight=float(omega_weight),
        continuity_weight=float(continuity_weight),
        spacing=float((t[-1] - t[0]) / (n - 1)),
    )
    return model, Settings(t, q, omega, omega_estimate, bounds, dtype)
