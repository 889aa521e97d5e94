"""`identify`'s fifth stage: the labelled parameters, their covariance and standard errors.

``Cov(φ̂) ≈ (JᵀJ)⁻¹`` of the whitened residuals at the optimum (`_covariance.analyse`),
carried to the user's units by the delta method through ``∂p/∂φ`` (forward mode, exact);
parameters that an undetermined direction moves are named and get infinite errors.
Every parameter has a typical size (``scale``) in its own units, against which "moves"
and "too wide to mean anything" are judged.
"""

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._covariance import analyse, propagate
from ._model import split, unpack
from ._sensors import ARGS_UNIT, INERTIA_UNIT, RATE_UNIT, SENSORS, sensor_labels


ELEMENTS = ((0, 1, 2, 0, 0, 1), (0, 1, 2, 1, 2, 2))


class Uncertainties(NamedTuple):
    names: tuple
    units: tuple
    estimates: np.ndarray  # the labelled parameters' values (q0 rotations: 0, the offset from the fit)
    covariance: np.ndarray
    unidentified: tuple
    fitted: tuple  # (inertia, args, q0, omega0, sensors) at the optimum
    stderr: tuple  # the same fields' standard errors (0 where held, inf where undetermined)
    parameter_jacobian: np.ndarray  # (p, n) ∂(labelled parameters)/∂φ
    kept: int  # directions of the column-scaled Jacobian the covariance keeps
    raw_singular_values: np.ndarray  # of the unscaled Jacobian (the optimiser's view)


def element_labels(base, shape):
    """``base[i,j]`` for every index of ``shape`` (just ``base`` for a scalar)."""
    if shape == ():
        return [base]
    return [f"{base}[{','.join(map(str, idx))}]" for idx in np.ndindex(*shape)]


def _size(x):
    size = float(np.max(np.abs(np.asarray(x, np.float64)), initial=0.0)) if np.size(x) else 0.0
    return size if size > 0 else 1.0


def _sensor_scale(name, settings, fitted_sensors):
    """A sensor parameter's typical size: what an error as large would mean it is not determined."""
    spacing = float(np.mean([np.mean(np.diff(e.t)) for e in settings.experiments]))
    rates = [np.nanmax(np.abs(e.omega_body)) for e in settings.experiments if e.counts["omega_body"]]
    return {
        "gyro_bias": max(rates, default=1.0) or 1.0,
        "gyro_scale": 1.0,
        "gyro_delay": spacing,
        "tracker_mount": 1.0,
        "tracker_delay": spacing,
    }[name]


def _labels(settings, fitted):
    """``(names, units, scales)`` of the labelled parameters, in the order of ``φ``."""
    inertia, args, _, omega0, sensors = fitted
    inertia_scale = max(np.trace(inertia) / 3, np.finfo(np.float64).tiny)
    names, units, scale = [], [], []

    def add(labels, unit, size):
        names.extend(labels)
        units.extend([unit] * len(labels))
        scale.extend([size] * len(labels) if np.ndim(size) == 0 else list(size))

    # Without a torque only the shape is determined, in the scale of inertia0's trace.
    inertia_unit = "(shape only)" if settings.unit_scale else INERTIA_UNIT
    if settings.free_inertia is True:
        add([f"inertia[{a},{b}]" for a, b in zip(*ELEMENTS, strict=True)], inertia_unit, inertia_scale)
    elif settings.free_inertia == "moments":
        add([f"moments[{a}]" for a in range(3)], inertia_unit, inertia_scale)
    leaves = jax.tree_util.tree_leaves(args)
    for index, leaf in enumerate(settings.leaves):
        if leaf.mode in ("free", "positive"):
            add(element_labels(leaf.label, np.shape(leaves[index])), ARGS_UNIT, _size(leaves[index]))
    for sensor in settings.sensors:
        if sensor.fitted and not sensor.kind.per_experiment:
            add(sensor_labels(sensor), sensor.kind.unit, _sensor_scale(sensor.name, settings, sensors))
    for j in range(settings.k):
        add([f"q0[{j}].rotation[{a}]" for a in range(3)], "rad", 1.0)
        add([f"omega0[{j},{a}]" for a in range(3)], RATE_UNIT, max(float(np.linalg.norm(omega0[j])), 1e-12))
        for index, leaf in enumerate(settings.leaves):
            if leaf.mode == "per_experiment":
                value = np.asarray(leaves[index])[j]
                labels = [f"{leaf.label}[{j}{',' if s else ''}{s}]" for s in
                          [",".join(map(str, i)) for i in np.ndindex(*np.shape(value))]]  # fmt: skip
                add(labels, ARGS_UNIT, _size(value))
        for sensor in settings.sensors:
            if sensor.fitted and sensor.kind.per_experiment:
                add(sensor_labels(sensor, j), sensor.kind.unit, _sensor_scale(sensor.name, settings, sensors))
    return tuple(names), tuple(units), np.asarray(scale, np.float64)


@eqx.filter_jit
def _parameter_jacobians(phi, layout, data, free_inertia):
    """``∂p/∂φ`` of the labelled parameters, ``∂(all fields)/∂φ``, and the fitted fields."""

    def user_values(phi):
        inertia, args, _, _, _ = unpack(phi, layout, data)
        head, own = split(phi, layout)
        parts = []
        if free_inertia is True:
            parts.append(inertia[ELEMENTS])
        elif free_inertia == "moments":
            parts.append(jnp.einsum("ji,jk,ki->i", layout.inertia0, inertia, layout.inertia0))
        leaves = jax.tree_util.tree_leaves(args)
        parts.extend(leaves[i].ravel() for i, _ in layout.shared_leaves)
        rest = head[layout.n_inertia + sum(layout.leaves[i].size for i, _ in layout.shared_leaves) :]
        parts.append(rest)  # the shared sensors are their own coordinates
        for j in range(layout.n_experiments):
            parts.append(own[j])  # δq₀ (the rotation's coordinates), ω₀, own leaves, gyro bias: as they are
        return jnp.concatenate(parts)

    def all_values(phi):
        inertia, args, q0, omega0, sensors = unpack(phi, layout, data)
        leaves = [jnp.ravel(leaf) for leaf in jax.tree_util.tree_leaves(args)]
        ordered = [jnp.ravel(sensors[name]) for name in SENSORS if name in sensors]
        return jnp.concatenate([inertia.ravel(), *leaves, q0.ravel(), omega0.ravel(), *ordered])

    values = user_values(phi)
    return jax.jacfwd(user_values)(phi), jax.jacfwd(all_values)(phi), unpack(phi, layout, data), values


def uncertainty(solution, settings) -> Uncertainties:
    """The `Uncertainties` of a `_solve.Solution`."""
    model = solution.model
    dtype = settings.dtype
    g, g_all, fitted, g_values = _parameter_jacobians(
        jnp.asarray(solution.phi, dtype), model.layout, model.data, settings.free_inertia
    )
    fitted = jax.tree_util.tree_map(lambda x: np.asarray(x, np.float64), fitted)
    inertia, args, q0, omega0, sensors = fitted
    names, units, scale = _labels(settings, fitted)
    result = analyse(solution.jac, np.asarray(g, np.float64), scale, names, settings.rcond)

    # Every field's entries, and their typical sizes, in `all_values`' order.
    inertia_scale = max(np.trace(inertia) / 3, np.finfo(np.float64).tiny)
    leaves = jax.tree_util.tree_leaves(args)
    sizes = [np.full(9, inertia_scale), *[np.full(np.size(leaf), _size(leaf)) for leaf in leaves]]
    sizes += [np.ones(4 * settings.k), np.repeat(np.maximum(np.linalg.norm(omega0, axis=-1), 1e-12), 3)]
    given = [name for name in SENSORS if name in sensors]
    sizes += [np.full(np.size(sensors[n]), _sensor_scale(n, settings, sensors)) for n in given]
    se_all = propagate(np.asarray(g_all, np.float64), result.cov_phi, result.null, np.concatenate(sizes))

    def take(size, shape):
        nonlocal se_all
        out, se_all = se_all[:size].reshape(shape), se_all[size:]
        return out

    se_inertia = take(9, (3, 3)) if settings.free_inertia is not False else (take(9, (3, 3)) * 0)
    se_leaves = []
    for leaf, value in zip(settings.leaves, leaves, strict=True):
        se = take(np.size(value), np.shape(value))
        se_leaves.append(se if leaf.mode is not None else np.zeros(np.shape(value)))
    se_q0 = take(4 * settings.k, (settings.k, 4))
    se_omega0 = take(3 * settings.k, (settings.k, 3))
    fitted_names = {s.name for s in settings.sensors if s.fitted}
    se_sensors = {}
    for name in given:
        se = take(np.size(sensors[name]), np.shape(sensors[name]))
        se_sensors[name] = se if name in fitted_names else np.zeros(np.shape(sensors[name]))
    stderr = (
        se_inertia,
        jax.tree_util.tree_unflatten(settings.treedef, se_leaves),
        se_q0,
        se_omega0,
        se_sensors,
    )
    estimates = np.array(g_values, np.float64)
    estimates[[name.startswith("q0[") for name in names]] = 0.0  # rotations from the fitted q0
    g = np.asarray(g, np.float64)
    return Uncertainties(
        names, units, estimates, result.covariance, result.unidentified, fitted, stderr, g, result.kept,
        result.raw_singular_values,
    )  # fmt: skip
