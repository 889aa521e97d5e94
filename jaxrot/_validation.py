"""Eager input checks of a run: a clear ``ValueError`` before anything compiles.

Shape checks always run (shapes are static, even under ``jit``). Value checks
(finite, unit norm, positive definite, …) run only on concrete arrays; on
tracers they are skipped, never wrong. They are not turned into ``eqx.error_if``
checks in the compiled program, on purpose: a check over every particle is a
global reduction, which a sharded rollout would have to communicate
(tests/test_sharding.py asserts that per-body torques communicate nothing), and
non-finite states inside ``jit`` are what ``rollout(..., runtime_check=True)``
reports, with the step they appeared at. Results that only exist at run time (a
failed reference solve) go through `jaxrot._core._checks.check_values`: one path that raises now
for concrete values and at run time for traced ones.

Here: the state, the bodies, the times and steps of a run, the torque. The generic value checks
(dtypes, `check_values`) are `jaxrot._core._checks`'; the inertia's, `jaxrot._inertia`'s.
`jaxrot.fit_inertia`'s checks (`check_observed`, `check_int`, `check_weight`,
`check_finite_array`) live here too; they reject traced inputs instead, as the fit
runs its optimiser eagerly.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np

from ._core._checks import QUATERNION_NORM_TOL, declared_dtype, float_dtype, is_concrete
from ._inertia import check_inertia
from ._state import RotState


def check_state(state, *, normalize=False, name="state") -> RotState:
    """Validate and convert a `RotState`; returns one with arrays of a common float dtype."""
    if not (isinstance(state, tuple) and len(state) == 2):
        raise ValueError(f"`{name}` must be jaxrot.RotState(q, omega); got {type(state).__name__}.")
    q_dtype = declared_dtype(state[0], f"{name}.q")
    omega_dtype = declared_dtype(state[1], f"{name}.omega")
    if q_dtype is not None and omega_dtype is not None and q_dtype != omega_dtype:
        raise ValueError(
            f"`{name}.q` ({q_dtype.name}) and `{name}.omega` ({omega_dtype.name}) must have the same dtype, "
            "float32 or float64 (the results keep it; the inertia is cast to it). Cast one of them, e.g. "
            f"{name}.omega.astype({name}.q.dtype)."
        )
    q, omega = (jnp.asarray(x) for x in state)
    if q.ndim < 1 or q.shape[-1] != 4:
        raise ValueError(f"`{name}.q` must have shape (..., 4) (scalar-first [w, x, y, z]); got {q.shape}.")
    if omega.ndim < 1 or omega.shape[-1] != 3:
        raise ValueError(f"`{name}.omega` must have shape (..., 3) (world frame); got {omega.shape}.")
    if q.shape[:-1] != omega.shape[:-1]:
        raise ValueError(
            f"`{name}.q` and `{name}.omega` must share their leading (particle) axes; "
            f"got {q.shape[:-1]} and {omega.shape[:-1]}."
        )
    declared = q_dtype if q_dtype is not None else omega_dtype
    dtype = declared if declared is not None else float_dtype(q, omega)
    q, omega = q.astype(dtype), omega.astype(dtype)
    if is_concrete(q, omega):
        for label, x in (("q", q), ("omega", omega)):
            if not np.all(np.isfinite(np.asarray(x))):
                raise ValueError(f"`{name}.{label}` contains NaN or infinite values.")
        norms = np.linalg.norm(np.asarray(q, dtype=np.float64), axis=-1)
        if np.any(norms == 0):
            raise ValueError(f"`{name}.q` contains a zero quaternion, which is not a rotation.")
        if not normalize:
            worst = float(np.max(np.abs(norms - 1))) if norms.size else 0.0
            if worst > QUATERNION_NORM_TOL:
                raise ValueError(
                    f"`{name}.q` must be unit quaternions (| |q| - 1 | <= {QUATERNION_NORM_TOL:g}); "
                    f"the worst is off by {worst:.3g}. Normalise it "
                    "(jaxrot.quaternion.normalize) or pass normalize=True."
                )
    if normalize:
        q = q / jnp.linalg.norm(q, axis=-1, keepdims=True)
    return RotState(q, omega)


def check_bodies(state, inertia, *, normalize=False):
    """`check_state` then `check_inertia` for its particle axes: ``(state, inertia, per_particle)``."""
    state = check_state(state, normalize=normalize)
    inertia, per_particle = check_inertia(inertia, state.q.shape[:-1], state.q.dtype)
    return state, inertia, per_particle


def check_times(ts, dtype, *, ordered, name="ts"):
    """A finite 1-D array of at least one time, cast to ``dtype``; non-decreasing if ``ordered``."""
    ts = jnp.asarray(ts)
    if ts.ndim != 1 or ts.shape[0] < 1:
        raise ValueError(f"`{name}` must be a 1-D array of at least one time; got shape {ts.shape}.")
    ts = ts.astype(dtype)
    if is_concrete(ts):
        ts_np = np.asarray(ts)
        if not np.all(np.isfinite(ts_np)):
            raise ValueError(f"`{name}` contains NaN or infinite values.")
        if ordered and np.any(np.diff(ts_np) < 0):
            raise ValueError(f"`{name}` must be non-decreasing (save times in order).")
    return ts


def check_dt(dt, name="dt"):
    dt_arr = jnp.asarray(dt)
    if dt_arr.ndim != 0:
        raise ValueError(f"`{name}` must be a scalar time step; got shape {dt_arr.shape}.")
    if is_concrete(dt_arr):
        value = float(dt_arr)
        if not np.isfinite(value) or value <= 0:
            raise ValueError(f"`{name}` must be a finite time step > 0; got {value}.")
    return dt_arr


def check_count(value, name, minimum):
    if (
        isinstance(value, jax.core.Tracer)
        or not isinstance(value, (int, np.integer))
        or isinstance(value, bool)
    ):
        raise ValueError(
            f"`{name}` must be a Python int (it fixes array shapes, so it cannot be traced); "
            f"got {type(value).__name__}."
        )
    if value < minimum:
        raise ValueError(f"`{name}` must be >= {minimum}; got {value}.")
    return int(value)


def _divisors(n: int) -> list[int]:
    small = [d for d in range(1, math.isqrt(n) + 1) if n % d == 0]
    return sorted({*small, *(n // d for d in small)})


def check_save_every(save_every, n_steps: int) -> int:
    """``save_every``, a Python int >= 1 that divides ``n_steps`` (so that the final state is saved).

    Otherwise the run would end on a step that is not saved: ``n_steps=10,
    save_every=3`` saved steps 0, 3, 6, 9 and silently dropped the final state.
    The message names the divisors of ``n_steps`` nearest ``save_every`` and the
    multiples of ``save_every`` nearest ``n_steps``.
    """
    save_every = check_count(save_every, "save_every", 1)
    if n_steps % save_every:
        divisors = _divisors(n_steps)
        near = [max(d for d in divisors if d < save_every)]
        near += [d for d in divisors if d > save_every][:1]
        below = n_steps // save_every * save_every
        steps = [m for m in (below, below + save_every) if m > 0]
        raise ValueError(
            f"`save_every` (= {save_every}) must divide `n_steps` (= {n_steps}), so that the last saved "
            f"state is the final one. Use save_every={' or '.join(map(str, near))} (the divisors of "
            f"{n_steps} nearest {save_every}), or n_steps={' or '.join(map(str, steps))}."
        )
    return save_every


def check_run_times(dt, n_steps, save_every, t0, dtype):
    """``(dt, n_steps, save_every, t0)`` of a rollout, checked: ``dt`` and ``t0`` cast to ``dtype``."""
    dt = check_dt(dt).astype(dtype)
    n_steps = check_count(n_steps, "n_steps", 0)
    save_every = check_save_every(save_every, n_steps)
    t0 = jnp.asarray(t0).astype(dtype)
    if t0.ndim != 0:
        raise ValueError(f"`t0` must be a scalar time; got shape {t0.shape}.")
    return dt, n_steps, save_every, t0


def check_torque(torque):
    if torque is not None and not callable(torque):
        raise ValueError(
            "`torque` must be None (torque-free) or a callable torque(t, q, omega, args) -> (3,) "
            f"world-frame torque; got {type(torque).__name__}."
        )


def check_observed(observed, normalize):
    """`jaxrot.fit_inertia`'s observations as ``(t, q, omega, dtype)``: float64 NumPy arrays, the fit's dtype.

    ``observed`` must be a concrete `Trajectory` of one body (the fit runs its
    optimiser eagerly): ``t`` ``(n,)`` finite and strictly increasing, ``n >= 3``;
    ``q`` ``(n, 4)`` finite unit quaternions (normalised with ``normalize``), made
    sign-continuous; ``omega`` ``(n, 3)`` finite, or None.
    """
    if not (isinstance(observed, tuple) and len(observed) == 3):
        raise ValueError(
            "`observed` must be a jaxrot.Trajectory(t, q, omega) with omega an (n, 3) array or None; "
            f"got {type(observed).__name__}."
        )
    t, q, omega = observed
    if not is_concrete(t, q, omega):
        raise ValueError(
            "`observed` must hold concrete arrays: fit_inertia runs its optimiser eagerly (not under jit)."
        )
    t, q = np.asarray(t), np.asarray(q)
    if t.ndim != 1 or t.shape[0] < 3:
        raise ValueError(f"`observed.t` must be a 1-D array of at least 3 times; got shape {t.shape}.")
    n = t.shape[0]
    if q.shape != (n, 4):
        raise ValueError(
            f"`observed.q` must have shape (n, 4) = ({n}, 4) for one body (scalar-first quaternions at "
            f"the times observed.t); got {q.shape}. Fit several bodies one at a time."
        )
    if omega is not None:
        omega = np.asarray(omega)
        if omega.shape != (n, 3):
            raise ValueError(
                f"`observed.omega` must be None or world-frame angular velocities of shape ({n}, 3); "
                f"got {omega.shape}."
            )
    for label, x in (("t", t), ("q", q), ("omega", omega)):
        if x is not None and not np.all(np.isfinite(x)):
            raise ValueError(
                f"`observed.{label}` contains NaN or infinite values; drop those samples (or pass "
                "omega=None when angular velocities were not measured)."
            )
    if np.any(np.diff(t) <= 0):
        raise ValueError("`observed.t` must be strictly increasing.")
    norms = np.linalg.norm(q, axis=-1)
    if np.any(norms == 0):
        raise ValueError("`observed.q` contains a zero quaternion, which is not a rotation.")
    worst = float(np.max(np.abs(norms - 1)))
    if not normalize and worst > QUATERNION_NORM_TOL:
        raise ValueError(
            f"`observed.q` must be unit quaternions (| |q| - 1 | <= {QUATERNION_NORM_TOL:g}); the worst is "
            f"off by {worst:.3g}. Normalise them or pass normalize=True."
        )
    dtype = jnp.result_type(*(x for x in (t, q, omega) if x is not None))
    if not jnp.issubdtype(dtype, jnp.floating):
        dtype = jnp.result_type(float)
    q = sign_continuous(q / norms[:, None])
    return (
        t.astype(np.float64),
        q.astype(np.float64),
        None if omega is None else omega.astype(np.float64),
        dtype,
    )


def sign_continuous(q) -> np.ndarray:
    """Quaternions ``(n, 4)`` with signs flipped so consecutive ones are on the same side (q ≡ −q)."""
    q = np.asarray(q, np.float64)
    dots = np.sum(q[1:] * q[:-1], axis=-1)
    return q * np.cumprod(np.concatenate([[1.0], np.where(dots < 0, -1.0, 1.0)]))[:, None]


def check_int(value, name, minimum=1):
    """An option that must be a Python int >= ``minimum`` (a bool is not one)."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise ValueError(f"`{name}` must be a Python int >= {minimum}; got {value!r}.")
    return int(value)


def check_weight(value, name):
    """An objective weight: a finite number >= 0."""
    if not (np.isfinite(value) and value >= 0):
        raise ValueError(f"`{name}` must be a finite number >= 0; got {value}.")


def check_finite_array(x, name, shape, what) -> np.ndarray:
    """``x`` as a float64 NumPy array, which must have ``shape`` and finite values (``what`` names it)."""
    x = np.asarray(x, dtype=np.float64)
    if x.shape != shape or not np.all(np.isfinite(x)):
        raise ValueError(f"`{name}` must be a finite {what}; got shape {x.shape}.")
    return x
