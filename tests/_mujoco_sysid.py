"""`mujoco.sysid` (MuJoCo 4.0) fitting the inertia to `_mujoco_telemetry`'s manoeuvres, as a user writes it.

What a careful user of sysid writes for this problem (https://github.com/google-deepmind/mujoco,
``python/mujoco/sysid``: README and sysid.ipynb):

- **inertia**: sysid's full-inertia parameterisation, the pseudo-inertia Cholesky factor of Rucker &
  Wensing (2022) (``body_inertia_param(..., InertiaType.Pseudo)``: ``θ = [α, d₁₋₃, s₁₂, s₂₃, s₁₃,
  t₁₋₃]``), with the mass ``α`` and the centre of mass ``t`` held at their known values (1 kg, the
  body origin): rotation data cannot see them (a free body's orientation under a pure couple is
  independent of both), and a sysid ``Parameter`` cannot hold part of its vector, so the six free
  entries ``[d₁₋₃, s₁₂, s₂₃, s₁₃]`` are one ``Parameter``. Its modifier turns θ into the tensor with
  sysid's ``pi_from_theta`` and writes it as the body's ``fullinertia``: sysid's own writer
  (``apply_body_theta_inertia``, the modifier of ``InertiaType.Pseudo``) sets ``iquat`` to NaN,
  which MuJoCo 4.0.0's compiler rejects ("mass and inertia of moving bodies must be larger than
  mjMINVAL", on any body; tests/test_mujoco_telemetry.py keeps the check). Every θ is a physical
  inertia (positive definite, triangle inequality), so no candidate makes the compiler raise.
- **initial state** (``fit_initial_state=True``): per manoeuvre a body-frame rotation vector ``δ``
  (``q₀ = q_first ⊗ exp(δ)``) and the body rates ``ω₀``, started at the first samples; sysid takes
  the initial state from the data, so fitting it needs a ``custom_rollout`` that builds each
  rollout's initial state from these parameters. ``fit_initial_state=False`` is sysid's default:
  the first (noisy) samples are the initial state.
- **residuals**: sysid's defaults (each sensor column's misfit divided by that column's norm / √2,
  the quaternion's four components compared directly), the optimiser ``"mujoco"`` (Gauss–Newton
  with finite-difference Jacobians over batched ``mujoco.rollout``, box bounds), and the
  intervals of ``sysid.calculate_intervals`` (``s² (JᵀJ)⁻¹`` with one pooled ``s²``, at the
  optimum's Jacobian), as ``sysid.save_results`` computes them.
- **time stamps**: a sensor row that MuJoCo records after the step to ``t + dt`` holds the state at
  ``t``, and sysid stamps its prediction with ``t + dt``; the measured sample of time ``t`` is
  therefore given the stamp ``t + dt`` (without it every prediction lags one step, 3e-4 rad here).

The inertia's standard errors are sysid's covariance of θ carried to the tensor by the delta
method (``G Cov Gᵀ``, ``G = ∂I/∂θ`` by central differences of sysid's ``pi_from_theta``).
"""

import io
import time
from typing import NamedTuple

import numpy as np
from _mujoco_telemetry import model_xml


try:
    import mujoco
    from mujoco import sysid
    from mujoco.sysid._src import model_modifier as _pseudo
except ImportError:
    mujoco = sysid = _pseudo = None

# Start of the fit, as `benchmarks/identify_speed.py`'s jaxrot fit: a diagonal guess, kg m².
INERTIA0 = np.diag([0.045, 0.045, 0.045])
# Box bounds: Σ's Cholesky diagonal within ×/÷ 2 (Σ_ii ×/÷ 4), shears ± 0.5 (sysid's default offset);
# the start-state offsets ± 0.05 rad and ± 0.05 rad/s (500 σ of the default noise).
LOG_STRETCH_BOUND = np.log(2.0)
SHEAR_BOUND = 0.5
Q0_BOUND = 0.05
OMEGA0_BOUND = 0.05


class SysidFit(NamedTuple):
    """What `sysid_fit` returns.

    ``inertia`` ``(3, 3)`` kg m², body frame; ``inertia_stderr`` ``(3, 3)`` its standard errors
    (delta method on sysid's covariance); ``names`` the labels of sysid's parameter vector,
    ``x`` its optimum, ``covariance`` and ``halfwidth95`` sysid's covariance and 95 % interval
    half-widths of it (``calculate_intervals``); ``q0`` ``(k, 4)`` and ``omega_body0`` ``(k, 3)``
    the initial states used (fitted, or the first samples); ``wall_s`` seconds for the whole fit
    (the optimisation and the intervals), ``optimize_s`` the optimisation alone; ``log`` the
    optimiser's printed trace; ``extra`` further fitted parameters by name (`fit_problem`'s ``extra``).
    """

    inertia: np.ndarray
    inertia_stderr: np.ndarray
    names: tuple
    x: np.ndarray
    covariance: np.ndarray
    halfwidth95: np.ndarray
    q0: np.ndarray
    omega_body0: np.ndarray
    wall_s: float
    optimize_s: float
    log: str
    extra: dict | None = None


def _theta10(theta6, theta0):
    """sysid's 10-vector θ with the mass (α) and the centre of mass (t) of ``theta0`` held."""
    return np.concatenate([theta0[:1], theta6, theta0[7:]])


def _inertia_of(theta6, theta0):
    """The inertia tensor about the body origin (the centre of mass) of θ: sysid's ``pi_from_theta``."""
    return _pseudo.pi_from_theta(_theta10(theta6, theta0))[4:].reshape(3, 3)


def _theta_of(inertia):
    """sysid's θ of a 1 kg body with its centre of mass at the origin and this inertia tensor."""
    pi = np.concatenate([[1.0], np.zeros(3), np.asarray(inertia, dtype=float).ravel()])
    return _pseudo.theta_from_pseudoinertia(_pseudo.pseudoinertia_from_pi(pi))


def _quat_exp(rotvec):
    angle = np.linalg.norm(rotvec)
    if angle == 0.0:
        return np.array([1.0, 0.0, 0.0, 0.0])
    return np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * rotvec / angle])


def _quat_mul(p, q):
    w1, v1, w2, v2 = p[0], p[1:], q[0], q[1:]
    return np.concatenate([[w1 * w2 - v1 @ v2], w1 * v2 + w2 * v1 + np.cross(v1, v2)])


def _sequences(spec, model, manoeuvres, min_pad=3):
    """sysid's ``ModelSequences``: controls held per step, sensors at their MuJoCo time stamps; at least
    ``min_pad`` held steps past the last control (a delayed sensor reads the prediction that late)."""
    dt = model.opt.timestep
    initial_states, controls, sensors = [], [], []
    for m in manoeuvres:
        if not np.allclose(np.diff(m.t_c), dt, rtol=0, atol=1e-12):
            raise ValueError(f"the controls must be held for MuJoCo's steps of {dt} s")
        # sysid drops the last control row, and the last sample is the state *after* the last
        # control step: padding rows make the prediction reach a step or more beyond the last sample.
        # sysid resamples the controls to the time step on ceil(span / dt) + 1 points: where span / dt
        # rounds past an integer (2002.0000000000002 for 2003 rows of 1 ms) the grid gains a point and
        # every held control is interpolated between two; the padding is chosen so that it is not.
        for pad in range(min_pad, min_pad + 7):
            ctrl = np.vstack([m.tau_c, np.repeat(m.tau_c[-1:], pad, axis=0)])
            control = sysid.TimeSeries.from_control_names(m.t_c[0] + np.arange(len(ctrl)) * dt, ctrl, model)
            if control.resample(target_dt=dt).data.shape == ctrl.shape:
                break
        else:
            raise ValueError("no padding keeps sysid's resampling of the controls on the time step")
        controls.append(control)
        sensors.append(sysid.TimeSeries.from_names(m.t + dt, np.hstack([m.q, m.omega_body]), model))
        initial_states.append(
            sysid.create_initial_state(model, np.r_[0, 0, 0, m.q[0]], np.r_[0, 0, 0, m.omega_body[0]])
        )
    names = [f"manoeuvre_{j}" for j in range(len(manoeuvres))]
    return sysid.ModelSequences("free_body", spec, names, initial_states, controls, sensors), initial_states


def _initial_state_rollout(model, measured_initial_states, first_q):
    """A sysid ``custom_rollout`` whose initial states are the parameters ``q0_offset_j``, ``omega0_j``."""
    which = {s.tobytes(): j for j, s in enumerate(measured_initial_states)}

    def custom_rollout(*, models, datas, control_signal, initial_states, param_dicts, **mappings):
        states = []
        for state, params in zip(initial_states, param_dicts, strict=True):
            j = which[np.asarray(state).tobytes()]
            q0 = _quat_mul(first_q[j], _quat_exp(params[f"q0_offset_{j}"].value))
            omega0 = params[f"omega0_{j}"].value
            states.append(sysid.create_initial_state(model, np.r_[0, 0, 0, q0], np.r_[0, 0, 0, omega0]))
        return sysid.sysid_rollout(models, datas, control_signal, states, **mappings)

    return custom_rollout


class SysidProblem(NamedTuple):
    """sysid's parameters and residual for the manoeuvres (`sysid_problem`), and what reads them back."""

    params: object  # sysid.ParameterDict: "inertia" (6), then per manoeuvre "q0_offset_j", "omega0_j"
    residual_fn: object  # sysid.build_residual_fn(...): (x, params) -> (residuals, predictions, records)
    theta0: np.ndarray  # sysid's 10-vector θ of the start; its mass and centre of mass are held
    first_q: list
    first_omega: list


def _require_sysid():
    """Raise ImportError where ``mujoco.sysid`` (MuJoCo >= 4.0) is missing."""
    if sysid is None or not hasattr(sysid, "optimize"):
        raise ImportError('mujoco.sysid is not installed: pip install -e ".[mujoco]" (mujoco[sysid] >= 4.0)')


def _inertia_parameter(theta0):
    """sysid's ``inertia`` parameter (the module docstring): θ's six free entries about ``theta0``, in
    their box bounds, with a modifier writing θ's tensor as the body's ``fullinertia``."""

    def write_inertia(spec, param):
        i = _inertia_of(param.value, theta0)
        spec.body("body").fullinertia = [i[0, 0], i[1, 1], i[2, 2], i[0, 1], i[0, 2], i[1, 2]]

    bounds = np.r_[[LOG_STRETCH_BOUND] * 3, [SHEAR_BOUND] * 3]
    return sysid.Parameter(
        "inertia", theta0[1:7], theta0[1:7] - bounds, theta0[1:7] + bounds, modifier=write_inertia
    )


def sysid_problem(manoeuvres, *, inertia0=INERTIA0, fit_initial_state=True):
    """The sysid problem of the module docstring, started at ``inertia0`` and the first samples."""
    _require_sysid()
    spec = mujoco.MjSpec.from_string(model_xml(inertia0))
    model = spec.compile()
    theta0 = _theta_of(inertia0)
    params = sysid.ParameterDict()
    params.add(_inertia_parameter(theta0))
    sequences, measured_initial_states = _sequences(spec, model, manoeuvres)
    first_q = [m.q[0] for m in manoeuvres]
    first_omega = [m.omega_body[0] for m in manoeuvres]
    custom_rollout = None
    if fit_initial_state:
        for j, w in enumerate(first_omega):
            params.add(
                sysid.Parameter(f"q0_offset_{j}", np.zeros(3), np.full(3, -Q0_BOUND), np.full(3, Q0_BOUND))
            )
            params.add(sysid.Parameter(f"omega0_{j}", w, w - OMEGA0_BOUND, w + OMEGA0_BOUND))
        custom_rollout = _initial_state_rollout(model, measured_initial_states, first_q)
    residual_fn = sysid.build_residual_fn(models_sequences=[sequences], custom_rollout=custom_rollout)
    return SysidProblem(params, residual_fn, theta0, first_q, first_omega)


def sysid_fit(manoeuvres, *, inertia0=INERTIA0, fit_initial_state=True, max_iters=100):
    """Fit the inertia tensor (and each manoeuvre's initial state) with ``mujoco.sysid``.

    Args:
        manoeuvres: `_mujoco_telemetry.Manoeuvre` records (true time stamps, body-frame controls
            held per MuJoCo step).
        inertia0: the start ``(3, 3)``, kg m², body frame.
        fit_initial_state: fit each manoeuvre's ``q₀`` and ``ω₀`` (a custom rollout); False: sysid's
            default, the first samples.
        max_iters: the optimiser's iteration cap.

    Returns:
        `SysidFit`; its ``wall_s`` counts from the model's construction to the intervals.
    """
    start = time.perf_counter()
    problem = sysid_problem(manoeuvres, inertia0=inertia0, fit_initial_state=fit_initial_state)
    return fit_problem(problem, start, fit_initial_state=fit_initial_state, max_iters=max_iters)


def fit_problem(problem, start, *, fit_initial_state=True, max_iters=100, extra=()):
    """Run sysid's optimiser and intervals on a `SysidProblem` (`sysid_fit`'s second half); ``start``
    is the ``time.perf_counter()`` at which the problem's construction began; ``extra``: names of
    further parameters whose fitted values go into `SysidFit.extra`."""
    log = io.StringIO()
    opt_params, result = sysid.optimize(
        problem.params, problem.residual_fn, "mujoco", verbose=False, max_iters=max_iters, output=log
    )
    optimize_s = time.perf_counter() - start
    residuals, _, _ = problem.residual_fn(result.x, opt_params, return_pred_all=True)
    covariance, halfwidth = sysid.calculate_intervals(residuals, result.jac)
    wall_s = time.perf_counter() - start

    theta0, theta6 = problem.theta0, opt_params["inertia"].value
    inertia = _inertia_of(theta6, theta0)
    # Delta method: ∂I/∂θ by central differences (θ ~ 0.1-1, so a step of 1e-6 errs by ~1e-12 relative).
    jac = np.stack(
        [
            (_inertia_of(theta6 + 1e-6 * e, theta0) - _inertia_of(theta6 - 1e-6 * e, theta0)).ravel() / 2e-6
            for e in np.eye(6)
        ],
        axis=1,
    )
    stderr = np.sqrt(np.diag(jac @ covariance[:6, :6] @ jac.T)).reshape(3, 3)
    names = tuple(f"{p.name}[{i}]" for p in problem.params.values() if not p.frozen for i in range(p.size))
    q0, omega0 = problem.first_q, problem.first_omega
    if fit_initial_state:
        q0 = [_quat_mul(q, _quat_exp(opt_params[f"q0_offset_{j}"].value)) for j, q in enumerate(q0)]
        omega0 = [opt_params[f"omega0_{j}"].value for j in range(len(q0))]
    return SysidFit(
        inertia=inertia,
        inertia_stderr=stderr,
        names=names,
        x=np.asarray(result.x),
        covariance=covariance,
        halfwidth95=halfwidth,
        q0=np.array(q0),
        omega_body0=np.array(omega0),
        wall_s=wall_s,
        optimize_s=optimize_s,
        log=log.getvalue(),
        extra={name: np.array(opt_params[name].value) for name in extra},
    )
