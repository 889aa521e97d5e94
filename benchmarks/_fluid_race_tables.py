"""The fluid race's sides, budgets and report: which rows are diffrax's, per budget the fastest row of
each side and their ratio, the overdamped model's error floor, and the work-precision figure."""

import diffrax


# Every ratio is diffrax's row against jaxrot's at one of these budgets [rad].
BUDGETS = [10.0**-k for k in range(2, 9)]
DIFFRAX = {"diffrax_tsit5": diffrax.Tsit5, "diffrax_kvaerno5": diffrax.Kvaerno5, "diffrax_kencarp4": None}


def is_diffrax(row):
    return row["method"] in DIFFRAX


def label(row):
    if row is None:
        return None
    setting = f"{row['n_steps']} steps" if row["kind"] == "fixed" else f"tol {row['tol']:.0e}"
    return f"{row['method']} {setting} {row['seconds'] * 1e3:.3g} ms"


def budget_table(rows):
    table = []
    for budget in BUDGETS:
        ok = [r for r in rows if r["max_orientation_error_rad"] <= budget]
        ours = min((r for r in ok if not is_diffrax(r)), key=lambda r: r["seconds"], default=None)
        theirs = min((r for r in ok if is_diffrax(r)), key=lambda r: r["seconds"], default=None)
        ratio = theirs["seconds"] / ours["seconds"] if ours and theirs else None
        table.append({"budget": budget, "jaxrot": label(ours), "diffrax": label(theirs), "ratio": ratio})
    return table


def overdamped_floor(rows):
    """The smallest error any overdamped row reached: below it the model's own error disqualifies it."""
    errors = [r["max_orientation_error_rad"] for r in rows if r["model"] == "overdamped"]
    return min(errors) if errors else None


def plot(report, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    runs = report["runs"]
    fig, axes = plt.subplots(
        1, len(runs), figsize=(5.2 * len(runs), 4.2), constrained_layout=True, squeeze=False
    )
    for ax, run in zip(axes[0], runs, strict=True):
        rows = run["rows"]
        for name in dict.fromkeys(r["method"] for r in rows):
            mine = [r for r in rows if r["method"] == name]
            style = {"linestyle": "--", "marker": "s"} if mine[0]["kind"] == "adaptive" else {"marker": "o"}
            ax.loglog(
                [r["seconds"] * 1e3 for r in mine],
                [r["max_orientation_error_rad"] for r in mine],
                label=name,
                **style,
            )
        ax.set(title=f"St = {run['stokes']:g}", xlabel="wall time [ms]", ylabel="max orientation error [rad]")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize="x-small")
    fig.savefig(path, dpi=110)
    plt.close(fig)
