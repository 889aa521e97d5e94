r"""Where each scheme stops being trustworthy: measured limits at the numerical extremes.

Two measurements, both on a torque-free body, whose exact motion
(`jaxrot.analytic.free_top`, float64) is the yardstick:

- `rotation_ladder` / `max_stable_rotation_per_step`: the error per step as a
  function of the rotation per step ``|ω|Δt`` (radians). A torque-free body's
  motion depends on ``ω`` and ``Δt`` only through ``|ω|Δt`` (time rescaling), so
  the ladder runs every ``|ω|Δt`` at once, as particles spinning at
  ``|ω| = (|ω|Δt) / Δt`` with one fixed ``Δt`` (by default ``1e-3``: the ladder's top,
  10 rad per step, is a body at 10⁴ rad/s).
- `long_run_drift`: ``| |q| - 1 |``, relative energy and angular-momentum drift
  over a long run (10⁶ steps by default), in float64 or float32.

**Error per step.** From the initial state, ``n_steps`` steps (default 8) are
taken; with ``e_k`` the geodesic orientation error after ``k`` steps against the
exact motion (`jaxrot.quaternion.angle_between`), the error per step is
``max_k e_k / k``. It includes the orientation's local error and the effect of
the angular-velocity error on the next steps. A NaN or infinity counts as an
infinite error. A float32 run is compared with the exact motion of its own
(rounded) initial state, so only the integration is measured.

Measured limits (``tol = 1e-3`` rad per step, default body, float64 and float32 alike;
``benchmarks/stability.py`` prints the full table, ``tests/test_stability.py`` checks it):
``zhao`` 0.345, ``rozmanov`` 0.325, ``euler`` 0.0907, ``no_squish`` 0.242 (`LIMITS`); the
splittings are exact for a free body (their DMV rotor takes as many steps per flow as it needs:
the whole ladder to 10 passes, as with ``Splitting(rotor="exact")``). On a needle
of inertia ratio 1e6 the schemes that carry the angular momentum need far smaller steps
(``rozmanov`` 0.0027, ``no_squish`` 0.012; ``zhao`` 0.29, ``euler`` 0.071; ``splitting`` 0.033,
where the DMV rotor's modified moments lose their digits and it returns NaN). Above its limit
each scheme loses accuracy; ``zhao`` also blows up (an explicit update of ``ω`` with the
gyroscopic term ``ω × Iω``), to an infinity and then NaN within 8 steps, from 3.98 rad per
step in float64 and 3.16 in float32 (``euler`` in float32 from 7.9); ``rozmanov`` and
``no_squish`` and the splittings stay finite up to 10, every other scheme up to 3. An eager
`jaxrot.rollout` that returns a NaN raises `jaxrot.IntegrationError` quoting `LIMITS`; use
``rollout(..., runtime_check=True)`` to be told the step, also under ``jit``.

Example:
    >>> from jaxrot import stability
    >>> ladder = stability.rotation_ladder("zhao", [1e-6, 0.1, 1.0])
    >>> bool(ladder.error_per_step[0] < 1e-14), [f"{e:.1e}" for e in ladder.error_per_step[1:]]
    (True, ['2.6e-05', '2.2e-02'])
    >>> round(stability.max_stable_rotation_per_step("zhao", lo=0.1), 2)
    0.34
"""

import warnings
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from . import quaternion as quat
from ._core._limits import LIMITS
from ._integrate._rollout import rollout
from ._state import RotState
from .analytic import free_top
from .diagnostics import angular_momentum, kinetic_energy


__all__ = [
    "LIMITS",
    "DEFAULT_MOMENTS",
    "DEFAULT_OMEGA_BODY",
    "DEFAULT_Q0",
    "Drift",
    "LadderResult",
    "long_run_drift",
    "max_stable_rotation_per_step",
    "rotation_ladder",
]

# An asymmetric body tumbling away from its principal axes.
DEFAULT_MOMENTS = (1.0, 2.0, 3.0)
DEFAULT_OMEGA_BODY = (1.0, 2.0, 0.5)
DEFAULT_Q0 = (0.1, 0.2, 0.3)  # rotation vector of the initial orientation


class LadderResult(NamedTuple):
    """One entry per rotation per step.

    Attributes:
        rotation_per_step: ``|ω(0)| Δt`` (radians).
        error_per_step: ``max_k e_k / k`` (radians; ``inf`` where not finite).
        norm_error: largest ``| |q_k| - 1 |`` over the steps.
        finite: whether every ``q`` and ``omega`` stayed finite.
    """

    rotation_per_step: np.ndarray
    error_per_step: np.ndarray
    norm_error: np.ndarray
    finite: np.ndarray


class Drift(NamedTuple):
    """Drifts of a long torque-free run, over the saved states (every ``save_every`` steps).

    Attributes:
        norm: largest ``| |q| - 1 |``.
        energy: largest ``|E - E₀| / E₀``.
        momentum: largest ``|L - L₀| / |L₀|`` (world angular momentum).
        first_nonfinite_step: the first saved step with a NaN or infinity, or None.
        n_steps: steps taken.
        dt: the time step.
    """

    norm: float
    energy: float
    momentum: float
    first_nonfinite_step: int | None
    n_steps: int
    dt: float


def _initial(omega_body, q0, scale, dtype):
    """States ``(P, ...)`` with body-frame angular velocity along ``omega_body``, of world norm ``scale``."""
    q0 = quat.exp(jnp.asarray(q0, jnp.float64))
    direction = quat.rotate(q0, jnp.asarray(omega_body, jnp.float64))
    direction = direction / jnp.linalg.norm(direction)
    scale = jnp.asarray(scale, jnp.float64)
    omega = scale[:, None] * direction[None]
    q = jnp.broadcast_to(q0, omega.shape[:-1] + (4,))
    return RotState(q.astype(dtype), omega.astype(dtype))


def _run_quietly(scheme, *args, **kwargs):
    # Rozmanov warns when its half-step iteration hits the cap at large steps; the measured
    # error already shows what that costs.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return rollout(scheme, *args, check_finite=False, **kwargs)


def rotation_ladder(
    scheme,
    rotation_per_step,
    *,
    inertia=DEFAULT_MOMENTS,
    omega_body=DEFAULT_OMEGA_BODY,
    q0=DEFAULT_Q0,
    dtype=jnp.float64,
    n_steps: int = 8,
    dt: float = 1e-3,
) -> LadderResult:
    """Error per step of a torque-free body at each rotation per step ``|ω|Δt``.

    Args:
        scheme: a name in `jaxrot.SCHEMES` or a scheme object.
        rotation_per_step: the ``|ω(0)| Δt`` values (radians), any 1-D sequence.
        inertia: body-frame inertia, ``(3,)`` principal moments or ``(3, 3)``.
        omega_body: direction of the initial angular velocity in the body frame.
        q0: rotation vector of the initial orientation.
        dtype: ``jnp.float64`` or ``jnp.float32`` (the reference is float64).
        n_steps: steps per measurement.
        dt: the fixed time step; ``|ω| = rotation_per_step / dt``.

    Returns:
        `LadderResult` of numpy arrays, in the order of ``rotation_per_step``.
    """
    x = np.asarray(rotation_per_step, dtype=np.float64).reshape(-1)
    if x.size == 0 or not np.all(np.isfinite(x)) or np.any(x < 0):
        raise ValueError("`rotation_per_step` must be a non-empty 1-D sequence of finite values >= 0.")
    inertia = jnp.asarray(inertia, jnp.float64)
    state = _initial(omega_body, q0, x / dt, dtype)
    traj = _run_quietly(scheme, state, inertia.astype(dtype), dt, n_steps)
    q = np.asarray(traj.q, dtype=np.float64)
    omega = np.asarray(traj.omega, dtype=np.float64)
    finite = np.all(np.isfinite(q), axis=(0, 2)) & np.all(np.isfinite(omega), axis=(0, 2))
    exact = free_top(
        RotState(jnp.asarray(q[0]), jnp.asarray(omega[0])),
        inertia,
        jnp.asarray(traj.t, jnp.float64),
        normalize=dtype != jnp.float64,
    )
    angle = np.asarray(quat.angle_between(jnp.asarray(np.nan_to_num(q[1:])), exact.q[1:]))
    error = np.max(angle / np.arange(1, n_steps + 1)[:, None], axis=0)
    error = np.where(finite, error, np.inf)
    with np.errstate(invalid="ignore"):
        norm_error = np.max(np.abs(np.linalg.norm(q, axis=-1) - 1), axis=0)
    return LadderResult(x, error, np.where(finite, norm_error, np.inf), finite)


def max_stable_rotation_per_step(
    scheme,
    *,
    tol: float = 1e-3,
    lo: float = 1e-12,
    hi: float = 10.0,
    points_per_decade: int = 10,
    **ladder_kwargs,
) -> float:
    """The largest ``|ω|Δt`` in ``[lo, hi]`` up to which the error per step stays below ``tol``.

    A log-spaced ladder (``points_per_decade``) locates the first ``|ω|Δt`` whose
    error per step exceeds ``tol`` (or is not finite); a second ladder of the
    same size between it and the last one below ``tol`` refines the limit to
    0.2% (at the default 10 points per decade). Every smaller ``|ω|Δt`` of the
    ladder passes.

    Args:
        scheme: a name in `jaxrot.SCHEMES` or a scheme object.
        tol: largest acceptable error per step (radians).
        lo, hi: the range searched (radians per step).
        points_per_decade: resolution of the first ladder.
        **ladder_kwargs: passed to `rotation_ladder` (``inertia``, ``dtype``, …).

    Returns:
        The limit, as a float: ``hi`` when the whole range passes, 0.0 when even
        ``lo`` fails.
    """
    n = int(round(np.log10(hi / lo) * points_per_decade)) + 1
    ladder = np.logspace(np.log10(lo), np.log10(hi), n)
    ok = _passes(rotation_ladder(scheme, ladder, **ladder_kwargs), tol)
    if ok.all():
        return float(hi)
    first_bad = int(np.argmin(ok))
    if first_bad == 0:
        return 0.0
    fine = np.logspace(np.log10(ladder[first_bad - 1]), np.log10(ladder[first_bad]), n)
    ok_fine = _passes(rotation_ladder(scheme, fine, **ladder_kwargs), tol)
    return float(fine[int(np.argmin(ok_fine)) - 1])


def _passes(result: LadderResult, tol):
    return result.finite & (result.error_per_step <= tol)


def long_run_drift(
    scheme,
    n_steps: int = 1_000_000,
    *,
    dt: float = 0.01,
    dtype=jnp.float64,
    save_every: int = 1000,
    inertia=DEFAULT_MOMENTS,
    omega_body=DEFAULT_OMEGA_BODY,
    q0=DEFAULT_Q0,
    runtime_check: bool = False,
) -> Drift:
    """Norm, energy and angular-momentum drift of a long torque-free run.

    The default body (moments ``(1, 2, 3)``, ``|ω| = 2.29``) at ``dt = 0.01`` turns
    0.023 rad per step; 10⁶ steps are t = 10⁴. The invariants are computed in
    float64 from the saved states.

    Args:
        scheme: a name in `jaxrot.SCHEMES` or a scheme object.
        n_steps: steps to take.
        dt: the time step.
        dtype: ``jnp.float64`` or ``jnp.float32``.
        save_every: the drifts are measured every ``save_every`` steps.
        inertia: body-frame principal moments ``(3,)``.
        omega_body: initial body-frame angular velocity (rad per unit time).
        q0: rotation vector of the initial orientation.
        runtime_check: passed to `jaxrot.rollout`: check every step, not only the saved ones,
            and raise `jaxrot.IntegrationError` at the first NaN or non-unit ``q``.

    Returns:
        `Drift` (floats; ``inf`` once the run is not finite).

    Example:
        >>> from jaxrot import stability
        >>> drift = stability.long_run_drift("no_squish", 10_000, save_every=100)
        >>> drift.norm < 1e-15, drift.energy < 1e-4, drift.momentum < 1e-13
        (True, True, True)
    """
    inertia = jnp.asarray(inertia, jnp.float64)
    omega_body = jnp.asarray(omega_body, jnp.float64)
    state = _initial(omega_body, q0, jnp.linalg.norm(omega_body)[None], dtype)
    state = RotState(state.q[0], state.omega[0])
    traj = _run_quietly(
        scheme, state, inertia.astype(dtype), dt, n_steps, save_every=save_every, runtime_check=runtime_check
    )
    q = np.asarray(traj.q, dtype=np.float64)
    omega = np.asarray(traj.omega, dtype=np.float64)
    finite = np.all(np.isfinite(q), axis=-1) & np.all(np.isfinite(omega), axis=-1)
    first_bad = None if finite.all() else int(np.argmin(finite)) * save_every
    if first_bad is not None:
        return Drift(np.inf, np.inf, np.inf, first_bad, n_steps, dt)
    energy = np.asarray(kinetic_energy(q, omega, np.asarray(inertia)))
    momentum = np.asarray(angular_momentum(q, omega, np.asarray(inertia)))
    return Drift(
        float(np.max(np.abs(np.linalg.norm(q, axis=-1) - 1))),
        float(np.max(np.abs(energy - energy[0])) / energy[0]),
        float(np.max(np.linalg.norm(momentum - momentum[0], axis=-1)) / np.linalg.norm(momentum[0])),
        None,
        n_steps,
        dt,
    )
