"""`rollout`: a whole run in one call, or in chunks for a progress bar (`jaxrot._integrate._chunked`).

The time loop (one `lax.scan` over time, `vmap` over particles, bodies in cache-sized
blocks) and the argument checks are the shared core in `jaxrot._integrate._run`.
"""

from .._particles import unflatten_trajectory
from .._state import RotState
from ._chunked import chunked_rollout
from ._run import prepare_run
from ._sharding import particle_sharded


@particle_sharded
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
    check_finite: bool = True,
    progress: bool = False,
    chunk_steps: int | None = None,
    fluid=None,
    key=None,
):
    """Integrate rigid-body rotation with a fixed step and return the saved states.

    One call, three models (`jaxrot.schemes_for`): a body in vacuum (``"vacuum"``, without
    ``fluid``), in a fluid (``"fluid"``, ``fluid=jaxrot.Fluid(friction)`` at ``kT = 0``) and in a
    fluid at a temperature (``"thermal"``, ``kT > 0`` and a PRNG ``key``). The call decides the
    model once, before anything compiles, and refuses a scheme that does not integrate it. A body
    without inertia: `jaxrot.overdamped_rollout`.

    Args:
        scheme: a name of `jaxrot.schemes_for` of the call's model, or a scheme instance: without
            ``fluid`` one of `jaxrot.SCHEMES` (``"zhao"``, …); with ``fluid`` one of
            `jaxrot.FLUID_SCHEMES` at ``kT = 0`` (``"exp_midpoint"``, ``"exp_rk4"``, and the thermal
            schemes without noise) and of `jaxrot.THERMAL_SCHEMES` at ``kT > 0`` with a ``key``
            (``"baoab"``, ``"exp_euler"``).
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
        save_every: save one state every ``save_every`` steps; it must divide
            ``n_steps``, so that the last saved state is the final one.
        t0: initial time.
        drive: a `jaxrot.Drive` imposing angular velocity or moment per body and
            component (Rockable's driven bodies), or None.
        normalize: normalise ``state.q`` instead of rejecting a non-unit one.
        return_carry: also return the scheme's final carry (particle axes
            flattened to one), for example the iteration counts of ``"rozmanov"``.
        runtime_check: check every step (saved or not) for a NaN/inf in ``q`` or
            ``omega`` and for ``| |q| - 1 | > 1e-6``, and report the first bad step,
            its time and particle (see `jaxrot.IntegrationError`). Off by default:
            then nothing is traced and it costs nothing. Under ``jit`` it is the
            way to be told of a NaN: ``check_finite`` needs concrete results.
        check_finite: eager calls (concrete results) only, on by default: raise
            `jaxrot.IntegrationError` if a saved state holds a NaN or an infinity,
            naming the first such saved state, the bodies affected, the largest
            ``|ω|Δt`` seen and the scheme's measured limit from
            `jaxrot.stability.LIMITS` with a ``dt`` inside it. One reduction over
            the saved states: within ±1% of a 200-step ``"zhao"`` run of 10⁴ bodies
            that saves every 10th step, +13% if it saves every step (measured).
            ``False`` returns the values unchecked.
        progress: show a `tqdm` progress bar (on stderr, counting steps), updated
            between chunks of ``chunk_steps`` steps (default: about 100 chunks).
        chunk_steps: run in chunks of this many steps (a positive multiple of
            ``save_every``) via `jaxrot.rollout_chunks`, and concatenate them. The
            result is bit for bit that of one call; chunks of one size compile
            once. To save and resume a long run, use `jaxrot.rollout_chunks`.
        fluid: a `jaxrot.Fluid` the bodies turn in, or None: its torque
            (friction, the flow's rotation and strain, and at ``kT > 0`` the thermal
            torque that balances the friction) is added to ``torque``. Its friction is
            integrated exactly, so no step is limited by ``I/ζ``: at ``kT = 0`` the
            schemes of `jaxrot.FLUID_SCHEMES` (``"exp_midpoint"``, order 2;
            ``"exp_rk4"``, order 4) or of `jaxrot.THERMAL_SCHEMES` take it, at
            ``kT > 0`` those of `jaxrot.THERMAL_SCHEMES` (``"baoab"``, weak order 2;
            ``"exp_euler"``, weak order 1); the others raise ``ValueError``. The
            inertia must be principal moments ``(..., 3)`` about the friction's axes.
        key: a JAX PRNG key, required for a fluid with ``kT > 0`` (the same key
            gives the same run); unused otherwise.

    Returns:
        `Trajectory` with ``t`` ``(n_saved,)``, ``q`` ``(n_saved, ..., 4)``,
        ``omega`` ``(n_saved, ..., 3)``, ``n_saved = n_steps // save_every + 1``;
        index 0 is the initial state and index -1 the final one. Arrays keep
        the dtype of ``state`` (float32 or float64). With ``return_carry``, a
        pair ``(trajectory, final_carry)``.

    Warns:
        RuntimeWarning: when the scheme reports a problem in its final carry
            (``"rozmanov"``: the half-step iteration hit ``max_iter``); eager
            calls only.

    Raises:
        jaxrot.IntegrationError: eager calls, when a saved state holds a NaN or an
            infinity (``check_finite``), or, with ``runtime_check=True``, when a
            step produced a NaN/inf or a non-unit quaternion. Under ``jit``/``vmap``/
            ``grad`` the same message is raised when the compiled code runs, wrapped
            by jax in ``jax.errors.JaxRuntimeError``.
        ValueError: for a wrong shape, non-finite values, a non-unit ``q``, a
            non-physical inertia, ``dt <= 0``, ``n_steps < 0``, a ``save_every``
            that does not divide ``n_steps``, an unknown scheme, a scheme that does
            not integrate the call's model (the message names the schemes that do),
            ``kT > 0`` without a ``key``, a ``kT`` traced (under ``jit``) without a
            ``key`` (at trace time: whether it is 0 is not known before the program
            runs), a full inertia tensor or a ``drive`` with ``fluid``, a
            ``chunk_steps`` that is not a positive multiple of ``save_every``, or a
            dtype other than float32/float64 (or ``state.q`` and ``state.omega`` of
            different dtypes), before anything compiles. Value checks are skipped for
            traced inputs.

    Example:
        >>> import jax.numpy as jnp, jaxrot
        >>> state = jaxrot.RotState(jnp.array([1.0, 0, 0, 0]), jnp.array([0.3, 1.0, 0.2]))
        >>> traj = jaxrot.rollout("zhao", state, jnp.array([1.0, 2.0, 3.0]), 0.01, 100, save_every=10)
        >>> traj.q.shape
        (11, 4)
        >>> chunked = jaxrot.rollout("zhao", state, jnp.array([1.0, 2.0, 3.0]), 0.01, 100, save_every=10,
        ...                          chunk_steps=30)
        >>> bool(jnp.all(chunked.q == traj.q))
        True
    """
    run = prepare_run(
        scheme,
        state,
        inertia,
        dt,
        n_steps,
        torque,
        args,
        save_every,
        t0,
        drive,
        normalize,
        runtime_check,
        check_finite,
        fluid,
        key,
    )
    if progress or chunk_steps is not None:
        return chunked_rollout(run, chunk_steps, progress=progress, return_carry=return_carry)
    # Without return_carry the compiled core returns only the scheme's summary of the final carry:
    # peak memory for 10^6 bodies, 10^3 steps fell from 992 to 719 MiB (NO_SQUISH), 823 to 728 (Zhao).
    traj, carry = run.flat(run.n_saves, state=run.flat_state, keep_carry=return_carry)
    carry = run.checked(carry)
    summary = run.scheme.summarize(carry) if return_carry else carry
    run.warn_if_reported(summary, stacklevel=3)  # past `particle_sharded`'s wrapper to the caller
    traj = unflatten_trajectory(traj, run.batch_shape)
    run.raise_if_nonfinite(traj)
    return (traj, carry) if return_carry else traj
