"""`overdamped_rollout`: bodies without inertia in a fluid, the orientation alone."""

import math

import jax
import jax.numpy as jnp
import numpy as np

from .. import quaternion as quat
from .._core._checks import QUATERNION_NORM_TOL, declared_dtype, float_dtype, is_concrete
from .._core._compile import filter_jit
from .._fluid._flow import flow_rotation
from .._fluid._fluid import check_fluid
from .._particles import PARTICLES, split_per_body, unflatten_trajectory
from .._state import Trajectory
from .._validation import check_run_times, check_torque
from ..schemes._base import world_torque
from ..schemes._rkn_splitting import uses_omega
from ._bind import OVERDAMPED, bind_brownian, for_concrete_steps, scheme_for_call
from ._runtime_check import IntegrationError, nonfinite_message
from ._saved_steps import saved_steps


def overdamped_rollout(
    q,
    fluid,
    dt,
    n_steps: int,
    *,
    torque=None,
    args=None,
    scheme=None,
    save_every: int = 1,
    t0=0.0,
    key=None,
) -> Trajectory:
    """Bodies without inertia in a fluid: the orientation turned by the fluid and the torque.

    The limit of `jaxrot.rollout` as ``I/ζ → 0`` (Stokes number 0): the fluid's torque balances
    ``torque`` at every instant, and the body turns at

        ω = Ω + B p × (E p) + R (ζ⁻¹ ⊙ Rᵀ τ),

    world frame, with ``Ω``, ``E``, ``B``, ``ζ`` of ``fluid`` (`jaxrot.Fluid`), ``R`` the rotation
    of ``q`` and ``p = R e_z``. Nothing in it is stiff: the step is set by the flow and the torque
    alone. Jeffery's orbits (``torque=None``) come out of it; `jaxrot.rollout` with a fluid tends to
    it as the Stokes number ``I γ̇/ζ`` falls, with an error of order the Stokes number.

    Two models (`jaxrot.schemes_for`): ``"overdamped"`` at ``kT = 0`` (`jaxrot.OVERDAMPED_SCHEMES`)
    and ``"brownian"`` at ``kT > 0`` with a PRNG ``key`` (`jaxrot.BROWNIAN_SCHEMES`: the orientation
    also diffuses, ``D_k = kT/ζ_k`` about the body axes). The call decides the model once, before
    anything compiles, and refuses a scheme that does not integrate it.

    Args:
        q: unit quaternions ``(..., 4)``, scalar first, body → world; leading axes are bodies.
        fluid: a `jaxrot.Fluid` (fields shared or one per body).
        dt: time step > 0; n_steps: number of steps (>= 0).
        torque: ``torque(t, q, omega, args) -> (3,)`` world torque on one body, or None. It receives
            as ``omega`` the flow's part of the angular velocity, ``Ω + B p × (E p)`` (without the
            torque's own part, which it determines): a torque that depends on ``omega`` is refused
            (``ValueError``), as the balance would be an implicit equation; fold a linear drag into
            ``fluid.friction`` instead.
        args: the torque's parameters (`jaxrot.per_body` leaves: one per body).
        scheme: a name of `jaxrot.schemes_for` of the call's model, or a scheme instance. At
            ``kT = 0``: ``"rkmk4"`` (order 4; the default, a ``key`` or not), ``"lie_euler"`` (1),
            ``"lie_midpoint"`` (2), e.g. ``type(jaxrot.OVERDAMPED_SCHEMES["rkmk4"])(chart="cayley")``
            (half the operations a step, not exact at a constant angular velocity), and the Brownian
            schemes without noise. At ``kT > 0`` with a ``key``:
            ``"brownian_splitting"`` (weak order 2; the default with a ``key``) or
            ``"brownian_euler"`` (weak order 1).
        save_every: save every ``save_every`` steps (it must divide ``n_steps``); t0: initial time.
        key: a JAX PRNG key, required when ``fluid.kT > 0`` (Brownian rotation; the same key gives
            the same run); unused otherwise, except that it makes ``"brownian_splitting"`` the default.

    Returns:
        `jaxrot.Trajectory`: ``t`` ``(n_saved,)``, ``q`` ``(n_saved, ..., 4)`` and ``omega``
        ``(n_saved, ..., 3)``, the world angular velocity above at each saved state.

    Raises:
        ValueError: a wrong shape, a non-unit or non-finite ``q``, ``dt <= 0``, ``n_steps < 0``, a
            ``save_every`` that does not divide ``n_steps``, an unknown scheme, a scheme that does not
            integrate the call's model (the message names the schemes that do), a bad fluid, a torque
            that depends on ``omega``, ``kT > 0`` without a ``key``, or a ``kT`` traced (under
            ``jit``) without a ``key`` (at trace time); before anything compiles.
        jaxrot.IntegrationError: (eager) a saved state holds a NaN or an infinity.

    Example:
        >>> import jax.numpy as jnp, jaxrot
        >>> shear = jnp.zeros((3, 3)).at[0, 1].set(1.0)  # u = (y, 0, 0), shear rate 1
        >>> fluid = jaxrot.Fluid.spheroid(3.0, 1.0, viscosity=1.0, velocity_gradient=shear)
        >>> q0 = jaxrot.quaternion.from_axis_angle(jnp.array([0.0, 1, 0]), jnp.pi / 2)  # axis along x
        >>> period = 2 * jnp.pi * (3 + 1 / 3)  # Jeffery's period at aspect ratio 3
        >>> traj = jaxrot.overdamped_rollout(q0, fluid, period / 2000, 2000, save_every=1000)
        >>> axis = jaxrot.quaternion.rotate(traj.q, jnp.array([0.0, 0, 1]))
        >>> (axis.round(6) + 0.0).tolist()  # tumbled: a half turn in half a period, home after one
        [[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [1.0, 0.0, 0.0]]
    """
    q, dtype = _check_orientations(q)
    scheme, model = scheme_for_call(scheme, OVERDAMPED, fluid, key)  # the one check of scheme and model
    if model == "brownian":  # read before the checks cast the fluid and dt into the trace
        scheme = for_concrete_steps(scheme, fluid, dt)
    batch_shape = tuple(q.shape[:-1])
    dt, n_steps, save_every, t0 = check_run_times(dt, n_steps, save_every, t0, dtype)
    check_torque(torque)
    fluid, fluid_axes = check_fluid(fluid, batch_shape, dtype)
    args, args_axes = split_per_body(args, batch_shape)
    n = math.prod(batch_shape)
    start = q.reshape(n, 4)
    if model == "brownian":  # each body's start carries its noise's key and its diffusion
        scheme, start = bind_brownian(scheme, start, fluid, key)
    else:
        scheme = scheme.overdamped()
    traj = _overdamped_flat(
        scheme,
        start,
        fluid,
        fluid_axes,
        dt,
        t0,
        torque,
        args,
        args_axes,
        n_steps // save_every,
        save_every,
    )
    traj = unflatten_trajectory(traj, batch_shape)
    if is_concrete(traj):
        text = nonfinite_message(traj, dt, scheme.name, "jaxrot.overdamped_rollout")
        if text is not None:
            raise IntegrationError(text)
    return traj


def _check_orientations(q):
    dtype = declared_dtype(q, "q")
    q = jnp.asarray(q)
    if q.ndim < 1 or q.shape[-1] != 4:
        raise ValueError(f"`q` must have shape (..., 4) (scalar-first [w, x, y, z]); got {q.shape}.")
    q = q.astype(dtype if dtype is not None else float_dtype(q))
    if is_concrete(q):
        raw = np.asarray(q, dtype=np.float64)
        if not np.all(np.isfinite(raw)):
            raise ValueError("`q` contains NaN or infinite values.")
        worst = float(np.max(np.abs(np.linalg.norm(raw, axis=-1) - 1))) if raw.size else 0.0
        if worst > QUATERNION_NORM_TOL:
            raise ValueError(
                f"`q` must be unit quaternions (| |q| - 1 | <= {QUATERNION_NORM_TOL:g}); the worst is off by "
                f"{worst:.3g}. Normalise it (jaxrot.quaternion.normalize)."
            )
    return q, q.dtype


def velocity_field(fluid, torque, args):
    """``velocity(t, q) -> (3,)``: the overdamped world angular velocity of one body."""

    def velocity(t, q):
        omega = flow_rotation(q, fluid.velocity_gradient, fluid.bretherton)
        if torque is None:
            return omega
        if uses_omega(torque, t, q, omega, args):
            raise ValueError(
                "`torque` depends on the angular velocity, which the overdamped model does not have as a "
                "state (ω is what balances the torques): fold a linear drag into `fluid.friction`, or "
                "integrate the inertial model, jaxrot.rollout(..., fluid=fluid)."
            )
        tau = world_torque(torque, t, q, omega, args)
        return omega + quat.rotate(q, quat.rotate(quat.conjugate(q), tau) / fluid.friction)

    return velocity


@filter_jit
def _overdamped_flat(scheme, q, fluid, fluid_axes, dt, t0, torque, args, args_axes, n_saves, save_every):
    """The time loop over ``(N, 4)`` orientations: ``n_saves`` saves of ``save_every`` steps."""

    def init_one(q, fluid, args):
        return scheme.init(q, t0, velocity_field(fluid, torque, args))

    def step_one(carry, t, fluid, args):
        return scheme.step(carry, t, dt, velocity_field(fluid, torque, args))

    init_all = jax.vmap(init_one, in_axes=(0, fluid_axes, args_axes), axis_name=PARTICLES)
    step_all = jax.checkpoint(
        jax.vmap(step_one, in_axes=(0, None, fluid_axes, args_axes), axis_name=PARTICLES), prevent_cse=False
    )

    carry = init_all(q, fluid, args)
    saved = saved_steps(
        carry, lambda c, t, _: step_all(c, t, fluid, args), lambda c: c, dt, save_every, n_saves, t0
    )
    t = t0 + jnp.arange(n_saves + 1).astype(dt.dtype) * (save_every * dt)
    return Trajectory(
        t, jnp.concatenate([carry.q[None], saved.q]), jnp.concatenate([carry.omega[None], saved.omega])
    )
