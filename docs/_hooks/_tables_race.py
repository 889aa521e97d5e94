"""The speed-and-accuracy tables: `python -m jaxrot compare`'s heavy top, the race, the front
door's paragraph and the scheme pages' measured facts."""

from _tables_accuracy import _limit, _stability
from _tables_format import _power_of_ten, _provenance, _read, _sig, _table


def _compare(docs):
    """``docs/compare_heavy_top.json``, written by ``python -m jaxrot compare`` (`jaxrot.comparison`)."""
    return _read(docs, "compare_heavy_top.json")


def _setting(r):
    return f"dt = {r['dt']:.4g}" if r["kind"] == "fixed" else f"tol = {r['tol']:.0e}"


def compare_table(docs):
    data = _compare(docs)
    header = [
        "method",
        "setting",
        "max q error [rad]",
        "final ω error",
        "rel. energy drift",
        "torque calls",
        "µs per particle-step",
        "µs per particle",
    ]
    rows = [
        [
            f"`{r['method']}`",
            _setting(r),
            f"{r['max_orientation_error_rad']:.1e}",
            f"{r['final_omega_error']:.1e}",
            "—" if r["rel_energy_drift"] is None else f"{r['rel_energy_drift']:.1e}",
            r["torque_evals"],
            _sig(r["us_per_particle_step"], 2),
            _sig(r["us_per_particle_run"], 3),
        ]
        for r in data["rows"]
    ]
    return _table(header, rows)


def compare_budget_table(docs):
    """Per error budget: the fastest jaxrot row, the fastest diffrax row and their time ratio
    (`jaxrot.comparison.budget_table`)."""
    from jaxrot.comparison import budget_table

    data = _compare(docs)
    out = [
        [f"{budget:.0e}", _pick(mine), _pick(best), "—" if ratio is None else f"{ratio:.1f}×"]
        for budget, mine, best, ratio in budget_table(data["rows"])
    ]
    header = ["budget [rad]", "fastest jaxrot row", "fastest diffrax row", "diffrax time / jaxrot time"]
    return _table(header, out) + _provenance("compare_heavy_top.json", data["machine"])


def compare_ratios(docs):
    """(smallest, largest) speed-up of jaxrot's fastest row over diffrax's, over the budgets of
    ``docs/compare_heavy_top.json`` where both sides have a row."""
    from jaxrot.comparison import budget_table

    ratios = [ratio for *_, ratio in budget_table(_compare(docs)["rows"]) if ratio is not None]
    return min(ratios), max(ratios)


def compare_orders(docs):
    """The measured orders of the fixed-step rows, one sentence."""
    orders = _compare(docs)["orders"]
    fitted = [f"`{name}` {order:.2f}" for name, order in orders.items() if order is not None]
    missing = [f"`{name}`" for name, order in orders.items() if order is None]
    text = (
        "Measured orders (log-log fit of each ladder's rungs between 0.1 rad and its floor): "
        + ", ".join(fitted)
        + "."
    )
    if missing:
        text += " Fewer than three rungs in that range: " + ", ".join(missing) + "."
    return text


def _run_time(r):
    return r["us_per_particle_run"]


def _pick(r):
    return "none" if r is None else f"`{r['method']}` {_setting(r)}: {_sig(_run_time(r), 3)} µs"


def _race(docs, dtype):
    return _read(docs, f"race_cpu/race_{dtype}.json")


def _race_cell(row):
    method = row["jaxrot"].split()[0] if row["jaxrot"] not in (None, "none") else None
    if method is None:
        return "no row"
    if row["ratio"] is None:
        return f"`{method}`: no diffrax row"
    return f"`{method}`: {row['ratio']:.2f}"


def _race_table(docs, dtype):
    """Budget × scene: the fastest jaxrot row and its speed-up over diffrax's fastest meeting the budget."""
    data = _race(docs, dtype)
    scenes = list(data["scenes"])
    budgets = [row["budget"] for row in data["scenes"][scenes[0]]["table"]]
    rows = [
        [f"{b:.0e}"] + [_race_cell(data["scenes"][s]["table"][i]) for s in scenes]
        for i, b in enumerate(budgets)
    ]
    o = data["options"]
    context = f" (N = {o['n']}, --repeats {o['repeats']} --time-cap {o['time_cap']})"
    return _table([f"budget ({dtype})", *scenes], rows) + _provenance(
        f"race_cpu/race_{dtype}.json", data["machine"], context
    )


def race_ratios(docs, dtype="float64"):
    """(smallest, largest) speed-up of jaxrot's fastest row over diffrax's, over every budget and scene
    where both sides have a row, and the cells where jaxrot is not the faster (ratio ≤ 1)."""
    data = _race(docs, dtype)
    cells = [(s, row) for s, scene in data["scenes"].items() for row in scene["table"]]
    ratios = [row["ratio"] for _, row in cells if row["ratio"] is not None]
    slower = [
        f"{s} at {row['budget']:.0e}" for s, row in cells if row["ratio"] is not None and row["ratio"] <= 1
    ]
    return min(ratios), max(ratios), slower


def race_table_float64(docs):
    return _race_table(docs, "float64")


def race_table_float32(docs):
    return _race_table(docs, "float32")


def race_summary(docs):
    """One sentence from the float64 race: the range of speed-ups, and any cell diffrax wins."""
    low, high, slower = race_ratios(docs)
    if slower:
        return (
            f"jaxrot's fastest row is {low:.2f}× to {high:.2f}× diffrax's fastest where both meet a budget; "
            f"diffrax is as fast or faster in {', '.join(slower)}."
        )
    return (
        f"jaxrot has the fastest row at every budget of every scene in float64, "
        f"{low:.2f}× to {high:.2f}× faster than diffrax's fastest row meeting the same budget."
    )


def measured(docs, name):
    """A scheme page's measured facts, each from the results file named beside it."""
    facts = []
    compare = _compare(docs)
    ladder = [r for r in compare["rows"] if r["method"] == name]
    if ladder:
        rungs = ", ".join(
            f"{r['max_orientation_error_rad']:.1e} at dt = {r['dt']:.3g}"
            for r in ladder
            if r["max_orientation_error_rad"] <= 0.1
        )
        order = compare["orders"].get(name)
        fitted = "" if order is None else f"; fitted order {order:.2f}"
        facts.append(
            ("heavy-top error, t = 5, float64 (rad)", (rungs or "above 0.1 rad on every rung") + fitted,
             "compare_heavy_top.json")
        )  # fmt: skip
    throughput = _read(docs, "throughput_cpu.json")
    rate = {(r["dtype"], r["n"]): r for r in throughput["rows"] if r["method"] == name}
    peer = {(r["dtype"], r["n"]): r for r in throughput["rows"] if r["method"] == "jax_md"}
    for dtype in ("float64", "float32"):
        cells = []
        for (d, n), r in rate.items():
            if d == dtype:
                vs = (
                    f" ({r['particle_steps_per_s'] / peer[d, n]['particle_steps_per_s']:.1f}× jax_md)"
                    if (d, n) in peer
                    else ""
                )
                cells.append(f"{r['particle_steps_per_s'] * 1e-6:.3g} at N = {_power_of_ten(n)}{vs}")
        if cells:
            facts.append((f"M particle-steps/s, heavy top, {dtype}", "; ".join(cells), "throughput_cpu.json"))
    compile_ = _read(docs, "compile_cpu.json")
    kinds = {r["kind"]: r for r in compile_["rows"] if r["method"] == name}
    if kinds:
        text = ", ".join(f"{kind} {r['total_s']:.1f} s" for kind, r in kinds.items())
        facts.append(("compile time (200-step heavy top)", text, "compile_cpu.json"))
    stability = _stability(docs)
    limits = [r for r in stability["limits"] if r["scheme"] == name]
    if limits:
        by = {(r["body"], r["dtype"]): r["limit"] for r in limits}
        bodies = list(dict.fromkeys(r["body"] for r in limits))
        cells = []
        for body in bodies:
            f64, f32 = _limit(by[body, "float64"]), _limit(by[body, "float32"])
            cells.append(f"{body}: {f64}" + ("" if f64 == f32 else f" (float32 {f32})"))
        facts.append(("largest |ω|Δt with error ≤ 1e-3 rad per step", "; ".join(cells), "stability_cpu.json"))
        for r in (r for r in stability["drift"] if r["scheme"] == name):
            text = (
                f"‖q‖ − 1: {_sig(r['norm'], 2)}; energy {_sig(r['energy'], 2)}; |L| {_sig(r['momentum'], 2)}"
            )
            facts.append(
                (f"drift over {r['steps']:.0e} free-body steps, {r['dtype']}", text, "stability_cpu.json")
            )
    race = _race(docs, "float64")
    wins = [
        f"{scene} {row['budget']:.0e} ({row['ratio']:.2f}×)"
        for scene, data in race["scenes"].items()
        for row in data["table"]
        if row["ratio"] is not None and row["jaxrot"].split()[0] == name
    ]
    if wins:
        facts.append(
            ("the race's fastest row (× diffrax's fastest)", "; ".join(wins), "race_cpu/race_float64.json")
        )
    rows = [[what, value, f"`docs/{source}`"] for what, value, source in facts]
    return _table(["measured", "value", "results file"], rows)


def _ranges(picks):
    """Consecutive budgets with the same pick, as ``(largest, smallest, pick, [ratios])``."""
    out = []
    for budget, name, ratio in picks:
        if out and out[-1][2] == name and (out[-1][3][-1] is None) == (ratio is None):
            out[-1][1] = budget
            out[-1][3].append(ratio)
        else:
            out.append([budget, budget, name, [ratio]])
    return out


def _span(values, digits):
    values = [v for v in values if v is not None]
    if not values:
        return "no diffrax row to compare"
    low, high = min(values), max(values)
    return (
        f"{low:.{digits}f}×"
        if f"{low:.{digits}f}" == f"{high:.{digits}f}"
        else f"{low:.{digits}f}× to {high:.{digits}f}×"
    )


def front_door_speed(docs):
    """README's and the home page's speed paragraph: the race's range and, per error range, the scheme
    to pick on the heavy top and its speed-up over diffrax's fastest, from the results files.
    `tests/test_results.py` checks that README.md carries exactly this text."""
    from jaxrot.comparison import budget_table

    low, high, slower = race_ratios(docs)
    race = _race(docs, "float64")
    where = "every error budget from 1e-2 to 1e-10 rad on all three scenes" if not slower else "most budgets"
    lines = [
        f"In the race (`benchmarks/race.py`: {race['options']['n']} random bodies per scene, float64, "
        f"{race['machine']['cpus']} CPU cores), jaxrot's fastest row is faster than diffrax's fastest "
        f"(Tsit5, Dopri5 or Dopri8) at {where}, by {low:.2f}× to {high:.2f}×. Which scheme for which "
        "budget on the heavy top (`python -m jaxrot compare`, 100 bodies, float64):",
        "",
    ]
    picks = [
        (
            budget,
            mine and f"`{mine['method']}`" + (" (adaptive)" if mine["kind"] == "adaptive" else ""),
            ratio,
        )
        for budget, mine, theirs, ratio in budget_table(_compare(docs)["rows"])
        if mine or theirs
    ]
    for largest, smallest, name, ratios in _ranges(picks):
        budgets = f"{largest:.0e} rad" if largest == smallest else f"{largest:.0e} to {smallest:.0e} rad"
        if name is None:
            lines.append(f"- {budgets}: no jaxrot row (diffrax has one)")
        elif ratios[0] is None:
            lines.append(f"- {budgets}: {name} (diffrax has no row this accurate)")
        else:
            lines.append(f"- {budgets}: {name}, {_span(ratios, 1)} faster than diffrax's fastest row")
    return "\n".join(lines)
