"""`identify`'s first stage: every argument checked (each `ValueError` before anything compiles).

The result, `Settings`, is what the later stages read: nothing of the user's arguments
is consulted again after this stage.
"""

import math
from collections.abc import Sequence
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..._inertia import check_inertia_values
from ..._integrate._bind import INERTIAL, scheme_for_call
from ..._validation import check_int, check_torque
from ._experiment import KINDS, Experiment
from ._scheme import DEFAULT_SCHEME
from ._sensors import check_sensors


FLAGS = (True, False, "positive", "per_experiment")


class Leaf(NamedTuple):
    """One leaf of ``args``: its label, start value and how it is fitted."""

    label: str  # e.g. "args.dipole"
    value: Any  # identify's value (a jax array, or a non-array leaf held as it is)
    mode: str | None  # None (held), "free", "positive" or "per_experiment"
    per_experiment: np.ndarray | None  # (k, *shape) values per experiment (known or starting), or None


class Settings(NamedTuple):
    """`identify`'s checked arguments."""

    experiments: tuple
    torque: Any
    args: Any  # as the user gave them
    treedef: Any
    leaves: tuple  # of Leaf
    scheme: Any  # the scheme object
    scheme_arg: Any  # as the user gave it (reported back)
    free_inertia: Any  # True, "moments" or False
    inertia0: np.ndarray | None  # (3, 3)
    unit_scale: bool  # torque-free: only the tensor's shape is determined
    sensors: tuple  # of `_sensors.Sensor`
    q0: np.ndarray | None  # (k, 4) unit
    omega0: np.ndarray | None  # (k, 3)
    dt: float | None
    max_iter: int
    ftol: float
    rcond: float
    dtype: Any
    counts: np.ndarray  # (k, 3) observed samples per experiment and kind
    n_params: int
    scheme_default: bool = False  # the user named no scheme: `_scheme.choose_scheme` may size it

    @property
    def k(self) -> int:
        return len(self.experiments)

    @property
    def has_control(self) -> bool:
        return any(e.control is not None for e in self.experiments)


def label_of(path) -> str:
    """``"args.a[0].b"``-style label of a pytree path."""
    out = "args"
    for key in path:
        if isinstance(key, jax.tree_util.DictKey):
            out += f".{key.key}"
        elif isinstance(key, jax.tree_util.SequenceKey):
            out += f"[{key.idx}]"
        elif isinstance(key, jax.tree_util.GetAttrKey):
            out += f".{key.name}"
        else:
            out += str(key)
    return out


def _flags(args, free_args):
    """Per leaf of ``args``, its flag from ``free_args`` (a pytree like ``args`` or a dict naming keys)."""

    def walk(free, sub, where):
        if isinstance(free, dict):
            if not isinstance(sub, dict):
                raise ValueError(f"`free_args`{where} is a dict but `args`{where} is {type(sub).__name__}.")
            for key in free:
                if key not in sub:
                    raise ValueError(
                        f"`free_args` names {where}[{key!r}], which is not in `args` (its keys there: "
                        f"{sorted(sub)}). Add it to args with its starting value."
                    )
            return {key: walk(free.get(key, False), value, f"{where}[{key!r}]") for key, value in sub.items()}
        if isinstance(free, (list, tuple)) and not isinstance(free, str):
            if not isinstance(sub, (list, tuple)) or len(sub) != len(free):
                raise ValueError(f"`free_args`{where} must have the structure of `args`{where}.")
            pairs = enumerate(zip(free, sub, strict=True))
            return type(sub)(walk(f, s, f"{where}[{i}]") for i, (f, s) in pairs)
        if not any(free is flag or (isinstance(flag, str) and free == flag) for flag in FLAGS):
            raise ValueError(
                f"`free_args`{where} must be True (fitted), False (held), 'positive' (fitted, kept > 0) or "
                f"'per_experiment' (one fitted value per experiment); got {free!r}."
            )
        return jax.tree_util.tree_map(lambda _: free, sub)

    if free_args is None:
        return [False] * len(jax.tree_util.tree_leaves(args))
    flags = jax.tree_util.tree_leaves(walk(free_args, args, ""), is_leaf=lambda x: x in FLAGS)
    if len(flags) != len(jax.tree_util.tree_leaves(args)):
        raise ValueError("`free_args` must have the structure of `args` (or a dict naming some of its keys).")
    return flags


def _per_experiment_values(args, experiments, paths, dtype):
    """``{leaf index: (k, *shape)}`` for the leaves that some experiment's ``args`` gives."""
    given = [e.args for e in experiments]
    if not any(given):
        return {}
    if not isinstance(args, dict):
        raise ValueError(
            "Experiments give their own `args`, so identify's `args` must be a dict holding every key they "
            f"name; it is {type(args).__name__}."
        )
    out = {}
    for j, known in enumerate(given):
        for key, value in known.items():
            if key not in args:
                raise ValueError(
                    f"experiments[{j}].args names {key!r}, which is not in identify's `args` (its keys: "
                    f"{sorted(args)}): experiment args must be a subset of args, with the same shapes."
                )
            shared = jax.tree_util.tree_structure(args[key])
            if jax.tree_util.tree_structure(value) != shared:
                raise ValueError(
                    f"experiments[{j}].args[{key!r}] must have the structure of args[{key!r}] ({shared})."
                )
            for leaf, mine in zip(
                jax.tree_util.tree_leaves(args[key]), jax.tree_util.tree_leaves(value), strict=True
            ):
                if np.shape(leaf) != np.shape(mine):
                    raise ValueError(
                        f"experiments[{j}].args[{key!r}] has shape {np.shape(mine)} where args[{key!r}] has "
                        f"{np.shape(leaf)}."
                    )
    leaves = jax.tree_util.tree_leaves(args)
    for index, path in enumerate(paths):
        key = path[0].key
        if not any(key in known for known in given):
            continue
        stacked = []
        for known in given:
            if key in known:
                offset = [p for p in paths if p[0].key == key].index(path)
                stacked.append(np.asarray(jax.tree_util.tree_leaves(known[key])[offset], np.float64))
            else:
                stacked.append(np.asarray(leaves[index], np.float64))
        out[index] = np.stack(stacked)
    return out


def check_arguments(
    experiments, *, torque, args, free_args, inertia0, free_inertia, scheme, dt, q0, omega0, max_iter, ftol,
    rcond, sensors,
) -> Settings:  # fmt: skip
    """Check all of `identify`'s arguments; `Settings` for the later stages."""
    experiments = [experiments] if isinstance(experiments, Experiment) else experiments
    if not isinstance(experiments, Sequence) or not experiments:
        raise ValueError("`experiments` must be a jaxrot.Experiment or a non-empty sequence of them.")
    if not all(isinstance(e, Experiment) for e in experiments):
        raise ValueError("`experiments` must be a jaxrot.Experiment or a non-empty sequence of them.")
    experiments = tuple(experiments)
    k = len(experiments)
    check_torque(torque)
    scheme_default = scheme is None
    scheme = DEFAULT_SCHEME if scheme is None else scheme
    scheme_obj, _ = scheme_for_call(scheme, INERTIAL)  # a body in vacuum: the model identify fits
    max_iter = check_int(max_iter, "max_iter", 1)
    if free_inertia not in (True, False, "moments"):
        raise ValueError(
            f"`free_inertia` must be True (the tensor), 'moments' or False; got {free_inertia!r}."
        )
    if not (np.isfinite(ftol) and ftol >= 0):
        raise ValueError(f"`ftol` must be a finite number >= 0; got {ftol}.")

    arrays = [x for e in experiments for x in (e.t, e.q, e.omega_body, e.direction) if x is not None]
    dtype = jnp.result_type(*arrays)
    dtype = jnp.dtype(dtype if jnp.issubdtype(dtype, jnp.floating) else jnp.result_type(float))
    rcond = math.sqrt(float(jnp.finfo(dtype).eps)) if rcond is None else float(rcond)

    paths_leaves = jax.tree_util.tree_flatten_with_path(args)[0]
    paths = [path for path, _ in paths_leaves]
    flags = _flags(args, free_args)
    per_values = _per_experiment_values(args, experiments, paths, dtype)
    leaves = []
    for index, ((path, leaf), flag) in enumerate(zip(paths_leaves, flags, strict=True)):
        label = label_of(path)
        mode = {True: "free", False: None, "positive": "positive", "per_experiment": "per_experiment"}[flag]
        value = jnp.asarray(leaf)
        if mode is not None and not np.all(np.isfinite(np.asarray(leaf))):
            raise ValueError(f"`{label}` must be finite to be fitted.")
        if mode == "positive" and not np.all(np.asarray(leaf) > 0):
            raise ValueError(f"`{label}` is declared positive in free_args but starts at {leaf}.")
        if mode in ("free", "positive") and index in per_values:
            raise ValueError(
                f"`{label}` is fitted as one value shared by all experiments, but some experiment gives its "
                "own value in Experiment.args: mark it 'per_experiment' in free_args (one fitted value per "
                "experiment, starting from those), or drop it from the experiments' args."
            )
        own = per_values.get(index)
        if mode == "per_experiment" and own is None:
            own = np.broadcast_to(np.asarray(leaf, np.float64), (k, *np.shape(leaf))).copy()
        leaves.append(Leaf(label, value, mode, own))
    if any(leaf.mode is not None for leaf in leaves) and torque is None:
        raise ValueError("`free_args` marks arguments to fit, but there is no `torque` model that uses them.")
    if any(leaf.per_experiment is not None for leaf in leaves) and torque is None:
        raise ValueError("Experiments give their own `args`, but there is no `torque` model that uses them.")

    sensors = check_sensors(sensors, experiments)
    for sensor in sensors:
        if sensor.name == "gyro_scale" and not sensor.fitted and np.any(sensor.value == 0):
            raise ValueError("`sensors['gyro_scale']` must be nonzero on every axis (1: a perfect gyro).")

    unit_scale = (
        free_inertia is not False and torque is None and not any(e.control is not None for e in experiments)
    )
    if inertia0 is not None:
        inertia0 = np.asarray(inertia0, np.float64)
        if inertia0.shape == (3,):
            inertia0 = np.diag(inertia0)
        if inertia0.shape != (3, 3):
            raise ValueError(
                f"`inertia0` must be a (3, 3) tensor or (3,) principal moments; got {inertia0.shape}."
            )
        check_inertia_values(inertia0, "inertia0")
    elif free_inertia is not True:
        raise ValueError(
            "`inertia0` is needed with free_inertia='moments' (its axes are held) or False (it is held)."
        )
    elif not any(np.sum(np.all(np.isfinite(e.q), axis=-1)) >= 3 for e in experiments if e.q is not None):
        raise ValueError(
            "`inertia0` is needed: no experiment has 3 or more orientation samples to estimate it from."
        )
    q0 = _starts(q0, "q0", k, 4)
    if q0 is not None:
        q0 = q0 / np.linalg.norm(q0, axis=-1, keepdims=True)
    omega0 = _starts(omega0, "omega0", k, 3)
    if dt is not None:
        dt = float(dt)
        if not (np.isfinite(dt) and dt > 0):
            raise ValueError(f"`dt` must be a finite time step > 0; got {dt}.")

    counts = np.array([[e.counts[name] for name, _, _, _ in KINDS] for e in experiments])
    n_inertia = {True: 6, "moments": 3, False: 0}[free_inertia] - (1 if unit_scale else 0)
    n_args = sum(
        int(np.size(leaf.value)) * (k if leaf.mode == "per_experiment" else 1)
        for leaf in leaves
        if leaf.mode is not None
    )
    n_sensors = sum(s.size * (k if s.kind.per_experiment else 1) for s in sensors)
    n_params = n_inertia + n_args + n_sensors + 6 * k
    m_info = int(np.sum(counts * np.array([d for _, _, _, d in KINDS])))
    if m_info <= n_params:
        raise ValueError(
            f"The experiments hold {m_info} informative residuals for {n_params} parameters: add samples or "
            "fix parameters."
        )
    treedef = jax.tree_util.tree_structure(args)
    return Settings(
        experiments, torque, args, treedef, tuple(leaves), scheme_obj, scheme, free_inertia, inertia0,
        unit_scale, sensors, q0, omega0, dt, max_iter, float(ftol), rcond, dtype, counts, n_params,
        scheme_default,
    )  # fmt: skip


def _starts(value, name, k, width):
    if value is None:
        return None
    value = np.asarray(value, np.float64)
    if value.shape != (k, width) or not np.all(np.isfinite(value)):
        raise ValueError(
            f"`{name}` must be a finite ({k}, {width}) array, one row per experiment; got {value.shape}."
        )
    return value
