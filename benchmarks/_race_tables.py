"""The race's budgets and its tables: per budget, the fastest jaxrot row and the fastest diffrax row
that meet it, their ratio, as printed, as the results file stores them, and rebuilt from a race's log
(``race.py --from-log``)."""

import ast
import json
import re
from pathlib import Path

import diffrax


# diffrax's side of every ratio (the other rows are jaxrot's), and the budgets of each dtype.
DIFFRAX = {"diffrax_tsit5": diffrax.Tsit5, "diffrax_dopri5": diffrax.Dopri5, "diffrax_dopri8": diffrax.Dopri8}
BUDGETS = {"float64": [10.0**-k for k in range(2, 11)], "float32": [10.0**-k for k in range(2, 6)]}


def race_table(rows, budgets):
    """``[(budget, fastest jaxrot row, fastest diffrax row, ratio)]``; ratio > 1 means jaxrot is faster."""
    table = []
    for budget in budgets:
        ok = [r for r in rows if r["max_orientation_error_rad"] <= budget]
        ours = min((r for r in ok if not _is_diffrax(r)), key=_seconds, default=None)
        theirs = min((r for r in ok if _is_diffrax(r)), key=_seconds, default=None)
        ratio = theirs["seconds"] / ours["seconds"] if ours and theirs else None
        table.append((budget, ours, theirs, ratio))
    return table


def _seconds(row):
    return row["seconds"]


def _is_diffrax(row):
    return row["method"] in DIFFRAX


def _label(row):
    if row is None:
        return "none"
    setting = f"{row['n_steps']} steps" if row["kind"] == "fixed" else f"tol {row['tol']:.0e}"
    return f"{row['method']} {setting} {row['seconds'] * 1e3:.3g} ms"


def _table_json(table):
    """`race_table`'s rows as the results file stores them (rows named by `_label`)."""
    return [
        {"budget": b, "jaxrot": o and _label(o), "diffrax": d and _label(d), "ratio": r}
        for b, o, d, r in table
    ]


def format_race(scene_name, dtype, table):
    lines = [
        f"### {scene_name}, {dtype}",
        "| budget [rad] | fastest jaxrot | fastest diffrax | diffrax time / jaxrot time |",
        "|---|---|---|---|",
    ]
    for budget, ours, theirs, ratio in table:
        r = "—" if ratio is None else f"{ratio:.2f}"
        lines.append(f"| {budget:.0e} | {_label(ours)} | {_label(theirs)} | {r} |")
    return "\n".join(lines)


_LADDER_ROW = re.compile(
    r"^  (?P<method>\S+)\s+(?:steps\s+(?P<steps>\d+)|tol\s+(?P<tol>\S+)\s+steps\s+(?P<mean>\S+))"
    r"\s+err\s+(?P<err>\S+)\s+(?P<ms>\S+) ms$"
)


def rows_from_log(lines):
    """``{scene: rows}`` of the ladder lines that `race` logged (error and first-pass time only)."""
    scenes, rows = {}, None
    for line in lines:
        if line.startswith("== ") and "N = " in line:
            rows = scenes.setdefault(line[3:].split(" (")[0], [])
        elif rows is not None and (match := _LADDER_ROW.match(line)):
            fixed = match["steps"] is not None
            rows.append(
                {"method": match["method"], "kind": "fixed" if fixed else "adaptive",
                 "tol": None if fixed else float(match["tol"]),
                 "n_steps": int(match["steps"]) if fixed else int(round(float(match["mean"]))),
                 "max_orientation_error_rad": float(match["err"]), "seconds": float(match["ms"]) / 1e3}
            )  # fmt: skip
    return scenes


def table_from_log(log_path, dtype, out):
    """Print and write (``out/race_DTYPE_firstpass.json``) the race tables rebuilt from a log."""
    lines = Path(log_path).read_text().splitlines()
    prefix = "machine: "
    machine = next(ast.literal_eval(line[len(prefix) :]) for line in lines if line.startswith(prefix))
    report = {"machine": machine, "source": str(log_path), "retimed": False, "scenes": {}}
    for scene_name, rows in rows_from_log(lines).items():
        table = race_table(rows, BUDGETS[dtype])
        print(format_race(scene_name, dtype, table) + "\n(first-pass timings, not re-timed side by side)")
        report["scenes"][scene_name] = {"rows": rows, "table": _table_json(table)}
    with open(Path(out) / f"race_{dtype}_firstpass.json", "w") as f:
        json.dump(report, f, indent=2)
