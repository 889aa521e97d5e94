"""The comparison's rows read: measured orders, the fastest row per error budget, the text
tables, the results files and the work-precision plot."""

import csv
import json
import math
from pathlib import Path

import numpy as np

from ._provenance import machine_info


ASYMPTOTIC_ERROR = 0.1  # rad; above this the error saturates and says nothing about the order


def fit_order(dts, errors) -> float:
    """Slope of log(error) against log(dt): the measured order of accuracy."""
    slope, _ = np.polyfit(np.log(np.asarray(dts)), np.log(np.asarray(errors)), 1)
    return float(slope)


def stalled(errors) -> bool:
    """Whether a ladder (errors in order of halving dt) has reached its floor: the last halving of dt
    gained less than a factor 2 below `ASYMPTOTIC_ERROR` (the reference's own error, or round-off)."""
    return len(errors) >= 2 and errors[-1] < ASYMPTOTIC_ERROR and errors[-1] > errors[-2] / 2


def measured_orders(rows) -> dict:
    """Per fixed-step scheme, the fitted order over its rungs between the floor and `ASYMPTOTIC_ERROR`.

    Above `ASYMPTOTIC_ERROR` the error saturates; where a ladder has `stalled`, rungs within a
    decade of its smallest error carry the floor's error, not the scheme's, and are left out too.
    None when fewer than three rungs qualify.
    """
    orders = {}
    fixed = [r for r in rows if r.get("kind", "fixed") == "fixed"]
    for name in dict.fromkeys(r["method"] for r in fixed):
        ladder = sorted(
            (r for r in fixed if r["method"] == name and math.isfinite(r["max_orientation_error_rad"])),
            key=lambda r: -r["dt"],
        )
        errors = [r["max_orientation_error_rad"] for r in ladder]
        floor = 10 * min(errors) if stalled(errors) else 0.0
        mine = [r for r, e in zip(ladder, errors, strict=True) if floor < e < ASYMPTOTIC_ERROR]
        errors = [r["max_orientation_error_rad"] for r in mine]
        orders[name] = fit_order([r["dt"] for r in mine], errors) if len(mine) >= 3 else None
    return orders


def setting_label(row) -> str:
    """``dt=…`` for a fixed-step row, ``tol=…`` for an adaptive one."""
    return f"dt={row['dt']:.3g}" if row["kind"] == "fixed" else f"tol={row['tol']:.0e}"


def recommend(rows, budgets=None):
    """For each error budget (rad), the row that meets it at the least wall time per particle.

    Default budgets: every decade from 1e-1 down to the smallest error on the
    table. Rows whose error is not finite (a step past a scheme's stability limit) meet no
    budget. Returns a list of ``(budget, row or None)``.
    """
    finite = [r for r in rows if math.isfinite(r["max_orientation_error_rad"])]
    if budgets is None:
        smallest = min((r["max_orientation_error_rad"] for r in finite), default=1.0)
        lowest = math.floor(math.log10(max(smallest, 1e-16)))
        budgets = [10.0**e for e in range(-1, lowest - 1, -1)] if lowest <= -1 else [1e-1]
    picks = []
    for budget in budgets:
        ok = [r for r in finite if r["max_orientation_error_rad"] <= budget]
        picks.append((budget, min(ok, key=lambda r: r["us_per_particle_run"]) if ok else None))
    return picks


def format_recommendation(rows) -> str:
    parts = []
    for budget, row in recommend(rows):
        if row is None:
            parts.append(f"≤{budget:.0e}: none")
        else:
            parts.append(
                f"≤{budget:.0e}: {row['method']} {setting_label(row)} ({row['us_per_particle_run']:.3g} µs)"
            )
    return "fastest within error budget [rad] (µs per particle over the horizon): " + "; ".join(parts)


def budget_table(rows, budgets=None) -> list:
    """Per error budget, each side's fastest row and how many times faster jaxrot's is.

    Returns ``[(budget, fastest jaxrot row or None, fastest diffrax row or None, ratio or None)]``
    with ``ratio`` = diffrax's wall time / jaxrot's (> 1: jaxrot is faster), at the budgets of
    `recommend` over all rows unless ``budgets`` are given.
    """
    budgets = [b for b, _ in recommend(rows, budgets)]
    ours = recommend([r for r in rows if not _is_diffrax(r)], budgets)
    theirs = recommend([r for r in rows if _is_diffrax(r)], budgets)
    table = []
    for (budget, mine), (_, best) in zip(ours, theirs, strict=True):
        ratio = best["us_per_particle_run"] / mine["us_per_particle_run"] if mine and best else None
        table.append((budget, mine, best, ratio))
    return table


def _is_diffrax(row) -> bool:
    """A diffrax solver's row (the ``diffrax_…`` methods: `ADAPTIVE_SOLVERS`, and Kvaerno5 in a fluid)."""
    return row["method"].startswith("diffrax_")


def format_budget_table(rows) -> str:
    """`budget_table` as text: one line per budget, the row to pick and its speed-up over diffrax."""

    def pick(row):
        return (
            "none"
            if row is None
            else f"{row['method']} {setting_label(row)} ({row['us_per_particle_run']:.3g} µs)"
        )

    head = (
        f"{'budget [rad]':>12}  {'fastest jaxrot row':<40} {'fastest diffrax row':<40} {'diffrax/jaxrot':>14}"
    )
    lines = [head, "-" * len(head)]
    for budget, mine, best, ratio in budget_table(rows):
        speed = "—" if ratio is None else f"{ratio:.1f}×"
        lines.append(f"{budget:>12.0e}  {pick(mine):<40} {pick(best):<40} {speed:>14}")
    return "\n".join(lines)


def _maybe(x):
    return "—" if x is None else f"{x:.2e}"


def format_table(rows) -> str:
    header = (
        f"{'method':<15} {'dt | tol':>12} {'steps':>7} {'max q err[rad]':>14} {'|Δω| final':>10} "
        f"{'rel ΔE':>9} {'torque ev':>9} {'µs/p-step':>9} {'µs/part.':>9} {'compile s':>9}"
    )
    lines = [header, "-" * len(header)]
    for r in rows:
        lines.append(
            f"{r['method']:<15} {setting_label(r):>12} {r['n_steps']:>7d} "
            f"{r['max_orientation_error_rad']:>14.3e} "
            f"{r['final_omega_error']:>10.2e} {_maybe(r['rel_energy_drift']):>9} {r['torque_evals']:>9d} "
            f"{r['us_per_particle_step']:>9.4f} {r['us_per_particle_run']:>9.3g} {r['compile_s']:>9.2f}"
        )
    for name, order in measured_orders(rows).items():
        fitted = (
            f"n/a: fewer than 3 rungs between {ASYMPTOTIC_ERROR} rad and the floor"
            if order is None
            else f"{order:.3f}"
        )
        nominal = next(r["order"] for r in rows if r["method"] == name)
        lines.append(f"measured order ({name}): {fitted} (nominal {nominal})")
    lines.append(format_recommendation(rows))
    if any(_is_diffrax(r) for r in rows) and not all(_is_diffrax(r) for r in rows):
        lines += ["", format_budget_table(rows)]
    return "\n".join(lines)


def write_csv(rows, path) -> Path:
    """``rows`` (dicts with the first row's keys) as a CSV file at ``path``."""
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    return Path(path)


def write_outputs(rows, out_dir, plot=True) -> list[Path]:
    """Write ``compare.csv``, ``compare.json`` and (optionally) ``compare.png`` to ``out_dir``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = [write_csv(rows, out / "compare.csv"), out / "compare.json"]
    recommendation = [
        {"budget_rad": b, "method": r and r["method"], "setting": r and setting_label(r)}
        for b, r in recommend(rows)
    ]
    with open(written[1], "w") as f:
        json.dump(
            {
                "machine": machine_info(),
                "orders": measured_orders(rows),
                "recommendation": recommendation,
                "rows": rows,
            },
            f,
            indent=2,
        )
    if plot:
        written.append(plot_work_precision(rows, out / "compare.png"))
    return written


def plot_work_precision(rows, path=None, axes=None):
    """Work-precision plot: error against wall time per particle and against torque evaluations.

    Log-log, one line per method (fixed-step schemes solid with circles, adaptive diffrax
    dashed with squares), the legend outside the axes. Saves to ``path`` when given; draws on
    ``axes`` (two Axes) when given.
    """
    import matplotlib

    if axes is None:
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = None
    if axes is None:
        fig, axes = plt.subplots(1, 2, figsize=(12.5, 4.2), constrained_layout=True)
    ax_time, ax_evals = axes
    # Fixed-step schemes: solid, circles, the ten colours of tab10; adaptive solvers: dashed, in
    # greys with their own markers (with 13 methods one colour cycle would repeat).
    fixed_styles = iter(dict(marker="o", linestyle="-", color=c) for c in plt.get_cmap("tab10").colors * 2)
    adaptive_styles = iter(
        dict(marker=m, linestyle="--", color=c)
        for m, c in zip("sD^v" * 2, ("black", "dimgray", "darkgray", "silver") * 2, strict=True)
    )
    for name in dict.fromkeys(r["method"] for r in rows):
        mine = [r for r in rows if r["method"] == name]
        style = dict(next(fixed_styles if mine[0]["kind"] == "fixed" else adaptive_styles), label=name)
        err = [r["max_orientation_error_rad"] for r in mine]
        ax_time.loglog([r["us_per_particle_run"] for r in mine], err, **style)
        ax_evals.loglog([max(r["torque_evals"], 1) for r in mine], err, **style)
    first = rows[0]
    ax_time.set(
        xlabel="wall time per particle over the horizon [µs]",
        ylabel="max orientation error [rad]",
        title=f"{first['scene']}, {first['dtype']}, {first['particles']} particles",
    )
    ax_evals.set(xlabel="torque evaluations per particle", ylabel="max orientation error [rad]")
    for ax in axes:
        ax.grid(True, which="both", alpha=0.3)
    # Outside the axes: inside, it covered the high-order rows' lower-left corner.
    ax_evals.legend(fontsize="small", loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0)
    if path is not None:
        (fig or ax_time.figure).savefig(path, dpi=120)
    if fig is not None:
        plt.close(fig)
    return path
