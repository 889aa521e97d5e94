"""`identify`'s fourth stage: Gauss–Newton from ``φ₀``, every pass in one compiled loop.

One loop (`_staged_gauss_newton`, a `jax.lax.while_loop`) runs the whole fit: the windows when
the start is far from the data, the whole record, and the second fit with estimated noise
levels. Passes are stages of that loop, so a call crosses to the host once, the Jacobian
program is traced and compiled once, and ``max_iter`` bounds the iterations of all passes
together.

Windows: far from the optimum a long record's misfit is strongly nonlinear in the
parameters (a 20 % error of the start's inertia turns a 600 s record by a radian), and
Gauss–Newton's linear model can lead it into another minimum (seen: a gyro delay of
−132 s). Over a short window the same error is a small misfit. So a far start is fitted
over the first 1/16, 1/8, … of every record's steps (each window holding at least
`WINDOW_DATA` times as many informative residuals as parameters), each from the last one's
optimum, and ends on the whole record. A window's steps past its end are skipped
(`_model`), so it costs its share of the record.

Far or close, decided from the loop's first evaluation (the whole record at ``φ₀``): the
start is *close* when no modelled orientation or tracked direction is off its sample by more
than `CLOSE_ANGLE` rad and, per experiment, the RMS of the gyro misfit is at most
`CLOSE_ANGLE` times the RMS of the rates read (a relative rate error is the same phase error
seen on the body rates); otherwise far. Why 1 rad: what a wrong parameter makes is a phase
error growing along the record, and Gauss–Newton lands in another minimum once a phase is
wrapped, past π; below 1 rad every sample is still on the near side with a factor π of room
for the first steps' overshoot, and a turn's misfit (the rotation vector, or the chord
``2 sin(θ/2)``, within 4 % of ``θ``) is still nearly linear in the phase. Measured: the
test satellites' starts are off by 0.33–0.52 rad (gyros 0.04–0.12): over the whole record at
once they reach the windows' optimum (to ~1e-12 in ``φ``) in 4 iterations instead of 8;
the noise-free fit with all five sensor flaws and a drag per manoeuvre starts 1.5–2.0 rad off
(gyros 0.46–1.05), and without windows ends in a false minimum (loss 6.5e9 after 87
iterations, against 2.5e-9 in 7 with them). Noise only makes a start look farther (the safe
side: windows).

Noise: a kind whose σ is not given has it estimated from its residuals,
``σ² = RSS_kind / (m_kind (1 − n/m))``; when several series (experiment and kind) are weighed
against each other the whole record is fitted once more with the estimated σ (the loop's last
stage); with one series the optimum is the same and only the Jacobian is rescaled.
"""

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._optimiser import MAX_REJECTIONS, Search, _converged, search_step, start_search, trace_once
from ._experiment import KINDS
from ._jacobian import residuals_jacobian_factor
from ._model import INDEX


WINDOW_DATA = 5  # informative residuals per parameter in the first window
WINDOWS = 4  # at most this many windows before the whole record: 1/16 … 1/2
WINDOW_FTOL = 1e-4  # a window's fit stops within ~0.01 standard errors of its optimum
CLOSE_ANGLE = 1.0  # rad: a start whose misfits stay below this skips the windows (module docstring)


class Solution(NamedTuple):
    """Where Gauss–Newton stopped."""

    phi: np.ndarray
    history: np.ndarray  # the objective at each accepted iterate, each pass's start included
    n_iterations: int  # Gauss–Newton steps over all passes (what max_iter bounds)
    converged: bool  # of the last pass, on the whole record
    raw: np.ndarray  # (k, 3, P + 1, 3) the misfits, not whitened (zero where not observed)
    jac: np.ndarray  # (m, n) the Jacobian of the whitened residuals (final σ)
    states: tuple  # (q (k, P + 1, 4), ω (k, P + 1, 3)) the modelled states at the samples
    model: object  # the model with the final σ
    windowed: bool  # whether the start was far and the windows ran
    evaluations: int  # of the residuals and Jacobian: iterations, passes' starts and rejected trials


def windows(model, settings):
    """The step counts of the windows before the whole record (increasing, maybe none)."""
    data = model.data
    total = data.step_start.shape[1]
    dof = np.array([d for _, _, _, d in KINDS], np.float64)
    informative = np.einsum("kap,a->kp", np.asarray(data.weight, np.float64), dof)  # per sample
    nodes = np.asarray(data.sample_node)
    out = []
    for halvings in range(WINDOWS, 0, -1):
        active = int(np.ceil(total / 2**halvings))
        if np.sum(informative * (nodes <= active)) >= WINDOW_DATA * settings.n_params:
            if not out or active > out[-1]:
                out.append(active)
    return out


class _Plan(eqx.Module):
    """The runtime values of the staged loop (arrays: a new record of the same shape reuses the program)."""

    windows: jax.Array  # (WINDOWS,) int: the windows' step counts, the first n_windows used
    n_windows: jax.Array  # () int
    total: jax.Array  # () int: every step
    ftol: jax.Array  # () the last passes' tolerance
    floor_sizes: jax.Array  # (3,) round-off of each kind's misfit (its units)
    counts: jax.Array  # (k, 3) observed samples per experiment and kind
    dof: jax.Array  # (3,) informative residuals per sample of each kind
    estimated: jax.Array  # (k, 3) bool: σ to estimate
    shrink: jax.Array  # () 1 − n/m
    refit: jax.Array  # () bool: σ estimated for several series, so fit once more with them
    use_windows: jax.Array  # () int: 1 always, 0 never, -1 when the start is far


def _floor(sigma, plan):
    """The objective of round-off-only residuals under ``sigma`` (`_optimiser._converged`)."""
    return jnp.sum(plan.counts * (plan.floor_sizes[None, :] / sigma) ** 2)


def estimated_sigma(raw_rss, sigma, counts, dof, estimated, shrink, floor_sizes, xp=jnp):
    """The noise levels ``(k, 3)``: ``σ² = RSS / (m (1 − n/m))`` where estimated, the given ones elsewhere."""
    estimate = xp.sqrt(raw_rss / xp.maximum(counts * dof[None, :] * shrink, 1))
    return xp.where(estimated, xp.maximum(estimate, floor_sizes[None, :]), sigma)


def _far(r, sigma, data):
    """Whether the start is far from the data (module docstring), from the whitened residuals ``r``."""
    k, n_max = data.t.shape
    raw = r.reshape(k, 3, n_max, 3) * sigma[:, :, None, None]
    angles = jnp.sqrt(jnp.sum(raw[:, 0] ** 2, axis=-1)), jnp.sqrt(jnp.sum(raw[:, 2] ** 2, axis=-1))
    turned = jnp.maximum(jnp.max(angles[0]), jnp.max(angles[1])) > CLOSE_ANGLE
    misfit = jnp.sum(raw[:, 1] ** 2, axis=(1, 2))
    read = jnp.sum(data.weight[:, 1, :, None] * data.omega_body**2, axis=(1, 2))
    rates = jnp.any((misfit > 0) & ~(misfit <= CLOSE_ANGLE**2 * read))
    return turned | rates | ~jnp.all(jnp.isfinite(r))


class _Carry(NamedTuple):
    search: Search  # `_optimiser`'s Gauss–Newton state: iterate, residuals, Jacobian, step, trial
    history: jax.Array
    slot: jax.Array  # next free entry of history
    n: jax.Array  # accepted Gauss–Newton steps, all passes
    stage: jax.Array  # windows 0 … n_windows − 1, then the whole record, then the refit
    active: jax.Array  # the stage's steps
    sigma: jax.Array  # (k, 3) the stage's noise levels
    fresh: jax.Array  # evaluate z itself and accept it (a pass's start)
    probe: jax.Array  # the first evaluation, which decides far or close
    windowed: jax.Array
    closing: jax.Array  # this evaluation is the last: the whole record after a cap inside a window
    done: jax.Array
    converged: jax.Array
    evaluations: jax.Array


def history_size(max_iter):
    """The history's length: a power of two, at least 128, so that ``max_iter`` (a runtime value) rarely
    changes the compiled program."""
    return max(128, 1 << int(max_iter + WINDOWS + 2 - 1).bit_length())


@eqx.filter_jit
def _staged_gauss_newton(z0, model, plan, max_iter, size: int):
    """Every pass of the fit in one `jax.lax.while_loop`: the `_Carry` at its end.

    Each trial is `_optimiser.search_step` (the Gauss–Newton of `_optimiser.gauss_newton`: one
    evaluation of `residuals_and_jacobian`, Armijo's test from the full step, halved up to
    `MAX_REJECTIONS` times); this loop adds the passes. A pass's start (``fresh``) evaluates the
    current point under the pass's window or σ and accepts it without counting an iteration.
    """

    def evaluate(z, active, sigma):
        m = eqx.tree_at(lambda m: (m.active, m.data.sigma), model, (active, sigma))
        r, jac, states, factor = residuals_jacobian_factor(z, m)
        return r, jac, (states, factor)

    # Traced once here, called from the loop's body: one Jacobian program for every pass.
    total = plan.total.astype(INDEX)
    evaluate_traced, shapes = trace_once(evaluate, z0, total, model.data.sigma)
    zero = jnp.zeros((), jnp.int32)
    false, true = jnp.zeros((), bool), jnp.ones((), bool)
    last = plan.n_windows  # the whole record's stage
    carry = _Carry(
        search=start_search(z0, shapes), history=jnp.zeros(size, z0.dtype), slot=zero, n=zero, stage=last,
        active=total, sigma=model.data.sigma, fresh=true, probe=true, windowed=false, closing=false,
        done=false, converged=false, evaluations=zero,
    )  # fmt: skip

    def body(c):
        s, accept, predicted = search_step(
            c.search,
            lambda z: evaluate_traced(z, c.active, c.sigma),
            c.fresh,
            minimum_norm=True,
            factor_of=lambda aux: aux[1],
        )
        n = c.n + (accept & ~c.fresh).astype(jnp.int32)
        far = c.probe & (plan.n_windows > 0) & ((plan.use_windows == 1) | (
            (plan.use_windows < 0) & _far(s.r, c.sigma, model.data)))  # fmt: skip
        # The refit's start is not recorded (its objective is the last pass's, reweighed).
        recorded = accept & ~far & ~(c.fresh & (c.stage > last))
        history = jnp.where(accept, c.history.at[jnp.minimum(c.slot, c.history.size - 1)].set(s.f), c.history)
        slot = c.slot + recorded.astype(jnp.int32)

        ftol = jnp.where(c.stage < last, jnp.asarray(WINDOW_FTOL, z0.dtype), plan.ftol)
        settled = accept & ~far & _converged(s.f, predicted, ftol, _floor(c.sigma, plan))
        capped = (accept & (n >= max_iter)) | (s.rejections >= MAX_REJECTIONS)
        far = far & ~capped
        next_window = settled & (c.stage < last) & ~capped
        refit = settled & (c.stage == last) & plan.refit & ~capped
        converged = settled & (c.stage >= last) & ~refit
        # Stopped inside a window: one more evaluation, of the whole record at z, so that the residuals
        # and Jacobian returned (the report, the health check) are the record's.
        reopen = capped & ~converged & (c.active < total) & ~c.closing
        # The next stage: the first window (far start), the next window or the whole record, the refit.
        stage = jnp.where(far, 0, c.stage + (next_window | refit).astype(c.stage.dtype))
        stage = jnp.where(reopen, last, stage)
        window = plan.windows[jnp.clip(stage, 0, plan.windows.size - 1)]
        active = jnp.where(far | next_window, jnp.where(stage < last, window, total), c.active)
        active = jnp.where(reopen, total, active)
        k, n_max = model.data.t.shape
        rss = jnp.sum((s.r.reshape(k, 3, n_max, 3) * c.sigma[:, :, None, None]) ** 2, axis=(2, 3))
        sigma = jnp.where(
            refit,
            estimated_sigma(
                rss, c.sigma, plan.counts, plan.dof, plan.estimated, plan.shrink, plan.floor_sizes
            ),
            c.sigma,
        )
        fresh = far | next_window | refit | reopen
        s = s._replace(d=jnp.where(fresh, jnp.zeros_like(s.d), s.d))
        done = converged | (capped & ~reopen) | c.closing
        return _Carry(
            s, history, slot, n, stage, active, sigma, fresh, false, c.windowed | far, reopen, done,
            converged, c.evaluations + 1,
        )  # fmt: skip

    return jax.lax.while_loop(lambda c: ~c.done, body, carry)


def solve(problem, settings, speed, *, use_windows=None) -> Solution:
    """Fit ``problem`` (`_problem.Problem`) under ``settings``; ``speed`` is the largest ``|ω|`` of
    the start (the round-off floor's angular velocities). ``use_windows``: None decides from the start
    (module docstring), True or False forces it (for measurements)."""
    model, dtype = problem.model, settings.dtype
    k, n_max = settings.k, model.data.t.shape[1]
    eps = float(jnp.finfo(dtype).eps)
    theta = (model.data.step_start.shape[1] + 1) * eps
    floor_sizes = np.array([theta, theta * max(speed, 1e-300), theta])
    counts, dof = settings.counts, np.array([d for _, _, _, d in KINDS], np.float64)
    shrink = 1 - settings.n_params / int(np.sum(counts * dof))
    steps = windows(model, settings)
    plan = _Plan(
        windows=jnp.asarray(np.pad(steps, (0, WINDOWS - len(steps)), constant_values=1), INDEX),
        n_windows=jnp.asarray(len(steps), INDEX),
        total=jnp.asarray(model.data.step_start.shape[1], INDEX),
        ftol=jnp.asarray(settings.ftol, dtype),
        floor_sizes=jnp.asarray(floor_sizes, dtype),
        counts=jnp.asarray(counts, dtype),
        dof=jnp.asarray(dof, dtype),
        estimated=jnp.asarray(problem.estimated),
        shrink=jnp.asarray(shrink, dtype),
        refit=jnp.asarray(bool(problem.estimated.any()) and int(np.sum(counts > 0)) > 1),
        use_windows=jnp.asarray({None: -1, True: 1, False: 0}[use_windows], jnp.int32),
    )
    max_iter = jnp.asarray(settings.max_iter, jnp.int32)
    end = _staged_gauss_newton(
        jnp.asarray(problem.phi0, dtype), model, plan, max_iter, history_size(settings.max_iter)
    )
    sigma = np.asarray(end.sigma, np.float64)
    raw = np.asarray(end.search.r, np.float64).reshape(k, 3, n_max, 3) * sigma[:, :, None, None]
    jac = np.asarray(end.search.jac, np.float64)
    if problem.estimated.any() and not int(end.stage) > len(steps):
        # One series, or stopped before the refit: σ estimated now, the same optimum, J rescaled.
        rss = np.sum(raw**2, axis=(2, 3))
        new_sigma = estimated_sigma(rss, sigma, counts, dof, problem.estimated, shrink, floor_sizes, xp=np)
        rows = np.broadcast_to((sigma / new_sigma)[:, :, None, None], (k, 3, n_max, 3)).reshape(-1)
        jac, sigma = jac * rows[:, None], new_sigma
    model = eqx.tree_at(lambda m: m.data.sigma, model, jnp.asarray(sigma, dtype))
    # Sliced in NumPy: slicing the device array by a new length compiled a jit(dynamic_slice) each time.
    history = np.asarray(end.history, np.float64)[: max(int(end.slot), 1)]
    states = tuple(np.asarray(x, np.float64) for x in end.search.aux[0])
    return Solution(
        np.asarray(end.search.z, np.float64), history, int(end.n), bool(end.converged), raw, jac, states,
        model, bool(end.windowed), int(end.evaluations),
    )  # fmt: skip
