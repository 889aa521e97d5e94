"""`reference_rollout`: a tight-tolerance diffrax solution to check schemes against."""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import quaternion as quat
from .._core._checks import check_values, is_concrete
from .._inertia import body_inertia
from .._integrate._runtime_check import IntegrationError, nonfinite_message
from .._integrate._sharding import particle_sharded
from .._particles import PARTICLES, flatten_particles, split_per_body, unflatten_trajectory
from .._state import RotState, Trajectory
from .._validation import check_bodies, check_times, check_torque
from ..schemes._base import body_torque


def _vector_field(t, y, ctx):
    """Rigid-body ODE in ``(q, ω_b)``: ``q̇ = ½ q ⊗ (0, ω_b)``, Euler's equations for ``ω_b``.

    ``q`` is integrated in ℝ⁴ (diffrax has no manifold solvers); the physics
    always sees ``q/|q|`` so the tiny norm drift never feeds back.
    """
    inertia, torque, args = ctx
    q, omega_b = y
    q_unit = quat.normalize(q)
    tau_b = None if torque is None else body_torque(torque, t, q_unit, quat.rotate(q_unit, omega_b), args)
    q_dot = 0.5 * quat.multiply(q, quat.pure(omega_b))
    return q_dot, inertia.angular_acceleration(omega_b, tau_b)


@particle_sharded
def reference_rollout(
    state: RotState,
    inertia,
    ts,
    *,
    torque=None,
    args=None,
    rtol=1e-12,
    atol=1e-12,
    max_steps: int = 1_000_000,
    normalize: bool = False,
    jump_ts=None,
) -> Trajectory:
    """High-accuracy reference trajectory from diffrax (Dopri8, adaptive PID steps).

    Integrates ``q̇ = ½ q ⊗ (0, ω_b)`` and Euler's equations
    ``I ω̇_b = τ_b − ω_b × I ω_b`` from ``ts[0]`` and returns the states at the
    times ``ts``, with ``q`` normalised on output. Use float64
    (``jax.config.update("jax_enable_x64", True)``) for tolerances below 1e-6.

    Args:
        state: `RotState` with ``q`` ``(..., 4)`` and world ``omega`` ``(..., 3)``;
            leading particle axes are vmapped.
        inertia: body-frame ``(3,)`` / ``(3, 3)``, shared or per particle (as in
            `jaxrot.rollout`).
        ts: increasing save times ``(n,)``; integration starts at ``ts[0]``.
        torque, args: as in `jaxrot.rollout`.
        rtol, atol: tolerances of the PID step-size controller.
        max_steps: cap on solver steps per particle.
        normalize: normalise ``state.q`` instead of rejecting a non-unit one.
        jump_ts: times ``(m,)`` at which the torque jumps (a held control, a switched
            field), or None. The solver steps onto each and restarts there
            (`diffrax.ClipStepSizeController`): an embedded error estimate does not see
            a jump inside a step, so without them the solution is only as accurate as
            the step that straddles it.

    Returns:
        `Trajectory` with ``t = ts``, ``q`` ``(n, ..., 4)``, ``omega`` ``(n, ..., 3)``.

    Raises:
        ValueError: bad input (see `jaxrot.rollout`), or ``ts`` not 1-D,
            non-finite or decreasing, or tolerances below what float32 can meet.
        RuntimeError: the solve failed (for example ``max_steps`` reached); under
            ``jit`` this is an ``EquinoxRuntimeError`` instead.

    Example:
        >>> import jax.numpy as jnp, jaxrot
        >>> state = jaxrot.RotState(jnp.array([1.0, 0, 0, 0]), jnp.array([0.0, 0, 2.0]))
        >>> ref = jaxrot.reference_rollout(state, jnp.array([1.0, 2.0, 3.0]), jnp.linspace(0, 1, 3),
        ...                                rtol=1e-6, atol=1e-6)
        >>> ref.q.shape
        (3, 4)
    """
    state, inertia, per_particle = check_bodies(state, inertia, normalize=normalize)
    dtype = state.q.dtype
    batch_shape = state.q.shape[:-1]
    check_torque(torque)
    ts = check_times(ts, dtype, ordered=True)
    for name, tol in (("rtol", rtol), ("atol", atol)):
        if not tol > 0:
            raise ValueError(f"`{name}` must be > 0; got {tol}.")
        if dtype == jnp.float32 and tol < 1e-6:
            raise ValueError(
                f"`{name}`={tol:g} is below what float32 can meet. Enable float64 with "
                f'jax.config.update("jax_enable_x64", True) and pass float64 arrays, or use {name} >= 1e-6.'
            )

    if jump_ts is not None:
        jump_ts = check_times(jump_ts, dtype, ordered=True, name="jump_ts")

    flat, inertia = flatten_particles(state, inertia, per_particle)
    args, args_axes = split_per_body(args, batch_shape)
    traj, result, _ = adaptive_solve(
        diffrax.Dopri8(), flat.q, flat.omega, inertia, per_particle, ts, torque, args, rtol, atol, max_steps,
        args_axes, jump_ts,
    )  # fmt: skip
    failed = result != diffrax.RESULTS.successful
    count = int(np.sum(failed)) if is_concrete(failed) else "some"
    traj = check_values(
        traj,
        failed,
        f"reference_rollout: the diffrax solve failed for {count} of {failed.size} particle(s) "
        f"(max_steps={max_steps}, rtol={rtol:g}, atol={atol:g}). Raise `max_steps`, loosen the "
        "tolerances, or check the torque for blow-up.",
        error=RuntimeError,
    )
    traj = unflatten_trajectory(traj, batch_shape)
    if is_concrete(traj):
        text = nonfinite_message(
            traj,
            None,
            "diffrax.Dopri8",
            "jaxrot.reference_rollout",
            advice="The adaptive solve reported success: the torque or the inertia made the motion "
            "non-finite (check them; tighter tolerances will not help).",
        )
        if text is not None:
            raise IntegrationError(text)
    return traj


@eqx.filter_jit
def adaptive_solve(
    solver, q, omega, inertia, per_particle, ts, torque, args, rtol, atol, max_steps, args_axes=None,
    jump_ts=None,
):  # fmt: skip
    """Adaptive diffrax solve of ``(N, ...)`` flattened particles (no input checks).

    Each particle gets its own adaptive steps, except under a coupled torque
    (``torque.coupled``, `jaxrot.torques`), where all bodies form one system
    with shared steps. Returns ``(trajectory, result, n_steps)``: the diffrax
    result code and the number of attempted steps (accepted + rejected) per
    particle. Shared by `reference_rollout` and ``python -m jaxrot compare``.
    ``jump_ts``: times the steps land on (torque discontinuities), or None.
    """
    controller = diffrax.PIDController(rtol=rtol, atol=atol)
    if jump_ts is not None:
        controller = diffrax.ClipStepSizeController(controller, jump_ts=jump_ts)
    inertia_axis = 0 if per_particle else None
    prepare = jax.vmap(body_inertia) if per_particle else body_inertia
    coupled = getattr(torque, "coupled", False)

    def solve(q0, omega0, inert, a, field):
        omega_b0 = quat.rotate(quat.conjugate(q0), omega0)
        sol = diffrax.diffeqsolve(
            diffrax.ODETerm(field),
            solver,
            t0=ts[0],
            t1=ts[-1],
            dt0=None,
            y0=(q0, omega_b0),
            args=(inert, torque, a),
            saveat=diffrax.SaveAt(ts=ts),
            stepsize_controller=controller,
            max_steps=max_steps,
            throw=False,
        )
        q_t = quat.normalize(sol.ys[0])
        return q_t, quat.rotate(q_t, sol.ys[1]), sol.result, sol.stats["num_steps"]

    if coupled:
        # One ODE for all bodies; the per-body field is vmapped over the named particle axis.
        def system_field(t, y, ctx):
            inert, trq, a = ctx
            return jax.vmap(
                lambda yi, ii, ai: _vector_field(t, yi, (ii, trq, ai)),
                in_axes=(0, inertia_axis, args_axes),
                axis_name=PARTICLES,
            )(y, inert, a)

        q_t, omega_t, result, n_steps = solve(q, omega, prepare(inertia), args, system_field)
        n = q.shape[0]
        result = jax.tree_util.tree_map(lambda x: jnp.broadcast_to(x, (n,)), result)  # an enum item
        n_steps = jnp.broadcast_to(n_steps, (n,))
        return Trajectory(ts, q_t, omega_t), result, n_steps

    def solve_one(q0, omega0, inert, a):
        return solve(q0, omega0, body_inertia(inert), a, _vector_field)

    in_axes = (0, 0, inertia_axis, args_axes)
    q_t, omega_t, result, n_steps = jax.vmap(solve_one, in_axes=in_axes)(q, omega, inertia, args)
    return Trajectory(ts, jnp.swapaxes(q_t, 0, 1), jnp.swapaxes(omega_t, 0, 1)), result, n_steps
