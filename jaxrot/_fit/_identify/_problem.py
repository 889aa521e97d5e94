"""`identify`'s third stage: the model and its starting parameter vector ``φ₀``.

The experiments become padded arrays (`_model.Data`), the fitted and held
parameters a `_model.Layout`, the step grids of their controls and samples
`_controls.StepGrid`s, and the starts of `_start.Start` the vector ``φ₀``.
"""

from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from .._parameterisation import cholesky_from_inertia
from ._controls import ControlledTorque, pad_grid, step_grid
from ._experiment import KINDS
from ._model import INDEX, Data, Layout, Model, n_head, pad_rows


class Problem(NamedTuple):
    """The model at its start."""

    model: Model
    phi0: np.ndarray  # float64
    estimated: np.ndarray  # (k, 3) bool: σ of this experiment and kind to be estimated
    max_step: float  # the longest model step
    held: bool  # some control is held (zero-order hold): a scheme that carries a torque restarts per step


def _inertia_coordinates(settings, start):
    """``(φ's inertia coordinates, the scale-free lead, the layout's tensor or axes)``."""
    if settings.free_inertia is True:
        coords = cholesky_from_inertia(start.inertia)
    elif settings.free_inertia == "moments":
        moments, axes = np.linalg.eigh(start.inertia)
        s = np.maximum(0.5 * (moments.sum() - 2 * moments), 1e-6 * moments.max())
        coords = np.sqrt(s)
    else:
        coords = np.zeros(0)
    lead = 1.0
    if settings.unit_scale:
        coords = coords[1:] / coords[0]
    held = {True: np.eye(3), False: start.inertia}.get(settings.free_inertia)
    if settings.free_inertia == "moments":
        held = axes
    return coords, lead, held


def build_problem(settings, start) -> Problem:
    """The `Problem` of these settings from this start."""
    k, dtype, experiments = settings.k, settings.dtype, settings.experiments
    cast = lambda x: jnp.asarray(np.stack(x), dtype)  # noqa: E731

    grids = [step_grid(e.t, e.control, e.control_hold, start.max_step) for e in experiments]
    n_steps = max(g.length.size for g in grids)
    grids = [pad_grid(g, n_steps) for g in grids]
    n_max = max(e.t.shape[0] for e in experiments)

    fill = {"q": np.array([1.0, 0, 0, 0]), "omega_body": np.zeros(3), "direction": np.zeros(3)}
    obs = {name: [] for name in fill}
    weights, sigmas = [], []
    for e in experiments:
        # Raw readings: the model reads like the sensors (`_model`), held parameters and all.
        observed = {"q": e.q, "omega_body": e.omega_body, "direction": e.direction}
        w_kinds, s_kinds = [], []
        for name, sigma_name, _, _ in KINDS:
            x = observed[name]
            if x is None:
                data, w = np.tile(fill[name], (e.t.shape[0], 1)), np.zeros(e.t.shape[0])
            else:
                w = np.all(np.isfinite(x), axis=-1).astype(np.float64)
                data = np.where(w[:, None] > 0, np.nan_to_num(np.asarray(x, np.float64)), fill[name])
                if name == "q":
                    data = data / np.linalg.norm(data, axis=-1, keepdims=True)
            obs[name].append(pad_rows(data, n_max))
            w_kinds.append(np.concatenate([w, np.zeros(n_max - w.shape[0])]))
            s_kinds.append(getattr(e, sigma_name) or 1.0)
        weights.append(np.stack(w_kinds))
        sigmas.append(s_kinds)
    estimated = np.array(
        [[getattr(e, s) is None and settings.counts[j, a] > 0 for a, (_, s, _, _) in enumerate(KINDS)]
         for j, e in enumerate(experiments)]
    )  # fmt: skip

    frames = {e.control_frame for e in experiments if e.control is not None}
    controlled = bool(frames)
    held_bias = [s.value for s in settings.sensors if s.name == "gyro_bias" and not s.fitted]
    known_leaves = tuple(
        i for i, leaf in enumerate(settings.leaves) if leaf.per_experiment is not None and leaf.mode is None
    )
    data = Data(
        t=cast([pad_rows(e.t.astype(np.float64), n_max) for e in experiments]),
        sample_node=jnp.asarray(np.stack([pad_rows(g.sample_node, n_max) for g in grids]), INDEX),
        step_start=cast([g.start for g in grids]),
        step_length=cast([g.length for g in grids]),
        control_value=cast([g.value for g in grids]) if controlled else None,
        control_slope=cast([g.slope for g in grids]) if controlled else None,
        control_body=jnp.asarray([e.control_frame == "body" for e in experiments]) if controlled else None,
        control_edges=cast([g.edges for g in grids]) if controlled else None,
        q=cast(obs["q"]),
        omega_body=cast(obs["omega_body"]),
        direction=cast(obs["direction"]),
        weight=cast(weights),
        body_vector=cast(
            [e.body_vector if e.body_vector is not None else np.array([1.0, 0, 0]) for e in experiments]
        ),  # fmt: skip
        sigma=cast(sigmas),
        q_start=cast(list(start.q)),
        known=tuple(jnp.asarray(settings.leaves[i].per_experiment, dtype) for i in known_leaves),
        held_bias=jnp.asarray(held_bias[0], dtype) if held_bias else None,
    )

    coords, lead, held_inertia = _inertia_coordinates(settings, start)
    values = [leaf.value for leaf in settings.leaves]
    layout = Layout(
        inertia_mode={True: "tensor", "moments": "moments", False: "fixed"}[settings.free_inertia],
        unit_scale=settings.unit_scale,
        n_inertia=int(coords.size),
        shared_leaves=tuple(
            (i, leaf.mode == "positive")
            for i, leaf in enumerate(settings.leaves)
            if leaf.mode in ("free", "positive")
        ),
        own_leaves=tuple(i for i, leaf in enumerate(settings.leaves) if leaf.mode == "per_experiment"),
        known_leaves=known_leaves,
        sensors=tuple((s.name, s.fitted) for s in settings.sensors),
        treedef=settings.treedef,
        n_experiments=k,
        inertia0=jnp.asarray(held_inertia, dtype),
        lead=jnp.asarray(lead, dtype),
        trace0=jnp.asarray(start.trace0, dtype),
        leaves=tuple(
            jnp.asarray(v, dtype) if jnp.issubdtype(jnp.asarray(v).dtype, jnp.floating) else v for v in values
        ),
        held_sensors={
            s.name: jnp.asarray(s.value, dtype)
            for s in settings.sensors
            if not s.fitted and not s.kind.per_experiment
        },  # fmt: skip
    )
    torque = settings.torque
    if controlled:
        torque = ControlledTorque(settings.torque, frames.pop() if len(frames) == 1 else "mixed")
    held = any(e.control is not None and e.control_hold == "previous" for e in experiments)
    reinit = held and settings.scheme.torque_evals_at_init > 0
    active = jnp.asarray(n_steps, INDEX)
    model = Model(
        data=data, layout=layout, scheme=settings.scheme, torque=torque, reinit=reinit, active=active
    )

    head = [coords]
    for index, positive in layout.shared_leaves:
        value = np.asarray(settings.leaves[index].value, np.float64)
        head.append((np.log(value) if positive else value).ravel())
    fitted = {s.name: s.value for s in settings.sensors if s.fitted}
    head += [np.ravel(fitted[name]) for name in ("gyro_scale", "gyro_delay", "tracker_mount", "tracker_delay")
             if name in fitted]  # fmt: skip
    blocks = []
    for j in range(k):
        block = [np.zeros(3), start.omega[j]]
        block += [np.ravel(settings.leaves[i].per_experiment[j]) for i in layout.own_leaves]
        if "gyro_bias" in fitted:
            block.append(fitted["gyro_bias"][j])
        blocks.append(np.concatenate(block))
    phi0 = np.concatenate([*head, *blocks]).astype(np.float64)
    assert phi0.size == settings.n_params and n_head(layout) == sum(h.size for h in head)
    max_step = max(float(np.max(g.length)) for g in grids)
    return Problem(model, phi0, estimated, max_step, held)
