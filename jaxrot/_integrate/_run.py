"""The rollout core that `jaxrot.rollout` and `jaxrot.rollout_chunks` share.

`prepare_run` checks a rollout's arguments (before anything compiles) and flattens
its particle axes into a `Run`; `Run.flat` runs the compiled time loop,
`_rollout_flat`, from an initial state or from a carry. `jaxrot._integrate._rollout` runs it in
one call and `jaxrot._integrate._chunked` a chunk at a time; this module imports neither.
"""

import dataclasses
import math
import warnings
from typing import Any

import jax
import jax.numpy as jnp

from .._core._compile import filter_jit
from .._core._concrete import is_concrete
from .._inertia import body_inertia
from .._particles import PARTICLES, flatten_particles, split_per_body
from .._state import RotState, Trajectory
from .._validation import check_bodies, check_run_times, check_torque
from ..schemes._base import advance
from . import _blocking
from ._bind import INERTIAL, bind_fluid, scheme_for_call
from ._drive import check_drive, driven_step, driven_torque
from ._runtime_check import (
    IntegrationError,
    check_in_graph,
    init_report,
    nonfinite_message,
    raise_if_bad,
    update_report,
)
from ._sharding import particle_shards, shard_particles


@dataclasses.dataclass(frozen=True, kw_only=True)
class Run:
    """A validated rollout with its particle axes flattened: the fixed arguments of `_rollout_flat`.

    Built by keyword (`prepare_run`), as diffrax builds its loop's state."""

    scheme: Any  # the scheme's form for the call's model (`jaxrot._integrate._bind`)
    flat_state: RotState
    inertia: Any
    per_particle: bool
    dt: jax.Array
    t0: jax.Array
    args: Any
    args_axes: Any
    torque: Any
    drive: Any
    drive_per_particle: bool
    n_saves: int
    save_every: int
    n_steps: int
    batch_shape: tuple
    runtime_check: bool
    n_blocks: int
    check_finite: bool = True

    def flat(self, n_saves, carry=None, save_offset=None, state=None, keep_carry=True):
        """`_rollout_flat` of ``n_saves`` saves from ``state``, or continuing ``carry`` (see there)."""
        return _rollout_flat(
            self.scheme,
            state,
            self.inertia,
            self.per_particle,
            self.dt,
            self.t0,
            self.args,
            self.args_axes,
            self.torque,
            self.drive,
            self.drive_per_particle,
            n_saves,
            self.save_every,
            runtime_check=self.runtime_check,
            carry=carry,
            save_offset=save_offset,
            n_blocks=self.n_blocks,
            keep_carry=keep_carry,
        )

    def checked(self, carry):
        """The scheme's carry (or summary) from `flat`'s: with ``runtime_check``, split off its
        report and raise (eager) or schedule the raise (traced) of any bad step in it."""
        if not self.runtime_check:
            return carry
        carry, report = carry
        check = raise_if_bad if is_concrete(report, self.t0, self.dt) else check_in_graph
        check(report, self.batch_shape, self.t0, self.dt, self.scheme.name)
        return carry

    def raise_if_nonfinite(self, traj, caller="jaxrot.rollout", first_index=0):
        """With ``check_finite`` and a concrete ``traj`` (its saved states numbered from ``first_index``):
        raise `IntegrationError` if it holds a NaN/inf."""
        if self.check_finite and is_concrete(traj):
            text = nonfinite_message(traj, self.dt, self.scheme.name, caller, first_index)
            if text is not None:
                raise IntegrationError(text)

    def warn_if_reported(self, summary, stacklevel):
        """Warn of the problem the scheme reports in the (concrete) `summarize` of its final carry,
        if any, at the frame ``stacklevel`` levels above the caller, as `warnings.warn` counts."""
        if is_concrete(summary):
            message = self.scheme.report(summary)
            if message:
                warnings.warn(message, RuntimeWarning, stacklevel=stacklevel + 1)


def prepare_run(
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
    check_finite=True,
    fluid=None,
    key=None,
) -> Run:
    """Check the arguments of `rollout` (before anything compiles) and flatten the particle axes."""
    scheme, model = scheme_for_call(scheme, INERTIAL, fluid, key)  # the one check of scheme and model
    state, inertia, per_particle = check_bodies(state, inertia, normalize=normalize)
    dtype = state.q.dtype
    batch_shape = tuple(state.q.shape[:-1])
    dt, n_steps, save_every, t0 = check_run_times(dt, n_steps, save_every, t0, dtype)
    check_torque(torque)
    drive, drive_per_particle = check_drive(drive, batch_shape, dtype)

    flat_state, inertia = flatten_particles(state, inertia, per_particle)
    args, args_axes = split_per_body(args, batch_shape)
    if model != "vacuum":  # the fluid's per-body values travel with the torque's args
        scheme, args, args_axes = bind_fluid(
            scheme, model, fluid, key, batch_shape, dtype, inertia, args, args_axes, drive
        )
    if drive_per_particle:
        drive = jax.tree_util.tree_map(lambda x: x.reshape(-1, 3), drive)
    # Sharded particles: each device keeps its own bodies (`jaxrot._integrate._sharding`).
    flat_state, inertia, args, drive = shard_particles(
        (flat_state, inertia, args, drive),
        (0, 0 if per_particle else None, args_axes, 0 if drive_per_particle else None),
    )
    n = math.prod(batch_shape)
    n_blocks = _blocking.n_blocks_for(n, shards=particle_shards()) if _blocking.on_cpu(flat_state.q) else 1
    # Only the torque's own args (not the fluid's) go to the torque.
    torque_args, torque_axes = (args.args, args_axes.args) if model != "vacuum" else (args, args_axes)
    if n_blocks > 1 and _blocking.couples_bodies(torque, n, t0, flat_state, torque_args, torque_axes):
        n_blocks = 1
    return Run(
        scheme=scheme,
        flat_state=flat_state,
        inertia=inertia,
        per_particle=per_particle,
        dt=dt,
        t0=t0,
        args=args,
        args_axes=args_axes,
        torque=torque,
        drive=drive,
        drive_per_particle=drive_per_particle,
        n_saves=n_steps // save_every,
        save_every=save_every,
        n_steps=n_steps,
        batch_shape=batch_shape,
        runtime_check=bool(runtime_check),
        n_blocks=n_blocks,
        check_finite=bool(check_finite),
    )


@filter_jit  # with jaxrot's compiler options when called at top level (`jaxrot._core._compile`)
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
    carry=None,
    save_offset=None,
    n_blocks=1,
    keep_carry=True,
):
    """Rollout of ``(N, ...)`` particles; the compiled core of `rollout`.

    With ``carry=None`` it starts from ``state`` with ``scheme.init`` and returns the
    ``n_saves + 1`` saved states, the initial one first. With a ``carry`` (a scheme
    carry of ``(N, ...)`` particles, as returned here) it continues it instead:
    ``state`` is then None, ``save_offset`` (a traced integer, so that every chunk of
    one size shares one compilation) is the number of saves already done, and only
    the ``n_saves`` new states are returned, with times and step numbers counted from
    ``t0`` exactly as in one call (`jaxrot._integrate._chunked`).

    With ``n_blocks > 1`` (bodies that no torque couples, `jaxrot._integrate._blocking`) the
    bodies go through the whole time loop one block at a time, each block's stages in
    cache: the same arithmetic per body (the same bits but for ``"splitting"``).

    With ``keep_carry=False`` the final carry is replaced by ``scheme.summarize`` of it
    (with the runtime check's report, if any, still beside it).
    """
    resumed = carry is not None
    # Global save indices: integer arithmetic, so times match one long call bit for bit.
    save_indices = save_offset + jnp.arange(n_saves) if resumed else jnp.arange(n_saves)

    def bodies(state, carry, inertia, drive, args):
        """The time loop for some ``(M, ...)`` of the bodies: ``(saved states, carry)``."""
        inertia_axis = 0 if per_particle else None
        drive_axis = 0 if drive_per_particle else None
        prepared = jax.vmap(body_inertia)(inertia) if per_particle else body_inertia(inertia)

        def init_one(s, inert, drv, a):
            return scheme.init(s, t0, inert, torque if drv is None else driven_torque(torque, drv), a)

        def step_one(carry, index, t, inert, drv, a):
            if drv is None:
                return advance(scheme, carry, index, t, t0, dt, inert, torque, a)
            return driven_step(scheme, carry, t, dt, inert, torque, a, drv)

        # Named, so that a coupled torque can gather the other bodies (`jaxrot.torques`).
        init_all = jax.vmap(init_one, in_axes=(0, inertia_axis, drive_axis, args_axes), axis_name=PARTICLES)
        # Checkpointed: under reverse-mode differentiation the time loop keeps only each step's carry
        # and recomputes the step's stages in the reverse pass, instead of keeping every stage value
        # of every step. Measured (benchmarks/compile.py's 200-step heavy-top gradient, 2 CPU cores):
        # gradients compile 15-40% faster (rkmk_dopri5 24.7 -> 15.9 s, no_squish 11.3 -> 8.4) and run
        # 1.1-3x faster (rkmk4 10.8 -> 4.3 ms; 1000 bodies 1.34 -> 0.66 s); only the RKN splittings'
        # one-body gradient runs slower (srkn6b 77 -> 136 ms; with 1000 bodies 17.4 -> 13.3 s).
        # Forward programs compute the same bits (no differentiation, no recompute); their speed stayed
        # within the 10-15% noise of that host (N = 1000 and 10^4, three interleaved rounds).
        step_all = jax.checkpoint(
            jax.vmap(
                step_one, in_axes=(0, None, None, inertia_axis, drive_axis, args_axes), axis_name=PARTICLES
            ),
            prevent_cse=False,  # inside a loop, as JAX's docs advise: the loop already prevents CSE
        )

        def save_interval(carry_report, save_index):
            def one_step(c_r, j):
                c, report = c_r
                # t from the step index, not by accumulation, so late times keep full precision.
                index = save_index * save_every + j
                t = t0 + index.astype(dt.dtype) * dt
                c = step_all(c, index, t, prepared, drive, args)
                if runtime_check:
                    report = update_report(report, jax.vmap(scheme.state)(c), save_index * save_every + j + 1)
                return (c, report), None

            (carry, report), _ = jax.lax.scan(one_step, carry_report, jnp.arange(save_every))
            return (carry, report), jax.vmap(scheme.state)(carry)

        if resumed:
            if runtime_check:
                # The chunk's first state is step ``save_offset * save_every`` (checked again in case the
                # carry comes from a run without the check).
                report = init_report(jax.vmap(scheme.state)(carry))
                first_step = (save_offset * save_every).astype(jnp.int32)
                report = report._replace(step=jnp.where(report.step >= 0, first_step, report.step))
            else:
                report = None
        else:
            carry = init_all(state, prepared, drive, args)
            report = init_report(state) if runtime_check else None
        if resumed and n_saves * save_every == 1:
            # A lone step outside any loop gets fused with its surroundings, which moved float32 results
            # by an ulp against the same step inside the loop of one call; a trip count that XLA cannot
            # evaluate (1 for any offset >= 0) keeps the loop.
            def body(i_carry_report):
                i, carry_report = i_carry_report
                return i + 1, save_interval(carry_report, save_offset + i)[0]

            trips = 1 + jnp.minimum(save_offset, 0)
            start = (jnp.zeros_like(save_offset), (carry, report))
            _, (carry, report) = jax.lax.while_loop(lambda x: x[0] < trips, body, start)
            saved = jax.tree_util.tree_map(lambda x: x[None], jax.vmap(scheme.state)(carry))
        else:
            (carry, report), saved = jax.lax.scan(save_interval, (carry, report), save_indices)
        if runtime_check:
            carry = (carry, report)
        if not resumed:
            saved = jax.tree_util.tree_map(lambda s, x: jnp.concatenate([s[None], x]), state, saved)
        return saved, carry

    inputs = (state, carry, inertia, drive, args)
    if n_blocks == 1:
        saved, carry = bodies(*inputs)
    else:
        axes = (0, 0, 0 if per_particle else None, 0 if drive_per_particle else None, args_axes)
        n = jax.tree_util.tree_leaves((state, carry))[0].shape[0]
        saved, carry = _blocking.map_blocks(bodies, n_blocks, inputs, axes)
        saved = jax.tree_util.tree_map(lambda y: _blocking.from_blocks(y, n, body_axis=1), saved)
        carry = jax.tree_util.tree_map(lambda y: _blocking.from_blocks(y, n, body_axis=0), carry)
    if resumed:
        t = t0 + (save_indices + 1).astype(dt.dtype) * (save_every * dt)
    else:
        t = t0 + jnp.arange(n_saves + 1).astype(dt.dtype) * (save_every * dt)
    if not keep_carry:
        carry = (scheme.summarize(carry[0]), carry[1]) if runtime_check else scheme.summarize(carry)
    return Trajectory(t, saved.q, saved.omega), carry
