"""Accuracy tables: stability limits and drift, float32 horizons, the fourth-order comparison,
MuJoCo's free body."""

from _tables_format import _power_of_ten, _provenance, _read, _sig, _table


def _stability(docs):
    return _read(docs, "stability_cpu.json")


def _limit(x):
    return "≥ 10" if x >= 10 else _sig(x)


def stability_limits_table(docs):
    """Largest |ω|Δt per scheme and body (float64; float32 after a slash where it differs)."""
    data = _stability(docs)
    value = {(r["scheme"], r["body"], r["dtype"]): r["limit"] for r in data["limits"]}
    bodies = list(dict.fromkeys(r["body"] for r in data["limits"]))
    rows = []
    for name in dict.fromkeys(r["scheme"] for r in data["limits"]):
        cells = []
        for body in bodies:
            f64, f32 = _limit(value[name, body, "float64"]), _limit(value[name, body, "float32"])
            cells.append(f64 if f64 == f32 else f"{f64} / {f32}")
        rows.append([f"[`{name}`](schemes/{name}.md)", *cells])
    return _table(["scheme", *bodies], rows) + _provenance("stability_cpu.json", data["machine"])


def stability_blow_up_table(docs):
    """The first |ω|Δt (of 131 from 1e-12 to 10) with a non-finite result within 8 steps, per dtype."""
    data = _stability(docs)
    first = {(r["scheme"], r["dtype"]): r["first_nonfinite"] for r in data["blow_up"]}
    rows = [
        [f"`{name}`"]
        + ["none ≤ 10" if first[name, d] is None else _sig(first[name, d]) for d in ("float64", "float32")]
        for name in dict.fromkeys(r["scheme"] for r in data["blow_up"])
    ]
    return _table(["scheme", "first non-finite |ω|Δt, float64", "float32"], rows)


def stability_drift_table(docs):
    """Drifts of a long torque-free run per scheme and dtype."""
    data = _stability(docs)
    rows = []
    for r in data["drift"]:
        energy = _sig(r["energy"], 2) + ("" if r["first_nonfinite_step"] is None else " (NaN)")
        rows.append([f"`{r['scheme']}`", r["dtype"], _sig(r["norm"], 2), energy, _sig(r["momentum"], 2)])
    steps = data["drift"][0]["steps"]
    header = ["scheme", "dtype", "max ‖q‖ − 1", "max ΔE / E₀", "max ‖ΔL‖ / ‖L₀‖"]
    return _table(header, rows) + _provenance("stability_cpu.json", data["machine"], f" ({steps:.0e} steps)")


def _steps(n, total):
    return f"> {_power_of_ten(total)}" if n is None else str(n)


def float32_horizon_table(docs, name="float32_horizon.json"):
    """Per scheme and problem: the float32 run's angle from its float64 run after 10³ and 10⁵ steps,
    and the first step (of every tenth) at which it exceeds each threshold (`benchmarks/float32.py`)."""
    data = _read(docs, name)
    thresholds = data["thresholds"]
    problems = list(data["problems"])
    header = ["scheme"]
    for problem in problems:
        header += [f"{problem}: after 10³", "after 10⁵"] + [f"steps to {t:.0e} rad" for t in thresholds]
    by_scheme = {}
    for problem in problems:
        for r in data["problems"][problem]:
            cells = [
                "–" if r[f"angle_after_{n}"] is None else _sig(r[f"angle_after_{n}"], 2)
                for n in (1000, 100_000)
            ]
            cells += [_steps(r[f"steps_to_{t:g}"], r["steps"]) for t in thresholds]
            by_scheme.setdefault(r["scheme"], []).extend(cells)
    rows = [[f"[`{scheme}`](schemes/{scheme}.md)", *cells] for scheme, cells in by_scheme.items()]
    return _table(header, rows) + _provenance(name, data["machine"])


def float32_rotor_table(docs, name="float32_horizon.json"):
    """The DMV rotor's two interfaces chained in float32 against float64 (`benchmarks/float32.py`)."""
    data = _read(docs, name)
    header = [
        "rotor interface",
        "flows",
        "L direction [rad]",
        "‖L‖ (relative)",
        "energy (relative)",
        "orientation [rad]",
    ]
    rows = [
        [
            f"`{r['interface']}`",
            r["calls"],
            _sig(r["momentum_direction_rad"], 2),
            _sig(r["momentum_norm_rel"], 2),
            _sig(r["energy_rel"], 2),
            _sig(r["orientation_rad"], 2),
        ]
        for r in data["rotor"]
    ]
    return _table(header, rows)


_ORDER4_PROBLEMS = {"dzhanibekov": "Dzhanibekov flip", "generic": "tumbling body", "heavy_top": "heavy top"}


def order4_table(docs, name="order4.json"):
    """The fourth-order Lie-group methods (`benchmarks/order4.py`): per problem the error at equal
    torque calls (four per reference step) and, in brackets, the fitted order."""
    data = _read(docs, name)
    rows = []
    for r in data["rows"]:
        cells = []
        for key in _ORDER4_PROBLEMS:
            p = r["problems"].get(key)
            if p is None:
                cells.append("–")
            elif p["error_at_equal_calls"] is None:  # below the fitted rungs: at round-off
                order = "" if p["fitted_order"] is None else f"; {p['fitted_order']:.2f}"
                cells.append(f"round-off ({_sig(p['errors'][0], 2)} at dt = {p['dts'][0]:g}{order})")
            else:
                cells.append(f"{_sig(p['error_at_equal_calls'], 2)} ({p['fitted_order']:.2f})")
        rows.append([r["method"], r["torque_calls_per_step"], r["exponentials"], *cells])
    header = ["method", "torque calls / step", "exponentials / step", *_ORDER4_PROBLEMS.values()]
    machine = data["machine"]
    mujoco = machine.get("mujoco") or "absent: its row skipped"
    return _table(header, rows) + _provenance(name, machine, f" (mujoco {mujoco})")


def order4_summary(docs, name="order4.json"):
    """One sentence: rkmk4 against the world-momentum RKMK4 it replaced, and against MuJoCo's RK4."""
    data = _read(docs, name)
    rows = {r["method"]: r["problems"] for r in data["rows"]}
    ours = rows["rkmk4: RKMK4, body momentum (jaxrot)"]
    before = rows["RKMK4, world momentum L (jaxrot's rkmk4 before)"]
    gains = [before[k]["error_at_equal_calls"] / ours[k]["error_at_equal_calls"] for k in _ORDER4_PROBLEMS]
    text = (
        f"At equal torque calls `rkmk4`'s errors are {min(gains):.1f}× to {max(gains):.1f}× smaller than "
        "those of the same tableau on the world angular momentum"
    )
    mujoco = rows.get("MuJoCo 4.0 RK4 (free body)")
    if mujoco:
        ratios = [mujoco[k]["error_at_equal_calls"] / ours[k]["error_at_equal_calls"] for k in mujoco]
        text += f", and {min(ratios):.3f}× to {max(ratios):.3f}× MuJoCo 4.0's RK4 on the free bodies"
    return text + "."


def _mujoco(docs):
    return _read(docs, "mujoco_free_body_cpu.json")


def _mujoco_context(data):
    s, m = data["settings"], data["machine"]
    return f" ({s['n']} bodies, t = {s['t_end']:g}, MuJoCo {m.get('mujoco', '–')})"


def mujoco_free_body_accuracy(docs):
    """`benchmarks/mujoco_free_body.py`: each method's error at t_end at a few step sizes, and its order."""
    data = _mujoco(docs)
    t_end = data["settings"]["t_end"]
    errors = {(r["method"], r["n_steps"]): r["error_rad"] for r in data["rows"]}
    steps = [n for n in (32, 256, 2048, 16384, 65536) if any(k[1] == n for k in errors)]
    methods = list(dict.fromkeys(r["method"] for r in data["rows"]))
    header = ["method", *[f"dt = {t_end / n:.3g}" for n in steps], "order"]
    rows = [
        [f"`{m}`"]
        + [
            ("blew up" if errors[m, n] is None else _sig(errors[m, n], 2)) if (m, n) in errors else "–"
            for n in steps
        ]
        + [_sig(data["orders"][m], 3) if data["orders"].get(m) is not None else "–"]
        for m in methods
    ]
    note = (
        "\n\nMaximum orientation error over the bodies at t = t_end [rad] against the exact free top; "
        "– where a ladder had stopped (its error at the 1e-12 floor or no longer falling) or not reached "
        "that step; order: the slope of log error against log dt over the rungs between {:.0e} and {:g} rad."
    ).format(*data["settings"]["order_fit_rad"])
    return (
        _table(header, rows)
        + note
        + _provenance("mujoco_free_body_cpu.json", data["machine"], _mujoco_context(data))
    )


def mujoco_free_body_speed(docs):
    """MuJoCo's cost per body-step on each path, and each budget's cheapest row of both sides."""
    data = _mujoco(docs)
    provenance = _provenance("mujoco_free_body_cpu.json", data["machine"], _mujoco_context(data))
    if not data["settings"]["timed"]:
        return (
            "*Not timed yet: the results file holds the errors only, measured on a loaded machine (load "
            "does not move an error). `python benchmarks/regenerate.py --only mujoco_free_body` on a quiet "
            "machine adds the timings and these tables.*" + provenance
        )
    paths = list(dict.fromkeys(p["path"] for p in data["mujoco_paths"]))
    cost = {(p["integrator"], p["path"]): p["ns_per_body_step"] for p in data["mujoco_paths"]}
    integrators = list(dict.fromkeys(p["integrator"] for p in data["mujoco_paths"]))
    path_rows = [
        [f"`{i}`"] + [_sig(cost[i, p], 3) if (i, p) in cost else "–" for p in paths] for i in integrators
    ]
    path_table = _table(["MuJoCo [ns per body-step]", *[f"`{p}`" for p in paths]], path_rows)

    def cell(r, side):
        if r is None:
            return "none"
        where = f", `{r['path']}`" if side == "mujoco" else ""
        return f"`{r['method']}`{where}, {r['n_steps']} steps: {_sig(r['us_per_body'], 3)} µs"

    budget_rows = [
        [
            f"{b['budget_rad']:.0e}",
            cell(b["mujoco"], "mujoco"),
            cell(b["jaxrot"], "jaxrot"),
            "–" if b["ratio"] is None else f"{b['ratio']:.1f}",
        ]
        for b in data["budgets"]
    ]
    budget_table = _table(
        ["budget [rad]", "MuJoCo's cheapest (per body)", "jaxrot's cheapest (per body)", "MuJoCo / jaxrot"],
        budget_rows,
    )
    return path_table + "\n\n" + budget_table + provenance
