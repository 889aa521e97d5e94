"""Known control torques in `identify`'s model: the steps they impose and their value inside a step.

A sampled control is a torque with kinks (``"linear"``) or jumps (``"previous"``, a
zero-order hold) at its sample times. A Runge–Kutta step across a jump or a kink
loses the scheme's order, so the model's steps land on every control time inside the
record as well as on the sample times (`step_grid`), and inside each step the control
is one affine function of time, ``value + slope (t − start)``: exact for both holds,
one fused multiply–add per stage instead of an interpolation search.
"""

from typing import NamedTuple

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ... import quaternion as quat


# A control time within this fraction of the record's span of a sample time is that sample time:
# records stamp both clocks in floating point (0.001 · 10 ≠ 0.01), and a step of 1e-15 s between
# them would only cost a step.
SNAP = 1e-10


class StepGrid(NamedTuple):
    """One experiment's model steps and the control inside each: NumPy arrays, float64."""

    start: np.ndarray  # (N,) step start times
    length: np.ndarray  # (N,) step lengths (> 0)
    value: np.ndarray  # (N, 3) the control at the step's start (zeros without a control)
    slope: np.ndarray  # (N, 3) its rate inside the step (zero when held)
    sample_node: np.ndarray  # (n,) int: the node (0 … N) at each sample time
    # (2, 2, 3): the control before the first and after the last node, as (value at that node, slope),
    # for the states a delayed sensor reads just outside the record.
    edges: np.ndarray


def step_grid(t, control, hold, max_step) -> StepGrid:
    """The steps of one experiment: every sample and control time inside ``[t[0], t[-1]]`` is a node,
    and each gap between nodes is cut into equal steps of at most ``max_step``.

    ``control`` is ``(t_c (m,), tau_c (m, 3))`` or None; ``hold`` is ``"linear"`` or
    ``"previous"`` (see `jaxrot.Experiment`).

    Example:
        >>> import numpy as np
        >>> g = step_grid(np.array([0.0, 1.0, 2.0]), (np.array([0.5]), np.ones((1, 3))), "previous", 0.6)
        >>> g.start.tolist(), g.value[:, 0].tolist(), g.sample_node.tolist()
        ([0.0, 0.5, 1.0, 1.5], [0.0, 1.0, 1.0, 1.0], [0, 2, 4])
    """
    t = np.asarray(t, np.float64)
    tol = SNAP * (t[-1] - t[0])
    nodes = t
    if control is not None:
        t_c = np.asarray(control[0], np.float64)
        inside = t_c[(t_c > t[0] + tol) & (t_c < t[-1] - tol)]
        # The nearest sample time by bisection (t is increasing): the dense |inside − t| table of
        # 10 000 control times by 1 001 samples took ~1 s per experiment.
        right = np.clip(np.searchsorted(t, inside), 1, t.size - 1)
        nearest = np.minimum(np.abs(inside - t[right - 1]), np.abs(t[right] - inside))
        nodes = np.union1d(t, inside[nearest > tol])
    gaps = np.diff(nodes)
    counts = np.maximum(1, np.ceil(gaps / max_step * (1 - 1e-12))).astype(int)
    length = np.repeat(gaps / counts, counts)
    first = np.concatenate([[0], np.cumsum(counts)])  # the step index at each node
    within = np.arange(length.size) - np.repeat(first[:-1], counts)
    start = np.repeat(nodes[:-1], counts) + within * length
    sample_node = first[np.searchsorted(nodes, t)]
    value, slope = _control_in_steps(start, length, control, hold, tol)
    return StepGrid(start, length, value, slope, sample_node, _edges(t[0], t[-1], control, hold, tol))


def _edges(first, last, control, hold, tol):
    """The control just before ``first`` and just after ``last``: ``[[value, slope], [value, slope]]``."""
    edges = np.zeros((2, 2, 3))
    if control is None:
        return edges
    t_c = np.asarray(control[0], np.float64)
    tau_c = np.asarray(control[1], np.float64)
    for side, (at, probe) in enumerate(((first, first - tol), (last, last + tol))):
        if hold == "previous":
            held = np.searchsorted(t_c, probe, side="right") - 1
            edges[side, 0] = tau_c[held] if held >= 0 else 0.0
            continue
        edges[side, 0] = [np.interp(at, t_c, tau_c[:, i]) for i in range(3)]
        segment = np.searchsorted(t_c, probe, side="right") - 1
        if 0 <= segment < t_c.size - 1:
            edges[side, 1] = (tau_c[segment + 1] - tau_c[segment]) / (t_c[segment + 1] - t_c[segment])
    return edges


def _control_in_steps(start, length, control, hold, tol):
    """``(value at each step's start (N, 3), slope inside it (N, 3))`` of the control."""
    zeros = np.zeros((start.size, 3))
    if control is None:
        return zeros, zeros
    t_c = np.asarray(control[0], np.float64)
    tau_c = np.asarray(control[1], np.float64)
    if hold == "previous":
        held = np.searchsorted(t_c, start + tol, side="right") - 1  # the sample at or before the start
        value = np.where(held[:, None] >= 0, tau_c[np.maximum(held, 0)], 0.0)
        return value, zeros
    value = np.stack([np.interp(start, t_c, tau_c[:, i]) for i in range(3)], axis=-1)
    if t_c.size < 2:
        return value, zeros
    # Steps land on the control times, so each lies inside one segment: the one holding its midpoint.
    segment = np.searchsorted(t_c, start + 0.5 * length, side="right") - 1
    inside = (segment >= 0) & (segment < t_c.size - 1)
    j = np.clip(segment, 0, t_c.size - 2)
    rate = (tau_c[j + 1] - tau_c[j]) / (t_c[j + 1] - t_c[j])[:, None]
    return value, np.where(inside[:, None], rate, 0.0)


def pad_grid(grid: StepGrid, n_steps: int) -> StepGrid:
    """``grid`` padded to ``n_steps`` steps of length zero at its end (a step of length zero leaves the
    state as it is), holding the control after the record."""
    extra = n_steps - grid.length.size
    end = grid.start[-1] + grid.length[-1]
    return grid._replace(
        start=np.concatenate([grid.start, np.full(extra, end)]),
        length=np.concatenate([grid.length, np.zeros(extra)]),
        value=np.concatenate([grid.value, np.repeat(grid.edges[1, :1], extra, 0)]),
        slope=np.concatenate([grid.slope, np.repeat(grid.edges[1, 1:], extra, 0)]),
    )


class ControlledTorque(eqx.Module):
    """The user's torque model plus the experiment's control torque in the current step.

    Called with ``args = (user_args, (start, value (3,), slope (3,), body))``: the control is
    ``value + slope (t − start)``, a world-frame torque, or a body-frame one turned to the world
    frame by ``q`` where ``body`` is true. ``frames`` (static) is ``"world"``, ``"body"`` or
    ``"mixed"`` (experiments of both kinds under one ``vmap``: both are computed, one kept).
    """

    user: object = eqx.field(static=True)
    frames: str = eqx.field(static=True)

    def __call__(self, t, q, omega, args):
        user_args, (start, value, slope, body) = args
        control = value + slope * (t - start)
        if self.frames == "body":
            control = quat.rotate(q, control)
        elif self.frames == "mixed":
            control = jnp.where(body, quat.rotate(q, control), control)
        if self.user is None:
            return control
        return jnp.asarray(self.user(t, q, omega, user_args), control.dtype) + control
