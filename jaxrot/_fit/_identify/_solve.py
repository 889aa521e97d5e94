"""`identify`'s fourth stage: Gauss–Newton from ``φ₀`` over growing windows, with the noise levels.

Windows: far from the optimum a long record's misfit is strongly nonlinear in the
parameters (a 20 % error of the start's inertia turns a 600 s record by a radian), and
Gauss–Newton's linear model can lead it into another minimum (seen: a gyro delay of
−132 s). Over a short window the same error is a small misfit. So the fit runs over the
first 1/16, 1/8, … of every record's steps (each window holding at least `WINDOW_DATA`
times as many informative residuals as parameters), each from the last one's optimum, and
ends on the whole record. A window's steps past its end are skipped (`_model`), so
it costs its share of the record; all windows run one compiled program.

Noise: a kind whose σ is not given has it estimated from its residuals,
``σ² = RSS_kind / (m_kind (1 − n/m))``; when several kinds are weighed against each
other the whole record is fitted once more with the estimated σ.
"""

from typing import NamedTuple

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._optimiser import gauss_newton
from ._experiment import KINDS
from ._model import INDEX, residuals, residuals_and_jacobian


WINDOW_DATA = 5  # informative residuals per parameter in the first window
WINDOWS = 4  # at most this many windows before the whole record: 1/16 … 1/2
WINDOW_FTOL = 1e-4  # a window's fit stops within ~0.01 standard errors of its optimum


class Solution(NamedTuple):
    """Where Gauss–Newton stopped."""

    phi: np.ndarray
    history: np.ndarray  # the objective before each iteration and at the end of each pass (window)
    n_iterations: int
    converged: bool  # of the last pass, on the whole record
    raw: np.ndarray  # (k, 3, P + 1, 3) the misfits, not whitened (zero where not observed)
    jac: np.ndarray  # (m, n) the Jacobian of the whitened residuals (final σ)
    states: tuple  # (q (k, P + 1, 4), ω (k, P + 1, 3)) the modelled states at the samples
    model: object  # the model with the final σ


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


def _run(phi, model, floor, ftol, settings):
    k, n_max = settings.k, model.data.t.shape[1]
    sigma = np.asarray(model.data.sigma, np.float64)
    z, history, n, converged, r, jac, fitted = gauss_newton(
        residuals,
        jnp.asarray(phi, settings.dtype),
        model,
        jnp.asarray(ftol, settings.dtype),
        jnp.asarray(floor, settings.dtype),
        settings.max_iter,
        minimum_norm=True,
        jacobian_fn=residuals_and_jacobian,
    )
    n = int(n)
    # Sliced in NumPy: slicing the device array by a new length compiled a jit(dynamic_slice) each time
    # (0.08-0.12 s of the first call per distinct iteration count, under load).
    raw = np.asarray(r, np.float64).reshape(k, 3, n_max, 3) * sigma[:, :, None, None]
    fitted = tuple(np.asarray(x, np.float64) for x in fitted)
    return (np.asarray(z, np.float64), np.asarray(history, np.float64)[: n + 1], n, bool(converged), raw,
            np.asarray(jac, np.float64), fitted)  # fmt: skip


def solve(problem, settings, speed) -> Solution:
    """Fit ``problem`` (`_problem.Problem`) under ``settings``; ``speed`` is the largest ``|ω|`` of
    the start (the round-off floor's angular velocities)."""
    model = problem.model
    eps = float(jnp.finfo(settings.dtype).eps)
    theta = (model.data.step_start.shape[1] + 1) * eps
    floor_sizes = np.array([theta, theta * max(speed, 1e-300), theta])

    def floor_of(sigma):
        return float(np.sum(settings.counts * (floor_sizes / sigma) ** 2))

    sigma = np.asarray(model.data.sigma, np.float64)
    phi, histories, n_iterations = problem.phi0, [], 0
    for active in windows(model, settings):
        window = eqx.tree_at(lambda m: m.active, model, jnp.asarray(active, INDEX))
        phi, history, n, _, _, _, _ = _run(phi, window, floor_of(sigma), WINDOW_FTOL, settings)
        histories.append(history)
        n_iterations += n
    phi, history, n, converged, raw, jac, fitted = _run(phi, model, floor_of(sigma), settings.ftol, settings)
    histories.append(history)
    n_iterations += n
    if problem.estimated.any():
        counts, dof = settings.counts, np.array([d for _, _, _, d in KINDS])
        m_info = int(np.sum(counts * dof))
        rss = np.sum(raw**2, axis=(2, 3))
        shrink = 1 - settings.n_params / m_info
        estimate = np.sqrt(rss / np.maximum(counts * dof * shrink, 1))
        new_sigma = np.where(problem.estimated, np.maximum(estimate, floor_sizes), sigma)
        model = eqx.tree_at(lambda m: m.data.sigma, model, jnp.asarray(new_sigma, settings.dtype))
        if int(np.sum(counts > 0)) > 1:  # the kinds' relative weights changed: fit again from here
            phi, more, n_more, converged, raw, jac, fitted = _run(
                phi, model, floor_of(new_sigma), settings.ftol, settings
            )
            histories.append(more[1:])
            n_iterations += n_more
        else:  # one kind: the same optimum, the Jacobian rescaled
            jac = jac * (sigma / new_sigma)[counts > 0][0]
    history = np.concatenate(histories)
    return Solution(phi, history, n_iterations, converged, raw, jac, fitted, model)
