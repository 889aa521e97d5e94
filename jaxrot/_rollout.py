"""`rollout`: one `lax.scan` over time, `vmap` over particles."""

import warnings

import equinox as eqx
import jax
import jax.numpy as jnp

from ._drive import check_drive, driven_step, driven_torque
from ._inertia import body_inertia
from ._particles import PARTICLES, flatten_particles, split_per_body, unflatten_trajectory
from ._runtime_check import check_in_graph, init_report, raise_if_bad, update_report
from ._state import RotState, Trajectory
from ._validation import check_bodies, check_count, check_dt, check_torque, is_concrete
from .schemes import resolve_scheme


def rollout(
    scheme,
    state: RotState,
    inertia,
    dt,
    n_steps: int,
    *,
    torque=None,
    args=None,
    save_every: int = 1,
    t0=0.0,
    drive=None,
    normalize: bool = False,
    return_carry: bool = False,
    runtime_check: bool = False,
):
    """Integrate rigid-body rotation with a fixed step and return the saved states.

    Args:
        scheme: a name in `jaxrot.SCHEMES` (``"zhao"``, …) or a scheme object.
        state: `RotState` with ``q`` ``(..., 4)`` (unit, scalar first, body →
            world) and ``omega`` ``(..., 3)`` (world frame). Leading axes are
            particles; they are vmapped.
        inertia: body-frame inertia, principal moments ``(3,)`` or a symmetric
            tensor ``(3, 3)``, shared by all particles, or one per particle with
            the particle axes in front. (For exactly three particles, a ``(3, 3)``
            array is read as one shared tensor.)
        dt: time step > 0 (scalar).
        n_steps: number of steps (Python int >= 0).
        torque: ``torque(t, q, omega, args) -> (3,)`` world-frame torque on one
            body, or None for a torque-free body (then never called).
        args: any pytree passed unchanged to ``torque``, shared by all particles;
            a leaf wrapped in `jaxrot.per_body` (particle axes in front) gives
            each body its own value. A coupled torque (`jaxrot.torques`) sees
            all bodies of the rollout.
        save_every: save one state every ``save_every`` steps.
        t0: initial time.
        drive: a `jaxrot.Drive` imposing angular velocity or moment per body and
            component (Rockable's driven bodies), or None.
        normalize: normalise ``state.q`` instead of rejecting a non-unit one.
        return_carry: also return the scheme's final carry (particle axes
            flattened to one), for example the iteration counts of ``"rozmanov"``.
        runtime_check: check every step (saved or not) for a NaN/inf in ``q`` or
            ``omega`` and for ``| |q| - 1 | > 1e-6``, and report the first bad step,
            its time and particle (see `jaxrot.IntegrationError`). Off by default:
            then nothing is traced and it costs nothing.

    Returns:
        `Trajectory` with ``t`` ``(n_saved,)``, ``q`` ``(n_saved, ..., 4)``,
        ``omega`` ``(n_saved, ..., 3)``, ``n_saved = n_steps // save_every + 1``;
        index 0 is the initial state. Steps after the last saved one are not
        computed. Arrays keep the dtype of ``state``. With ``return_carry``, a
        pair ``(trajectory, final_carry)``.

    Warns:
        RuntimeWarning: when the scheme reports a problem in its final carry
            (``"rozmanov"``: the half-step iteration hit ``max_iter``); eager
            calls only.

    Raises:
        jaxrot.IntegrationError: with ``runtime_check=True``, eager calls, when a
            step produced a NaN/inf or a non-unit quaternion. Under ``jit``/``vmap``/
            ``grad`` the same message is raised when the compiled code runs, wrapped
            by jax in ``jax.errors.JaxRuntimeError``.
        ValueError: for a wrong shape, non-finite values, a non-unit ``q``, a
            non-physical inertia, ``dt <= 0``, ``n_steps < 0`` or an unknown scheme,
            before anything compiles. Value checks are skipped for traced inputs.

    Example:
        >>> import jax.numpy as jnp, jaxrot
        >>> state = jaxrot.RotState(jnp.array([1.0, 0, 0, 0]), jnp.array([0.3, 1.0, 0.2]))
        >>> traj = jaxrot.rollout("zhao", state, jnp.array([1.0, 2.0, 3.0]), 0.01, 100, save_every=10)
        >>> traj.q.shape
        (11, 4)
    """
    scheme = resolve_scheme(scheme)
    state, inertia, per_particle = check_bodies(state, inertia, normalize=normalize)
    dtype = state.q.dtype
    batch_shape = state.q.shape[:-1]
    dt = check_dt(dt).astype(dtype)
    n_steps = check_count(n_steps, "n_steps", 0)
    save_every = check_count(save_every, "save_every", 1)
    check_torque(torque)
    t0 = jnp.asarray(t0).astype(dtype)
    if t0.ndim != 0:
        raise ValueError(f"`t0` must be a scalar time; got shape {t0.shape}.")

    drive, drive_per_particle = check_drive(drive, batch_shape, dtype)

    flat_state, inertia = flatten_particles(state, inertia, per_particle)
    args, args_axes = split_per_body(args, batch_shape)
    if drive_per_particle:
        drive = jax.tree_util.tree_map(lambda x: x.reshape(-1, 3), drive)
    traj, carry = _rollout_flat(
        scheme,
        flat_state,
        inertia,
        per_particle,
        dt,
        t0,
        args,
        args_axes,
        torque,
        drive,
        drive_per_particle,
        n_steps // save_every,
        save_every,
        runtime_check,
    )
    if runtime_check:
        carry, report = carry
        check = raise_if_bad if is_concrete(report, t0, dt) else check_in_graph
        check(report, batch_shape, t0, dt, scheme.name)
    if is_concrete(carry):
        message = scheme.report(carry)
        if message:
            warnings.warn(message, RuntimeWarning, stacklevel=2)
    traj = unflatten_trajectory(traj, batch_shape)
    return (traj, carry) if return_carry else traj


@eqx.filter_jit
def _rollout_flat(
    scheme,
    state,
    inertia,
    per_particle,
    dt,
    t0,
    args,
    args_axes,
    torque,
    drive,
    drive_per_particle,
    n_saves,
    save_every,
    runtime_check=False,
):
    """Rollout of ``(N, ...)`` particles; the compiled core of `rollout`."""
    inertia_axis = 0 if per_particle else None
    drive_axis = 0 if drive_per_particle else None
    prepared = jax.vmap(body_inertia)(inertia) if per_particle else body_inertia(inertia)

    def init_one(s, inert, drv, a):
        return scheme.init(s, t0, inert, torque if drv is None else driven_torque(torque, drv), a)

    def step_one(carry, t, inert, drv, a):
        if drv is None:
            return scheme.step(carry, t, dt, inert, torque, a)
        return driven_step(scheme, carry, t, dt, inert, torque, a, drv)

    # Named, so that a coupled torque can gather the other bodies (`jaxrot.torques`).
    init_all = jax.vmap(init_one, in_axes=(0, inertia_axis, drive_axis, args_axes), axis_name=PARTICLES)
    step_all = jax.vmap(step_one, in_axes=(0, None, inertia_axis, drive_axis, args_axes), axis_name=PARTICLES)

    def save_interval(carry_report, save_index):
        def one_step(c_r, j):
            c, report = c_r
            # t from the step index, not by accumulation, so late times keep full precision.
            t = t0 + (save_index * save_every + j).astype(dt.dtype) * dt
            c = step_all(c, t, prepared, drive, args)
            if runtime_check:
                report = update_report(report, jax.vmap(scheme.state)(c), save_index * save_every + j + 1)
            return (c, report), None

        (carry, report), _ = jax.lax.scan(one_step, carry_report, jnp.arange(save_every))
        return (carry, report), jax.vmap(scheme.state)(carry)

    carry = init_all(state, prepared, drive, args)
    report = init_report(state) if runtime_check else None
    (carry, report), saved = jax.lax.scan(save_interval, (carry, report), jnp.arange(n_saves))
    if runtime_check:
        carry = (carry, report)
    q = jnp.concatenate([state.q[None], saved.q], axis=0)
    omega = jnp.concatenate([state.omega[None], saved.omega], axis=0)
    t = t0 + jnp.arange(n_saves + 1).astype(dt.dtype) * (save_every * dt)
    return Trajectory(t, q, omega), carry
