"""`identify`: a rigid body's parameters from several experiments' telemetry, with their uncertainty."""

import math
import warnings
from collections.abc import Sequence
from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import quaternion as quat
from .._state import Trajectory
from .._validation import check_inertia_values, check_int, check_torque, sign_continuous
from ..schemes import RKMKDopri5, resolve_scheme
from ._experiment import KINDS, Experiment
from ._identify_model import (
    ControlledTorque,
    Data,
    Layout,
    Model,
    pad_rows,
    residuals,
    residuals_and_jacobian,
    unpack,
)
from ._initial import _linear_estimate, estimate_omega, rotate_np
from ._optimiser import gauss_newton
from ._parameterisation import cholesky_from_inertia
from ._uncertainty import analyse, correlations, propagate


# The default scheme and step: see `identify`'s docstring for the measurements behind them.
DEFAULT_SCHEME = RKMKDopri5(chart="cayley")
DEFAULT_STEP_ANGLE = 0.6  # rad turned per step at the largest |ω| seen


class StandardErrors(NamedTuple):
    """Standard errors of `Identification`'s fields in their units: 0 where fixed, inf where undetermined."""

    inertia: np.ndarray  # (3, 3)
    args: Any  # a pytree like args
    q0: np.ndarray  # (k, 4)
    omega0: np.ndarray  # (k, 3)


class Identification(NamedTuple):
    """What `jaxrot.identify` found.

    Attributes:
        inertia: fitted body-frame tensor ``(3, 3)``; without any torque (no
            ``torque``, no ``control``) only its shape is determined and it has the
            trace of ``inertia0`` (1 when not given): ``scale_determined`` False.
        args: the torque arguments with the fitted leaves replaced.
        q0: fitted initial orientation of each experiment ``(k, 4)``.
        omega0: fitted initial angular velocity of each experiment ``(k, 3)``, world frame.
        stderr: `StandardErrors` of the four fields above (delta method through
            the parameterisation; inf for anything an undetermined combination moves).
        covariance: ``(p, p)`` covariance of the labelled parameters ``names``, in
            their own units (the inertia's six distinct elements or the three
            moments, the free elements of ``args``, then per experiment the
            rotation vector of ``q0`` from its fitted value in rad and ``omega0``).
        names: the covariance's row labels, e.g. ``"inertia[0,1]"``, ``"args.dipole[2]"``,
            ``"q0[1].rotation[0]"``, ``"omega0[1,2]"``.
        correlation: the covariance as correlations ``(p, p)``.
        unidentified: labels of the parameters the data do not determine (an
            undetermined combination of the Jacobian's scaled columns moves them,
            or their standard error exceeds their own size); empty when all are.
        converged: Gauss–Newton stopped on its tolerance, not on ``max_iter``.
        sigma: the noise level used per experiment and kind ``(k, 3)``
            (``q``, ``omega_body``, ``direction``), given or estimated; NaN where absent.
        residuals: per experiment, a dict of the whitened misfits ``(n, 3)`` of each
            observed kind (NaN where a sample is missing).
        trajectories: per experiment, the fitted model at its sample times (`Trajectory`).
        loss: final sum of squared whitened residuals.
        loss_history: the sum before each Gauss–Newton iteration and at the end.
        n_iterations: Gauss–Newton iterations (both passes when σ was estimated).
        scale_determined: whether a torque fixes the tensor's scale.
        dt: the largest integrator step used.
        scheme: the scheme's name or object.
    """

    inertia: jax.Array
    args: Any
    q0: jax.Array
    omega0: jax.Array
    stderr: StandardErrors
    covariance: np.ndarray
    names: tuple
    correlation: np.ndarray
    unidentified: tuple
    converged: bool
    sigma: np.ndarray
    residuals: list
    trajectories: list
    loss: float
    loss_history: np.ndarray
    n_iterations: int
    scale_determined: bool
    dt: float
    scheme: Any


def _label(path) -> str:
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


def _element_labels(base, shape):
    if shape == ():
        return [base]
    return [f"{base}[{','.join(map(str, idx))}]" for idx in np.ndindex(*shape)]


def _free_mask(args, free_args):
    """Per leaf of ``args``: None (fixed), "free" or "positive"; checks ``free_args`` against ``args``."""
    leaves_with_path, treedef = jax.tree_util.tree_flatten_with_path(args)
    if free_args is None:
        return [None] * len(leaves_with_path), leaves_with_path, treedef

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
        if free not in (True, False, "positive"):
            raise ValueError(
                f"`free_args`{where} must be True (fitted), False (fixed) or 'positive' (fitted, kept > 0); "
                f"got {free!r}."
            )
        return jax.tree_util.tree_map(lambda _: free, sub)

    full = walk(free_args, args, "")
    flags = jax.tree_util.tree_leaves(full, is_leaf=lambda x: x in (True, False, "positive"))
    if len(flags) != len(leaves_with_path):
        raise ValueError("`free_args` must have the structure of `args` (or a dict naming some of its keys).")
    mask = [None if f is False else ("positive" if f == "positive" else "free") for f in flags]
    return mask, leaves_with_path, treedef


def _rotation_between(a, b):
    """A unit quaternion turning unit vector ``a`` onto ``b`` (the shortest arc)."""
    c = float(np.dot(a, b))
    if c < -1 + 1e-12:
        axis = np.cross(a, [1.0, 0, 0])
        axis = axis if np.linalg.norm(axis) > 1e-6 else np.cross(a, [0, 1.0, 0])
        return np.array([0.0, *(axis / np.linalg.norm(axis))])
    q = np.array([1 + c, *np.cross(a, b)])
    return q / np.linalg.norm(q)


def _finite_rows(x):
    return np.zeros(0, int) if x is None else np.flatnonzero(np.all(np.isfinite(x), axis=-1))


def _start_orientation(e):
    rows = _finite_rows(e.q)
    if rows.size:
        return np.asarray(e.q[rows[0]], np.float64)
    rows = _finite_rows(e.direction)
    if rows.size:
        return _rotation_between(e.body_vector.astype(np.float64), e.direction[rows[0]].astype(np.float64))
    return np.array([1.0, 0, 0, 0])


def _start_omega(e, q_start):
    rows = _finite_rows(e.omega_body)
    if rows.size:
        return rotate_np(q_start, np.asarray(e.omega_body[rows[0]], np.float64))
    rows = _finite_rows(e.q)
    if rows.size >= 3:
        return estimate_omega(e.t[rows[:3]], sign_continuous(e.q[rows[:3]]))[0]
    return np.zeros(3)


def _check_starts(value, name, k, width):
    if value is None:
        return None
    value = np.asarray(value, np.float64)
    if value.shape != (k, width) or not np.all(np.isfinite(value)):
        raise ValueError(
            f"`{name}` must be a finite ({k}, {width}) array, one row per experiment; got {value.shape}."
        )
    return value


def identify(
    experiments: Experiment | Sequence[Experiment],
    *,
    torque=None,
    args=None,
    free_args=None,
    inertia0=None,
    free_inertia: bool | str = True,
    scheme=DEFAULT_SCHEME,
    dt: float | None = None,
    q0=None,
    omega0=None,
    max_iter: int = 100,
    ftol: float = 1e-10,
    rcond: float | None = None,
) -> Identification:
    r"""Fit a rigid body's inertia, torque parameters and initial states to several experiments.

    The model steps each experiment with ``scheme`` from its fitted ``(q₀, ω₀)``
    under ``torque(t, q, ω, args)`` plus the experiment's known ``control``
    torque, and minimises the sum of squared whitened residuals
    (misfit / σ) of every observation (`jaxrot.Experiment`):

    - orientation: the rotation vector ``2 v sign(w)`` of ``q_obs* ⊗ q = (w, v)``
      (rad, sign invariant);
    - gyro: the body-frame angular velocity ``q* ⊗ ω ⊗ q − ω_b,obs``;
    - tracked axis: ``rotate(q, b) − d_obs`` (2 informative components).

    Fitted, jointly over all experiments: the inertia (``free_inertia=True``:
    the full tensor through `inertia_from_cholesky`, always positive definite
    with the triangle inequality; ``"moments"``: the principal moments, with the
    axes of ``inertia0`` held; ``False``: ``inertia0`` held), the leaves of
    ``args`` that ``free_args`` marks (True; ``"positive"`` keeps a leaf > 0
    through a log), and each experiment's ``q₀`` and ``ω₀``. Without any torque
    the tensor's scale is not determined: it keeps the trace of ``inertia0``.

    Optimiser: the Gauss–Newton of `fit_inertia` (forward-mode Jacobian through
    the rollout, Armijo backtracking, one compiled loop). Noise: a kind whose σ
    is None has it estimated from its residuals,
    ``σ² = RSS_kind / (m_kind (1 − n/m))`` (``m`` informative residuals, ``n``
    parameters); when several kinds are weighed against each other the fit is
    repeated once with the estimated σ.

    Uncertainty: ``Cov ≈ (JᵀJ)⁻¹`` at the optimum (whitened residuals), carried
    to the reported units by the delta method. Directions whose singular value
    of the column-scaled ``J`` falls below ``rcond`` (default √eps of the dtype)
    times the largest are undetermined: the parameters they move are listed in
    ``unidentified``, get infinite standard errors and a warning.

    Default scheme: ``RKMKDopri5(chart="cayley")`` (fifth-order Lie-group Runge–Kutta
    in Cayley coordinates, `jaxrot.schemes.RKMKDopri5`) at steps turning the body by at
    most 0.6 rad at the largest ``|ω|`` seen. Measured on the three-manoeuvre satellite
    of ``tests/_telemetry.py`` (noise-free data from the reference solver, 5 s sample
    spacing, |ω| ≤ 0.12 rad/s; bias = the largest parameter error in standard errors of
    the noisy fit; 2-core CPU, float64, one run each, so fit times within ±20 % are
    noise; reproduced by ``benchmarks/identify_schemes.py``):

    ===========  ==========  ========  =================  =======  ==============
    scheme       step (rad)  substeps  bias / std. error  fit (s)  first call (s)
    ===========  ==========  ========  =================  =======  ==============
    zhao         0.05        9         4.3                0.22     4.0
    zhao         0.2         3         38                 0.11     4.6
    rkmk4        0.05        9         8e-5               0.41     5.9
    rkmk4        0.2         3         0.0066             0.14     5.8
    rkmk4        0.5         1         0.6                0.10     —
    rkmk_dopri5  0.15        3         3e-5               0.25     5.7
    rkmk_dopri5  0.3         2         8e-5               0.17     5.7
    rkmk_dopri5  0.6         1         0.0015             0.10     5.2
    … cayley     0.3         2         2e-4               0.16     5.8
    … cayley     0.6         1         0.0066             0.11     4.8
    splitting    0.05        9         0.46               0.33     12.2
    ===========  ==========  ========  =================  =======  ==============

    (``… cayley``: ``RKMKDopri5(chart="cayley")``.) Second-order schemes bias the fit by
    several standard errors at any step that runs as fast; the fifth-order pair at one
    step per sample leaves a bias under 1 % of a standard error with the fewest stages
    per sample (6, against ``rkmk4``'s 12 at 0.2 rad). Of its two charts, the Cayley
    map (rational, no trigonometry) biases 4× more (0.66 % of a standard error against
    0.15 %) and its Jacobian rollout, the cost of each iteration, runs 1.24× faster
    (8.45 against 10.46 ms, median of 15 interleaved rounds, same process).

    Args:
        experiments: one `jaxrot.Experiment` or a sequence of them.
        torque: world-frame torque model ``torque(t, q, omega, args) -> (3,)``
            (None: only the experiments' controls, or torque-free).
        args: its arguments, a pytree (e.g. a dict of arrays).
        free_args: which leaves of ``args`` are fitted: a pytree of True / False /
            ``"positive"`` with the structure of ``args``, or a dict naming some
            of its keys (the others fixed).
        inertia0: starting (or held) tensor ``(3, 3)`` or principal moments
            ``(3,)``; None: a linear angular-momentum estimate from the
            experiment with the most orientation samples.
        free_inertia: True, ``"moments"`` or False (see above).
        scheme: integrator name or object.
        dt: largest step (each sample interval is cut into equal steps).
        q0, omega0: starting initial states ``(k, 4)``, ``(k, 3)`` instead of
            those read from the data (needed when a record starts far from
            anything its observations suggest).
        max_iter: Gauss–Newton iteration cap (per pass).
        ftol: stop when the next step's predicted decrease is ``≤ ftol ×`` the
            objective, or the objective is at the round-off floor.
        rcond: singular-value ratio below which a direction is undetermined.

    Returns:
        `Identification`.

    Raises:
        ValueError: before any compilation, for a bad experiment, a ``free_args``
            naming what is not in ``args``, a bad ``inertia0`` or option.

    Example:
        >>> import jax.numpy as jnp, numpy as np, jaxrot
        >>> true = jaxrot.rollout("rkmk4", jaxrot.RotState(jnp.array([1.0, 0, 0, 0]),
        ...                       jnp.array([0.3, 0.1, 1.0])), jnp.array([1.0, 1.5, 2.0]), 0.01, 600,
        ...                       save_every=20)
        >>> exp = jaxrot.Experiment(true.t, q=true.q, sigma_q=1e-3)
        >>> fit = jaxrot.identify(exp)  # torque-free: the moments up to scale
        >>> m = np.linalg.eigvalsh(np.asarray(fit.inertia))
        >>> print((m / m[0]).round(4).tolist(), fit.converged)
        [1.0, 1.5, 2.0] True
    """
    experiments = [experiments] if isinstance(experiments, Experiment) else list(experiments)
    if not experiments or not all(isinstance(e, Experiment) for e in experiments):
        raise ValueError("`experiments` must be a jaxrot.Experiment or a non-empty sequence of them.")
    k = len(experiments)
    check_torque(torque)
    scheme_obj = resolve_scheme(scheme)
    max_iter = check_int(max_iter, "max_iter", 1)
    if free_inertia not in (True, False, "moments"):
        raise ValueError(
            f"`free_inertia` must be True (the tensor), 'moments' or False; got {free_inertia!r}."
        )
    if not (np.isfinite(ftol) and ftol >= 0):
        raise ValueError(f"`ftol` must be a finite number >= 0; got {ftol}.")
    mask, leaves_with_path, treedef = _free_mask(args, free_args)
    leaves = [jnp.asarray(leaf) for _, leaf in leaves_with_path]
    for (path, leaf), m in zip(leaves_with_path, mask, strict=False):
        if m is not None and not np.all(np.isfinite(np.asarray(leaf))):
            raise ValueError(f"`{_label(path)}` must be finite to be fitted.")
        if m == "positive" and not np.all(np.asarray(leaf) > 0):
            raise ValueError(f"`{_label(path)}` is declared positive in free_args but starts at {leaf}.")
    if any(m is not None for m in mask) and torque is None:
        raise ValueError("`free_args` marks arguments to fit, but there is no `torque` model that uses them.")

    arrays = [x for e in experiments for x in (e.t, e.q, e.omega_body, e.direction) if x is not None]
    dtype = jnp.result_type(*arrays)
    if not jnp.issubdtype(dtype, jnp.floating):
        dtype = jnp.result_type(float)
    dtype = jnp.dtype(dtype)
    eps = float(jnp.finfo(dtype).eps)
    rcond = math.sqrt(eps) if rcond is None else float(rcond)

    # --- the inertia's parameterisation and start ---
    has_control = any(e.control is not None for e in experiments)
    unit_scale = free_inertia is not False and torque is None and not has_control
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
    controlled = ControlledTorque(torque) if has_control else torque
    user_args0 = jax.tree_util.tree_unflatten(treedef, leaves)

    def run_args(e, user_args):
        if not has_control:
            return user_args
        t_c, tau_c = e.control if e.control is not None else (np.array([0.0]), np.zeros((1, 3)))
        return (user_args, jnp.asarray(t_c, dtype), jnp.asarray(tau_c, dtype))

    momentum, best = None, None
    if inertia0 is None:
        candidates = [i for i, e in enumerate(experiments) if _finite_rows(e.q).size >= 3]
        if not candidates:
            raise ValueError(
                "`inertia0` is needed: no experiment has 3 or more orientation samples to estimate it from."
            )
        best = max(candidates, key=lambda i: _finite_rows(experiments[i].q).size)
        e = experiments[best]
        rows = _finite_rows(e.q)
        q_rows = sign_continuous(e.q[rows])
        w_rows = _finite_rows(e.omega_body)
        if np.array_equal(w_rows, np.arange(e.t.shape[0])) and rows.size == e.t.shape[0]:
            omega_world = rotate_np(q_rows, np.asarray(e.omega_body, np.float64))
        else:
            omega_world = estimate_omega(e.t[rows], q_rows)
        start, momentum = _linear_estimate(
            e.t[rows].astype(np.float64), q_rows, omega_world, controlled, run_args(e, user_args0), dtype
        )
        start = 0.5 * (start + start.T)
        q_first = q_rows[0]
    else:
        start = inertia0
    trace0 = float(np.trace(start)) if inertia0 is not None else 1.0
    if free_inertia is True:
        coords = cholesky_from_inertia(start)
    elif free_inertia == "moments":
        moments, axes0 = np.linalg.eigh(start)
        s = np.maximum(0.5 * (moments.sum() - 2 * moments), 1e-6 * moments.max())
        coords = np.sqrt(s)
    else:
        coords = np.zeros(0)
    lead = 1.0
    if unit_scale:
        coords = coords[1:] / coords[0]
    layout_inertia0 = axes0 if free_inertia == "moments" else (start if free_inertia is False else np.eye(3))

    # --- the start of each experiment ---
    q_starts = np.stack([_start_orientation(e) for e in experiments])
    omega_starts = np.stack([_start_omega(e, q) for e, q in zip(experiments, q_starts, strict=False)])
    if momentum is not None and np.all(np.isfinite(momentum)):
        # ω₀ = R₀ I⁻¹ R₀ᵀ L₀ from the momentum fitted to all samples of that record: better than differences.
        if _finite_rows(experiments[best].q)[0] == 0:
            q_first = np.asarray(q_first, np.float64)
            q_first_inverse = q_first * np.array([1.0, -1.0, -1.0, -1.0])  # the conjugate
            scaled = start * (trace0 / np.trace(start)) if unit_scale else start
            momentum = momentum * (trace0 / np.trace(start)) if unit_scale else momentum
            body = np.linalg.solve(scaled, rotate_np(q_first_inverse, momentum))
            candidate = rotate_np(q_first, body)
            if np.all(np.isfinite(candidate)):
                omega_starts[best] = candidate
    q_starts = _check_starts(q0, "q0", k, 4) if q0 is not None else q_starts
    if q0 is not None:
        q_starts = q_starts / np.linalg.norm(q_starts, axis=-1, keepdims=True)
    omega_starts = _check_starts(omega0, "omega0", k, 3) if omega0 is not None else omega_starts

    # --- the padded data ---
    n_max = max(e.t.shape[0] for e in experiments)
    m_max = max((e.control[0].shape[0] for e in experiments if e.control is not None), default=1)
    fill = {"q": np.array([1.0, 0, 0, 0]), "omega_body": np.zeros(3), "direction": np.zeros(3)}
    t_rows, obs, weights, sigmas, body_vectors, controls_t, controls_tau = (
        [],
        {n: [] for n in fill},
        [],
        [],
        [],
        [],
        [],
    )
    counts = np.zeros((k, 3), int)
    for i, e in enumerate(experiments):
        t_rows.append(pad_rows(e.t.astype(np.float64), n_max))
        w_kinds, s_kinds = [], []
        for j, (name, sigma_name, _, _) in enumerate(KINDS):
            x = getattr(e, name)
            if x is None:
                data = np.tile(fill[name], (e.t.shape[0], 1))
                w = np.zeros(e.t.shape[0])
            else:
                w = np.all(np.isfinite(x), axis=-1).astype(np.float64)
                data = np.where(w[:, None] > 0, np.nan_to_num(x.astype(np.float64)), fill[name])
                if name == "q":
                    data = data / np.linalg.norm(data, axis=-1, keepdims=True)
            counts[i, j] = int(w.sum())
            obs[name].append(pad_rows(data, n_max))
            w_kinds.append(np.concatenate([w, np.zeros(n_max - w.shape[0])]))
            s_kinds.append(getattr(e, sigma_name) or 1.0)
        weights.append(np.stack(w_kinds))
        sigmas.append(s_kinds)
        body_vectors.append(e.body_vector if e.body_vector is not None else np.array([1.0, 0, 0]))
        if has_control:
            t_c, tau_c = e.control if e.control is not None else (np.array([e.t[0]]), np.zeros((1, 3)))
            extra = t_c[-1] + np.arange(1, m_max - t_c.shape[0] + 1)
            controls_t.append(np.concatenate([t_c, extra]))
            controls_tau.append(pad_rows(np.asarray(tau_c, np.float64), m_max))
    estimated = np.array(
        [
            [getattr(e, s) is None and counts[i, j] > 0 for j, (_, s, _, _) in enumerate(KINDS)]
            for i, e in enumerate(experiments)
        ]
    )
    cast = lambda x: jnp.asarray(np.stack(x), dtype)  # noqa: E731
    data = Data(
        t=cast(t_rows),
        q=cast(obs["q"]),
        omega_body=cast(obs["omega_body"]),
        direction=cast(obs["direction"]),
        weight=cast(weights),
        body_vector=cast(body_vectors),
        sigma=cast(sigmas),
        q_start=cast(list(q_starts)),
        control_t=cast(controls_t) if has_control else None,
        control_tau=cast(controls_tau) if has_control else None,
    )
    free_leaves = tuple((index, m == "positive") for index, m in enumerate(mask) if m is not None)
    layout = Layout(
        inertia_mode={True: "tensor", "moments": "moments", False: "fixed"}[free_inertia],
        unit_scale=unit_scale,
        n_inertia=int(coords.size),
        free_leaves=free_leaves,
        treedef=treedef,
        n_experiments=k,
        inertia0=jnp.asarray(layout_inertia0, dtype),
        lead=jnp.asarray(lead, dtype),
        trace0=jnp.asarray(trace0, dtype),
        leaves=tuple(
            jnp.asarray(leaf, dtype) if jnp.issubdtype(jnp.asarray(leaf).dtype, jnp.floating) else leaf
            for leaf in leaves
        ),
    )

    # --- the step ---
    spacing = max(float(np.max(np.diff(e.t))) for e in experiments)
    if dt is None:
        speeds = [np.linalg.norm(omega_starts, axis=-1).max()]
        for e in experiments:
            rows = _finite_rows(e.omega_body)
            if rows.size:
                speeds.append(np.linalg.norm(e.omega_body[rows], axis=-1).max())
            rows = _finite_rows(e.q)
            if rows.size >= 3:
                speeds.append(
                    np.linalg.norm(estimate_omega(e.t[rows], sign_continuous(e.q[rows])), axis=-1).max()
                )
        w_max = float(max(speeds))
        dt = DEFAULT_STEP_ANGLE / w_max if w_max > 0 else spacing
    dt = float(dt)
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"`dt` must be a finite time step > 0; got {dt}.")
    substeps = max(1, math.ceil(spacing / dt * (1 - 1e-12)))
    model = Model(data=data, layout=layout, scheme=scheme_obj, torque=controlled, substeps=substeps)

    phi0 = np.concatenate(
        [
            coords,
            *[
                np.log(np.asarray(leaves[i], np.float64)).ravel()
                if p
                else np.asarray(leaves[i], np.float64).ravel()
                for i, p in free_leaves
            ],
            np.zeros(3 * k),
            omega_starts.ravel(),
        ]
    )
    n_params = phi0.size
    dof = np.array([d for _, _, _, d in KINDS])
    m_info = int(np.sum(counts * dof))
    if m_info <= n_params:
        raise ValueError(
            f"The experiments hold {m_info} informative residuals for {n_params} parameters: add samples or "
            "fix parameters."
        )
    n_steps = (n_max - 1) * substeps
    speed = float(np.max(np.linalg.norm(omega_starts, axis=-1), initial=0.0))

    def floor_of(sigma):
        theta = (n_steps + 1) * eps
        sizes = np.array([theta, theta * speed, theta])
        return float(np.sum(counts * (sizes / sigma) ** 2))

    def run(phi, model):
        sigma = np.asarray(model.data.sigma, np.float64)
        z, history, n, converged, r, jac, fitted = gauss_newton(
            residuals,
            jnp.asarray(phi, dtype),
            model,
            jnp.asarray(ftol, dtype),
            jnp.asarray(floor_of(sigma), dtype),
            max_iter,
            minimum_norm=True,
            jacobian_fn=residuals_and_jacobian,
        )
        n = int(n)
        raw = np.asarray(r, np.float64).reshape(k, 3, n_max, 3) * sigma[:, :, None, None]
        history = np.asarray(history[: n + 1], np.float64)
        fitted = tuple(np.asarray(x, np.float64) for x in fitted)
        jac = np.asarray(jac, np.float64)
        return np.asarray(z, np.float64), history, n, bool(converged), raw, jac, fitted

    phi, history, n_iterations, converged, raw, jac, fitted = run(phi0, model)
    sigma = np.asarray(data.sigma, np.float64)
    if estimated.any():
        rss = np.sum(raw**2, axis=(2, 3))
        shrink = 1 - n_params / m_info
        theta = (n_steps + 1) * eps
        floor = np.array([theta, theta * max(speed, 1e-300), theta])
        estimate = np.sqrt(rss / np.maximum(counts * dof * shrink, 1))
        sigma = np.where(estimated, np.maximum(estimate, floor), sigma)
        model = eqx.tree_at(lambda m: m.data.sigma, model, jnp.asarray(sigma, dtype))
        if int(np.sum(counts > 0)) > 1:  # the kinds' relative weights changed: fit again from here
            phi, more, n_more, converged, raw, jac, fitted = run(phi, model)
            history = np.concatenate([history, more[1:]])
            n_iterations += n_more
        else:  # one kind: the same optimum, the Jacobian rescaled
            jac = jac * (np.asarray(data.sigma, np.float64) / sigma)[counts > 0][0]

    # --- uncertainty ---
    phi_j = jnp.asarray(phi, dtype)
    g, g_all, (inertia, args_fit, _, omega_fit), q_fit0 = _parameter_jacobians(
        phi_j, layout, data.q_start, free_inertia
    )
    g, g_all = np.asarray(g, np.float64), np.asarray(g_all, np.float64)
    inertia_np = np.asarray(inertia, np.float64)
    inertia_scale = max(np.trace(inertia_np) / 3, np.finfo(np.float64).tiny)
    names, scale = [], []
    if free_inertia is True:
        names += [f"inertia[{a},{b}]" for a, b in ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))]
        scale += [inertia_scale] * 6
    elif free_inertia == "moments":
        names += [f"moments[{a}]" for a in range(3)]
        scale += [inertia_scale] * 3
    fitted_leaves = jax.tree_util.tree_leaves(args_fit)
    leaf_scales = []
    for leaf in fitted_leaves:
        size = float(np.max(np.abs(np.asarray(leaf, np.float64)), initial=0.0)) if np.size(leaf) else 0.0
        leaf_scales.append(size if size > 0 else 1.0)
    for index, _ in free_leaves:
        path = leaves_with_path[index][0]
        shape = np.shape(fitted_leaves[index])
        names += _element_labels(_label(path), shape)
        scale += [leaf_scales[index]] * int(np.prod(shape, dtype=int))
    omega_np = np.asarray(omega_fit, np.float64)
    for j in range(k):
        names += [f"q0[{j}].rotation[{a}]" for a in range(3)] + [f"omega0[{j},{a}]" for a in range(3)]
        scale += [1.0] * 3 + [max(float(np.linalg.norm(omega_np[j])), 1e-12)] * 3
    scale = np.asarray(scale)
    result = analyse(jac, g, scale, names, rcond)
    scale_all = np.concatenate(
        [
            np.full(9, inertia_scale),
            *[np.full(np.size(leaf), leaf_scales[i]) for i, leaf in enumerate(fitted_leaves)],
            np.ones(4 * k),
            np.repeat(np.maximum(np.linalg.norm(omega_np, axis=-1), 1e-12), 3),
        ]
    )
    se_all = propagate(g_all, result.cov_phi, result.null, scale_all)
    i = 9
    se_inertia = se_all[:9].reshape(3, 3)
    se_leaves = []
    free_set = {index for index, _ in free_leaves}
    for index, leaf in enumerate(fitted_leaves):
        size = int(np.size(leaf))
        se_leaf = (
            se_all[i : i + size].reshape(np.shape(leaf)) if index in free_set else np.zeros(np.shape(leaf))
        )
        se_leaves.append(se_leaf)
        i += size
    se_q0 = se_all[i : i + 4 * k].reshape(k, 4)
    se_omega0 = se_all[i + 4 * k :].reshape(k, 3)
    if free_inertia is False:
        se_inertia = np.zeros((3, 3))
    if result.unidentified:
        warnings.warn(
            "identify: the data do not determine " + ", ".join(result.unidentified) + " (see "
            "Identification.unidentified; their standard errors are infinite where a combination of "
            "parameters is undetermined). Fix them, or add experiments or observations that excite them.",
            stacklevel=2,
        )

    # --- the fitted model at the samples ---
    q_fit, omega_world = fitted  # the modelled states at phi, from the fit's last evaluation
    whitened = raw / np.asarray(model.data.sigma, np.float64)[:, :, None, None]
    trajectories, residual_dicts = [], []
    for j, e in enumerate(experiments):
        n = e.t.shape[0]
        trajectories.append(
            Trajectory(
                jnp.asarray(e.t, dtype),
                jnp.asarray(q_fit[j, :n], dtype),
                jnp.asarray(omega_world[j, :n], dtype),
            )
        )
        parts = {}
        for a, (name, _, _, _) in enumerate(KINDS):
            if counts[j, a]:
                r = whitened[j, a, :n].copy()
                r[data.weight[j, a, :n] == 0] = np.nan
                parts[name] = r
        residual_dicts.append(parts)
    sigma_out = np.where(counts > 0, np.asarray(model.data.sigma, np.float64), np.nan)
    return Identification(
        inertia=jnp.asarray(inertia, dtype),
        args=args_fit if free_leaves else args,
        q0=q_fit0,
        omega0=omega_fit,
        stderr=StandardErrors(se_inertia, jax.tree_util.tree_unflatten(treedef, se_leaves), se_q0, se_omega0),
        covariance=result.covariance,
        names=tuple(names),
        correlation=correlations(result.covariance),
        unidentified=result.unidentified,
        converged=converged,
        sigma=sigma_out,
        residuals=residual_dicts,
        trajectories=trajectories,
        loss=float(history[-1]),
        loss_history=history,
        n_iterations=n_iterations,
        scale_determined=not unit_scale,
        dt=spacing / substeps,
        scheme=scheme,
    )


@eqx.filter_jit
def _parameter_jacobians(phi, layout, q_start, free_inertia):
    """``∂p/∂φ`` of the labelled parameters, ``∂(all fields)/∂φ``, the unpacked parameters and ``q₀``."""

    def user_values(phi):
        inertia, args_fit, dq, omega_fit = unpack(phi, layout)
        parts = []
        if free_inertia is True:
            parts.append(inertia[(0, 1, 2, 0, 0, 1), (0, 1, 2, 1, 2, 2)])
        elif free_inertia == "moments":
            parts.append(jnp.einsum("ji,jk,ki->i", layout.inertia0, inertia, layout.inertia0))
        leaves = jax.tree_util.tree_leaves(args_fit)
        parts.extend(leaves[i].ravel() for i, _ in layout.free_leaves)
        for j in range(layout.n_experiments):
            parts.extend([dq[j], omega_fit[j]])
        return jnp.concatenate(parts)

    def fitted_q0(dq):
        return quat.multiply(quat.exp(dq), q_start)

    def all_values(phi):
        inertia, args_fit, dq, omega_fit = unpack(phi, layout)
        q_fit = fitted_q0(dq)
        leaves = [jnp.ravel(leaf) for leaf in jax.tree_util.tree_leaves(args_fit)]
        return jnp.concatenate([inertia.ravel(), *leaves, q_fit.ravel(), omega_fit.ravel()])

    unpacked = unpack(phi, layout)
    return jax.jacfwd(user_values)(phi), jax.jacfwd(all_values)(phi), unpacked, fitted_q0(unpacked[2])
