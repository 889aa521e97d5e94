"""The fluid page's tables (docs/fluid.md): orders with a fluid, the overdamped cost, the race in a fluid."""

import json
from pathlib import Path

from _tables_format import _provenance, _read, _sig, _table


def fluid_orders_table(docs, name="fluid_orders.json"):
    """Orders with a fluid (`benchmarks/fluid_orders.py`): each ladder's fitted order and its local ones."""
    data = _read(docs, name)
    rows = []
    for r in data["rows"]:
        span = r["zeta_dt_over_inertia"]
        stiffness = (
            "—" if span is None else ("0" if span[1] == 0 else f"{_sig(span[0], 2)} – {_sig(span[1], 2)}")
        )
        stokes = "—" if r["stokes"] is None else ("0" if r["stokes"] == 0 else f"{r['stokes']:.0e}")
        local = " ".join(f"{x:.2f}" for x in r["local_orders"])
        rows.append([f"`{r['scheme']}`", stokes, r["torque"], stiffness, f"{r['order']:.2f}", local])
    header = ["scheme", "Stokes number", "torque", "ζΔt/I over the ladder", "fitted order", "local orders"]
    return _table(header, rows) + _provenance(name, data["machine"])


def fluid_layer_table(docs, name="fluid_layer.json"):
    """`benchmarks/fluid_layer.py`: local orders across ζΔt/I, off and on the slow manifold, graded or not."""
    data = _read(docs, name)
    rows = []
    for r in data["rows"]:
        span = r["zeta_dt_over_inertia"]
        local = " ".join(f"{x:.1f}" for x in r["local_orders"])
        rows.append(
            [
                f"`{r['scheme']}`",
                f"{r['rate']:.0e}",
                f"{_sig(span[0], 2)} → {_sig(span[-1], 2)}",
                "at rest" if r["start"] == "off" else "on S",
                "yes" if r["graded_start"] else "no",
                f"{_sig(r['errors'][0], 2)} → {_sig(r['errors'][-1], 2)}",
                local,
            ]
        )
    header = ["scheme", "ζ/I", "ζΔt/I", "start", "graded start", "error (rad)", "local orders"]
    return _table(header, rows) + _provenance(name, data["machine"])


def _fluid_race(docs, name):
    path = docs / name
    return json.loads(path.read_text()) if path.exists() else None


def overdamped_cost_table(docs, name="overdamped_cost_cpu.json"):
    """`benchmarks/overdamped_cost.py`: each overdamped scheme's cost per body-step against ``zhao``'s."""
    path = Path(docs) / name
    if not path.exists():
        return f"*Not measured yet: `python benchmarks/overdamped_cost.py --json docs/{name}`.*"
    data = _read(docs, name)
    header = ["scheme", "bodies", "ns per body-step", "× zhao"]
    rows = [
        [r["scheme"], f"{r['bodies']}", f"{r['ns_per_body_step']:.1f}", f"{r['vs_zhao']:.2f}"]
        for r in data["rows"]
    ]
    return _table(header, rows) + _provenance(name, data["machine"], f" ({data['steps']} steps)")


def fluid_step_cost_table(docs, name="fluid_step_cost_cpu.json"):
    """`benchmarks/fluid_step_cost.py`: one exponential step in the race's fluid against rkmk4's with the
    same physics as a torque callable, wall and CPU time per body-step."""
    path = Path(docs) / name
    if not path.exists():
        return "*Not measured yet: `python benchmarks/regenerate.py --only fluid_step_cost`.*"
    data = _read(docs, name)
    header = ["step", "ns per body-step", "× rkmk4", "CPU ns per body-step", "CPU × rkmk4"]
    rows = [
        [
            r["scheme"],
            f"{r['ns_per_body_step']:.1f}",
            f"{r['vs_rkmk4']:.2f}",
            f"{r['cpu_ns_per_body_step']:.1f}",
            f"{r['cpu_vs_rkmk4']:.2f}",
        ]
        for r in data["rows"]
    ]
    rounds = data["rounds"]
    note = f" ({data['bodies']} bodies, St = {data['stokes']:g}, medians of {rounds} interleaved rounds)"

    return _table(header, rows) + _provenance(name, data["machine"], note)


def fluid_race_table(docs, name="fluid_race_cpu.json"):
    """The race in a fluid (`benchmarks/fluid_race.py`): per Stokes number and budget, the fastest row
    of each side and their ratio; a placeholder until the benchmark has written its results file."""
    data = _fluid_race(docs, name)
    if data is None:
        return f"*Not measured yet: `python benchmarks/fluid_race.py` writes `docs/{name}`.*"
    rows = []
    for run in data["runs"]:
        for line in run["table"]:
            ratio = "—" if line["ratio"] is None else f"{line['ratio']:.1f}×"
            rows.append(
                [
                    f"{run['stokes']:.0e}",
                    f"{line['budget']:.0e}",
                    line["jaxrot"] or "none",
                    line["diffrax"] or "none",
                    ratio,
                ]
            )
    header = [
        "Stokes number",
        "budget [rad]",
        "fastest jaxrot row",
        "fastest diffrax row",
        "diffrax time / jaxrot time",
    ]
    return _table(header, rows) + _provenance(name, data["machine"], f" ({data['options']['n']} bodies)")


def fluid_race_notes(docs, name="fluid_race_cpu.json"):
    """Per Stokes number: the overdamped model's smallest error, diffrax's failures, the reference's check."""
    data = _fluid_race(docs, name)
    if data is None:
        return ""
    lines = []
    for run in data["runs"]:
        parts = [
            f"overdamped rows reach {_sig(run['overdamped_floor'], 2)} rad at best (the model's own error)"
        ]
        for solver, why in run["diffrax_failures"]["not_raced"].items():
            parts.append(f"`{solver}` not raced: {why}")
        for failure in run["diffrax_failures"]["failed"]:
            method, tol, bodies = failure["method"], failure["tol"], failure["bodies_failed"]
            parts.append(f"`{method}` not reached at tol {tol:.0e} ({bodies} bodies past its step budget)")
        if run["reference_vs_dopri8"] is not None:
            parts.append(f"reference within {_sig(run['reference_vs_dopri8'], 2)} rad of Dopri8")
        if run.get("rounds_spread") is not None:  # files from 2026-11-29 on
            rounds = data["options"]["rounds"]
            parts.append(
                f"the re-timed rows' rounds (up to {rounds}) spread {run['rounds_spread']:.0%} (median)"
            )
        lines.append(f"- St = {run['stokes']:.0e}: " + "; ".join(parts) + ".")
    return "\n".join(lines)


def fluid_race_figure(docs, name="fluid_race_cpu.png"):
    """The race's figure, once the benchmark has drawn it (a missing image would fail the strict build)."""
    if not (docs / name).exists():
        return ""
    return f"![Error against wall time, one panel per Stokes number]({name})"
