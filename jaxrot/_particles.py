"""Leading particle axes: flattened to one vmapped axis inside, restored on output."""

import math

from ._state import RotState, Trajectory


def flatten_particles(state: RotState, inertia, per_particle: bool):
    """``state`` as ``(N, 4)``/``(N, 3)`` and a per-particle ``inertia`` as ``(N, 3[, 3])``."""
    batch_shape = state.q.shape[:-1]
    n = math.prod(batch_shape)
    flat = RotState(state.q.reshape(n, 4), state.omega.reshape(n, 3))
    if per_particle:
        inertia = inertia.reshape(n, *inertia.shape[len(batch_shape) :])
    return flat, inertia


def unflatten_trajectory(traj: Trajectory, batch_shape) -> Trajectory:
    """``(n_saved, N, ...)`` arrays back to ``(n_saved, *batch_shape, ...)``."""
    n_saved = traj.q.shape[0]
    return Trajectory(
        traj.t, traj.q.reshape(n_saved, *batch_shape, 4), traj.omega.reshape(n_saved, *batch_shape, 3)
    )
