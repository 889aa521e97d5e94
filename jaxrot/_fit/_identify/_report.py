"""What a person reads of an `Identification`: a text summary and a figure of the whitened residuals.

A fit whose model holds leaves residuals that look like the noise: whitened, their RMS is
about 1 and consecutive ones are uncorrelated. A model error (an unmodelled torque, a
sensor delay, a bias) shows as an RMS above 1 and, more tellingly, as residuals correlated
from one sample to the next (lag-one autocorrelation near 1), long before the estimates
themselves look wrong.
"""

import numpy as np

from ...schemes import resolve_scheme
from ._sensors import TIME_UNIT, UNIT_LEGEND


SENSOR_NAMES = {"q": "tracker", "omega_body": "gyro", "direction": "direction"}


def residual_statistics(residuals):
    """``(n samples, RMS, lag-one autocorrelation)`` of a whitened residual series ``(n, 3)`` (NaN rows
    skipped; the autocorrelation pools the components over pairs of consecutive observed samples)."""
    r = np.asarray(residuals, np.float64)
    seen = np.all(np.isfinite(r), axis=-1)
    n = int(seen.sum())
    if n == 0:
        return 0, np.nan, np.nan
    rms = float(np.sqrt(np.mean(r[seen] ** 2)))
    pairs = seen[1:] & seen[:-1]
    energy = np.sum(r[seen] ** 2)
    lag = float(np.sum(r[1:][pairs] * r[:-1][pairs]) / energy) if pairs.any() and energy > 0 else np.nan
    return n, rms, lag


def strongest_correlations(names, correlation, count=5):
    """The ``count`` largest ``|ρ|`` between different parameters: ``[(a, b, ρ), ...]``."""
    c = np.array(correlation, np.float64)
    upper = np.triu(np.isfinite(c), k=1)
    i, j = np.nonzero(upper)
    order = np.argsort(-np.abs(c[i, j]))[:count]
    return [(names[i[o]], names[j[o]], float(c[i[o], j[o]])) for o in order]


def scheme_label(scheme) -> str:
    """A scheme's name with its chart where it has one: ``"rkmk_dopri5 (cayley chart)"``."""
    try:
        obj = resolve_scheme(scheme)
    except ValueError:
        return str(scheme)
    chart = getattr(obj, "chart", None)
    return obj.name + (f" ({chart} chart)" if chart is not None else "")


def summary(fit) -> str:
    """The text of `Identification.summary`."""
    k = len(fit.trajectories)
    m = sum(
        int(np.sum(np.all(np.isfinite(r), axis=-1))) * 3 for parts in fit.residuals for r in parts.values()
    )
    state = "converged" if fit.converged else "NOT converged (max_iter or a failed line search)"
    lines = []
    if not fit.reliable:
        lines.append("jaxrot.identify: FIT NOT RELIABLE, its standard errors are unreliable:")
        lines += [f"  - {problem}" for problem in fit.problems]
    lines += [
        f"jaxrot.identify: {k} experiment(s), {len(fit.names)} parameters, {state} after "
        f"{fit.n_iterations} iteration(s)",
        f"loss (sum of squared whitened residuals) {fit.loss:.6g} over {m} residuals; scheme "
        f"{scheme_label(fit.scheme)}, largest step {fit.dt:.3g}",
        UNIT_LEGEND,
    ]
    if fit.scheme_note:
        lines.insert(len(lines) - 1, f"scheme {fit.scheme_note}")
    if not fit.scale_determined:
        lines.append("no torque fixes the inertia's scale: it keeps the trace of inertia0 (shape only)")
    se = np.sqrt(np.maximum(np.diag(fit.covariance), 0))
    width = max(len(name) for name in fit.names) if fit.names else 10
    error_head = "std. error" if fit.reliable else "unreliable"
    lines += ["", f"{'parameter':<{width}}  {'estimate':>14}  {error_head:>10}  unit"]
    for name, value, error, unit in zip(fit.names, fit.estimates, se, fit.units, strict=True):
        if name.startswith("q0["):
            continue  # shown as quaternions below
        flag = "  (unidentified)" if name in fit.unidentified else ""
        lines.append(f"{name:<{width}}  {value:>14.8g}  {error:>10.3g}  {unit}{flag}")
    for j in range(k):
        rows = [i for i, name in enumerate(fit.names) if name.startswith(f"q0[{j}].")]
        q = ", ".join(f"{x:.8g}" for x in np.asarray(fit.q0[j], np.float64))
        errors = ", ".join(f"{se[i]:.3g}" for i in rows) + ("" if fit.reliable else " (unreliable)")
        lines.append(f"q0[{j}] = [{q}]  ± {errors} rad (rotation)")
    pairs = strongest_correlations(fit.names, fit.correlation)
    lines += ["", "strongest correlations:"]
    lines += [f"  {a} ~ {b}: {rho:+.3f}" for a, b, rho in pairs] or ["  (none)"]
    header = f"  {'experiment':>10}  {'sensor':<9}  {'samples':>7}  {'sigma':>9}  {'RMS':>6}  {'lag-1':>6}"
    lines += ["", "whitened residuals (RMS ≈ 1 and lag-1 autocorrelation ≈ 0 where the model fits):", header]
    for j, parts in enumerate(fit.residuals):
        for kind, r in parts.items():
            n, rms, lag = residual_statistics(r)
            sigma = fit.sigma[j, ("q", "omega_body", "direction").index(kind)]
            lines.append(
                f"  {j:>10}  {SENSOR_NAMES[kind]:<9}  {n:>7}  {sigma:>9.3g}  {rms:>6.3f}  {lag:>+6.3f}"
            )
    lines.append("")
    if fit.unidentified:
        lines.append("unidentified (the data do not determine them): " + ", ".join(fit.unidentified))
    else:
        lines.append("unidentified: none")
    return "\n".join(lines)


def plot_residuals(fit):
    """The figure of `Identification.plot_residuals`."""
    from matplotlib.figure import Figure

    kinds = [kind for kind in ("q", "omega_body", "direction") if any(kind in p for p in fit.residuals)]
    k = len(fit.residuals)
    fig = Figure(figsize=(4.2 * len(kinds), 2.4 * k + 0.6), layout="constrained")
    axes = fig.subplots(k, len(kinds), squeeze=False, sharey=True)
    for j, parts in enumerate(fit.residuals):
        t = np.asarray(fit.trajectories[j].t, np.float64)
        for c, kind in enumerate(kinds):
            ax = axes[j, c]
            if kind not in parts:
                ax.set_axis_off()
                continue
            for axis, colour in zip(range(3), ("C0", "C1", "C2"), strict=True):
                ax.plot(t, parts[kind][:, axis], ".", ms=2.5, color=colour, label="xyz"[axis])
            ax.axhline(2, color="0.6", lw=0.8, ls="--")
            ax.axhline(-2, color="0.6", lw=0.8, ls="--")
            n, rms, lag = residual_statistics(parts[kind])
            ax.set_title(f"experiment {j}, {SENSOR_NAMES[kind]}: RMS {rms:.2f}, lag-1 {lag:+.2f}", fontsize=9)
            if j == k - 1:
                ax.set_xlabel(f"time {TIME_UNIT}")
            if c == 0:
                ax.set_ylabel("residual / σ")
    axes[0, 0].legend(loc="upper right", fontsize=7, ncols=3)
    return fig
