"""`identify`'s model: the parameter vector, the padded experiments, and the whitened residuals.

The optimiser works on one vector ``φ = [head | own₀ | own₁ | …]``. The head holds what all
experiments share: the inertia's coordinates, the shared free ``args`` leaves and the shared
fitted sensor parameters (gyro scale and delay, tracker mounting and delay); experiment
``j``'s own block holds ``δq₀`` (3), ``ω₀`` (3), its values of the ``"per_experiment"``
leaves and its gyro bias when fitted. Every ``φ`` is physical: the tensor comes from
`inertia_from_cholesky` (or, with the axes known, moments ``s₂+s₃, s₁+s₃, s₁+s₂`` of squared
second moments ``sᵢ = pᵢ²``), a positive argument is ``exp`` of its coordinate, and the
initial orientation is ``exp(δq₀) ⊗ q_start``.

Each experiment is stepped over its own `_controls.StepGrid` (steps on every sample and
control time); the experiments are padded to common numbers of steps and samples and run
under one ``vmap``: padded steps have length zero and padded samples weight 0, as do NaN
samples and absent kinds. A delayed sensor sees the state at ``t − delay``: one more step
from the node before that time.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ... import quaternion as quat
from ..._inertia import body_inertia
from ..._state import RotState
from .._misfit import signed_vector
from .._parameterisation import inertia_from_cholesky


# Step and sample indices: the default integer of the x64 setting, as `jnp.arange` makes them.
INDEX = jax.dtypes.canonicalize_dtype(jnp.int64)
SHARED_SENSORS = ("gyro_scale", "gyro_delay", "tracker_mount", "tracker_delay")  # in the head, this order


class Data(eqx.Module):
    """The experiments, padded to ``P + 1`` samples and ``N`` steps: leading axis ``k``."""

    t: jax.Array  # (k, P + 1) sample times
    sample_node: jax.Array  # (k, P + 1) int: the step grid's node at each sample
    step_start: jax.Array  # (k, N)
    step_length: jax.Array  # (k, N)
    control_value: jax.Array | None  # (k, N, 3) the control at each step's start
    control_slope: jax.Array | None  # (k, N, 3)
    control_body: jax.Array | None  # (k,) bool: a body-frame control
    control_edges: jax.Array | None  # (k, 2, 2, 3) before the first and after the last node: value, slope
    q: jax.Array  # (k, P + 1, 4)   NaN and absent samples replaced by the identity (weight 0)
    omega_body: jax.Array  # (k, P + 1, 3)
    direction: jax.Array  # (k, P + 1, 3)
    weight: jax.Array  # (k, 3, P + 1)  per kind (q, omega_body, direction): 1 observed, 0 not
    body_vector: jax.Array  # (k, 3)
    sigma: jax.Array  # (k, 3) noise standard deviation per kind (1 where absent)
    q_start: jax.Array  # (k, 4) the orientation δq₀ is measured from
    known: tuple  # per leaf of Layout.known_leaves, its held values (k, ...)
    held_bias: jax.Array | None  # (k, 3) a held gyro bias


class Layout(eqx.Module):
    """How ``φ`` maps to the physical parameters (static), and the fixed values it needs."""

    inertia_mode: str = eqx.field(static=True)  # "tensor", "moments" or "fixed"
    unit_scale: bool = eqx.field(static=True)  # torque-free: the tensor's scale is fixed, not fitted
    n_inertia: int = eqx.field(static=True)
    shared_leaves: tuple = eqx.field(static=True)  # ((leaf index, positive), ...) fitted, shared
    own_leaves: tuple = eqx.field(static=True)  # (leaf index, ...) fitted per experiment
    known_leaves: tuple = eqx.field(static=True)  # (leaf index, ...) held per experiment (Data.known)
    sensors: tuple = eqx.field(static=True)  # ((name, fitted), ...) in `_sensors.SENSORS` order
    treedef: object = eqx.field(static=True)
    n_experiments: int = eqx.field(static=True)
    inertia0: jax.Array  # (3, 3) fixed tensor ("fixed"), or the known axes ("moments")
    lead: jax.Array  # the fixed first inertia coordinate when unit_scale (L₀₀ or p₀)
    trace0: jax.Array  # the trace a scale-free tensor is given
    leaves: tuple  # args' leaves at the start (the held ones are used as they are)
    held_sensors: dict  # name: value of the held shared sensor parameters

    def fitted(self, name):
        return (name, True) in self.sensors

    def has(self, name):
        return (name, True) in self.sensors or (name, False) in self.sensors


class Model(eqx.Module):
    """Everything the residuals need: data, layout and the static configuration of the rollout."""

    data: Data
    layout: Layout
    scheme: object = eqx.field(static=True)
    torque: object = eqx.field(static=True)
    reinit: bool = eqx.field(static=True)  # a held control: no torque carried across a step's end
    active: jax.Array  # int32 (): the first this many steps run; later samples are out of the window
    # With a `_scheme.SchemeSwitch` as ``scheme``: which of its schemes runs, a runtime index (one program
    # serves them all); None for a plain scheme.
    choice: jax.Array | None = None


SENSOR_SIZES = {"gyro_bias": 3, "gyro_scale": 3, "gyro_delay": 1, "tracker_mount": 3, "tracker_delay": 1}


def n_head(layout):
    """Length of ``φ``'s shared head."""
    leaves = sum(layout.leaves[index].size for index, _ in layout.shared_leaves)
    return layout.n_inertia + leaves + sum(SENSOR_SIZES[n] for n in SHARED_SENSORS if layout.fitted(n))


def n_own(layout):
    """Length of each experiment's block of ``φ``."""
    leaves = sum(layout.leaves[index].size for index in layout.own_leaves)
    return 6 + leaves + (3 if layout.fitted("gyro_bias") else 0)


def split(phi, layout):
    """``φ`` as its head ``(n_head,)`` and the experiments' blocks ``(k, n_own)``."""
    i = n_head(layout)
    return phi[:i], phi[i:].reshape(layout.n_experiments, n_own(layout))


def inertia_of(phi_inertia, layout):
    """The body-frame tensor ``(3, 3)`` from its coordinates."""
    if layout.inertia_mode == "fixed":
        return layout.inertia0
    coords = phi_inertia
    if layout.unit_scale:
        coords = jnp.concatenate([layout.lead[None].astype(coords.dtype), coords])
    if layout.inertia_mode == "tensor":
        inertia = inertia_from_cholesky(coords, unit_trace=layout.unit_scale)
    else:
        s = coords**2
        moments = jnp.stack([s[1] + s[2], s[0] + s[2], s[0] + s[1]])
        axes = layout.inertia0.astype(coords.dtype)
        inertia = (axes * moments[None, :]) @ axes.T
        if layout.unit_scale:
            inertia = inertia / jnp.trace(inertia)
    return inertia * layout.trace0 if layout.unit_scale else inertia


def shared_values(head, layout):
    """``(inertia (3, 3), args leaves with the shared fitted ones set, shared sensor values)`` of the head."""
    i = layout.n_inertia
    inertia = inertia_of(head[:i], layout)
    leaves = list(layout.leaves)
    for index, positive in layout.shared_leaves:
        like = leaves[index]
        value = head[i : i + like.size].reshape(like.shape)
        leaves[index] = jnp.exp(value) if positive else value
        i += like.size
    sensors = dict(layout.held_sensors)
    for name in SHARED_SENSORS:
        if layout.fitted(name):
            size = SENSOR_SIZES[name]
            sensors[name] = head[i : i + size] if size > 1 else head[i]
            i += size
    return inertia, leaves, sensors


def own_values(own, layout, d):
    """``(δq₀, ω₀, {leaf index: value}, gyro bias or None)`` of one experiment's block and data ``d``."""
    values = {index: known for index, known in zip(layout.known_leaves, d.known, strict=True)}
    i = 6
    for index in layout.own_leaves:
        like = layout.leaves[index]
        values[index] = own[i : i + like.size].reshape(like.shape)
        i += like.size
    bias = own[i : i + 3] if layout.fitted("gyro_bias") else d.held_bias
    return own[:3], own[3:6], values, bias


def _assemble(head, own, q_start, layout):
    """``(inertia, args, sensors, q₀, ω₀)`` from the head and `own_values`' parts (one experiment's, or
    all of them with a leading axis ``k``)."""
    inertia, leaves, sensors = shared_values(head, layout)
    dq, omega0, values, bias = own
    for index, value in values.items():
        leaves[index] = value
    if bias is not None:
        sensors = sensors | {"gyro_bias": bias}
    q0 = quat.multiply(quat.exp(dq), q_start)
    return inertia, jax.tree_util.tree_unflatten(layout.treedef, leaves), sensors, q0, omega0


def _parameters(head, own, d, layout):
    """One experiment's ``(inertia, args, sensors, q₀, ω₀)`` from the head, its block and its data."""
    return _assemble(head, own_values(own, layout, d), d.q_start, layout)


def _step_args(model, d, user_args, j):
    """The torque's ``args`` in step ``j`` (the user's, and the control held or ramping there)."""
    if d.control_value is None:
        return user_args
    return user_args, (d.step_start[j], d.control_value[j], d.control_slope[j], d.control_body)


def _stepper(model):
    """The scheme the model runs: its own, or the one its runtime ``choice`` picks from a switch."""
    return model.scheme if model.choice is None else model.scheme.bind(model.choice)


def _node_states(model, inertia, args, q0, omega0, d):
    """The modelled states ``q (N + 1, 4)``, ``ω (N + 1, 3)`` at every node of the step grid."""
    scheme, torque = _stepper(model), model.torque

    def one(inner, j):
        def advance(inner):
            step_args = _step_args(model, d, args, j)
            if model.reinit:  # a carried torque is stale across a jump of the control
                inner = scheme.init(scheme.state(inner), d.step_start[j], inertia, torque, step_args)
            return scheme.step(inner, d.step_start[j], d.step_length[j], inertia, torque, step_args)

        # Steps past the window are skipped, not masked: the predicate is the same for every experiment
        # (not batched by their vmap), so the window's fit costs its share of the record.
        inner = jax.lax.cond(j < model.active, advance, lambda inner: inner, inner)
        return inner, scheme.state(inner)

    state0 = RotState(q0, omega0)
    carry = scheme.init(state0, d.step_start[0], inertia, torque, _step_args(model, d, args, 0))
    _, states = jax.lax.scan(one, carry, jnp.arange(d.step_start.shape[0]))
    return jnp.concatenate([q0[None], states.q]), jnp.concatenate([omega0[None], states.omega])


def _states_at(model, inertia, args, node_at, d, times):
    """The modelled states at arbitrary ``times`` ``(P + 1,)``: one step from the node before each
    (``node_at(indices) -> (q, ω)``, the nodes' states)."""
    scheme, torque = _stepper(model), model.torque
    node_t = jnp.concatenate([d.step_start, d.step_start[-1:] + d.step_length[-1:]])
    last = jnp.minimum(d.step_start.shape[0], model.active) - 1
    # Past the window the nodes hold its last state: those samples (weight 0) get a short step from it.
    times = jnp.minimum(times, node_t[last + 1])
    j = jnp.clip(jnp.searchsorted(node_t, times, side="right").astype(INDEX) - 1, 0, last)

    def one(j, s, q_j, omega_j):
        step_args = _step_args(model, d, args, j)
        if d.control_value is not None:  # outside the record, the control as it runs there
            edge = jnp.where(s < node_t[0], 0, 1)
            outside = (s < node_t[0]) | (s > node_t[-1])
            value = jnp.where(outside, d.control_edges[edge, 0], d.control_value[j])
            slope = jnp.where(outside, d.control_edges[edge, 1], d.control_slope[j])
            step_args = (args, (node_t[j], value, slope, d.control_body))
        carry = scheme.init(RotState(q_j, omega_j), node_t[j], inertia, torque, step_args)
        return scheme.state(scheme.step(carry, node_t[j], s - node_t[j], inertia, torque, step_args))

    q_nodes, omega_nodes = node_at(j)
    states = jax.vmap(one)(j, times, q_nodes, omega_nodes)
    return states.q, states.omega


def _one(head, own, d, model, node_at=None):
    """One experiment's whitened misfits ``(3 kinds, P + 1, 3)`` and modelled states at its samples.

    ``node_at(indices) -> (q, ω)``: the states at the step grid's nodes, when the caller has them
    (`residuals_and_jacobian`); None: rolled out here."""
    layout = model.layout
    inertia, args, sensors, q0, omega0 = _parameters(head, own, d, layout)
    prepared = body_inertia(inertia)
    if node_at is None:
        nodes = _node_states(model, prepared, args, q0, omega0, d)
        node_at = lambda j: (nodes[0][j], nodes[1][j])  # noqa: E731
    q, omega = node_at(d.sample_node)

    q_seen = q
    if layout.has("tracker_delay"):
        q_seen, _ = _states_at(model, prepared, args, node_at, d, d.t - sensors["tracker_delay"])
    if layout.has("tracker_mount"):
        q_seen = quat.multiply(q_seen, quat.exp(sensors["tracker_mount"])[None, :])
    q_gyro, omega_gyro = q, omega
    if layout.has("gyro_delay"):
        q_gyro, omega_gyro = _states_at(model, prepared, args, node_at, d, d.t - sensors["gyro_delay"])
    gyro = quat.rotate(quat.conjugate(q_gyro), omega_gyro)
    if layout.has("gyro_scale"):
        gyro = sensors["gyro_scale"][None, :] * gyro
    if "gyro_bias" in sensors:
        gyro = gyro + sensors["gyro_bias"][None, :]

    r_q = signed_vector(q_seen, d.q)
    r_omega = gyro - d.omega_body
    r_direction = quat.rotate(q, d.body_vector[None, :]) - d.direction
    weight = d.weight * (d.sample_node <= model.active).astype(d.weight.dtype)[None, :]
    r = jnp.stack([r_q, r_omega, r_direction]) * (weight / d.sigma[:, None])[..., None]
    return r, q, omega


def states(phi, model):
    """Modelled ``q (k, P + 1, 4)``, ``ω (k, P + 1, 3)`` (world frame) at every padded sample."""
    head, own = split(phi, model.layout)
    _, q, omega = jax.vmap(lambda own, d: _one(head, own, d, model))(own, model.data)
    return q, omega


def residuals(phi, model):
    """The whitened residual vector (each misfit over its noise σ) whose sum of squares is minimised.

    Experiment-major: experiment ``j``'s ``3 (P + 1) 3`` misfits, kind by kind, then ``j + 1``'s.
    """
    head, own = split(phi, model.layout)
    r, _, _ = jax.vmap(lambda own, d: _one(head, own, d, model))(own, model.data)
    return r.reshape(-1)


def pad_rows(x, length):
    """``x`` ``(n, ...)`` padded to ``length`` rows by repeating its last row."""
    return np.concatenate([x, np.repeat(x[-1:], length - x.shape[0], axis=0)])


def unpack(phi, layout, data):
    """All fitted values: ``(inertia (3, 3), args, q₀ (k, 4), ω₀ (k, 3), sensors)``; per-experiment leaves
    of ``args`` and the gyro bias with a leading axis ``k``."""
    head, own = split(phi, layout)
    parts = jax.vmap(lambda o, d: own_values(o, layout, d))(own, data)
    inertia, args, sensors, q0, omega0 = _assemble(head, parts, data.q_start, layout)
    return inertia, args, q0, omega0, sensors
