"""Energy and momentum over long runs against the rotation per step: `benchmarks/energy_growth.py`'s
results file ``docs/energy_growth.json`` (every vacuum scheme and MJX's integrators)."""

from _tables_format import _power_of_ten, _provenance, _read, _table


NAME = "energy_growth.json"
BODIES = {"tumbling": "tumbling", "dzhanibekov": "Dzhanibekov", "heavy_top": "heavy top"}
# The README's example (README.md, "Use"): its scheme, step (s) and number of steps, on the heavy top.
README_EXAMPLE = ("splitting", 0.005, 1000)
README_RIVAL = "zhao"  # the scheme the example used to take, and the general-purpose one


def _energy(docs):
    return _read(docs, NAME)


def _rows(data):
    return {(r["method"], r["body"]): r for r in data["rows"]}


def _methods(data, wanted=None):
    methods = list(dict.fromkeys(r["method"] for r in data["rows"]))
    return methods if wanted is None else [m for m in wanted.split(",") if m in methods]


def _rung(x, grid):
    """A 1 % step as printed: below the grid, at its top, or the rung."""
    if x is None:
        return f"< {grid[0]:.2g}"
    if x >= grid[-1]:
        return f"≥ {grid[-1]:.3g}"
    return f"{x:.3g}"


def _percent(x):
    return f"{100 * x:g} %"


def _name(method, link):
    if method.startswith("mjx_"):
        return f"MJX `{method.removeprefix('mjx_')}`"
    return f"[`{method}`]({link}{method}.md)" if link is not None else f"`{method}`"


def _context(data):
    s, m = data["settings"], data["machine"]
    if s["mjx"] == "measured":
        mjx = f"; MJX {m.get('mujoco_mjx', '–')}, MuJoCo {m.get('mujoco', '–')}"
    else:
        mjx = f"; MJX {s['mjx']}: its rows are left out"
    return f" ({_power_of_ten(s['steps'])} steps, float64, accuracy only{mjx})"


def energy_limits_table(docs, methods=None):
    """Per method and body, the largest |ω|Δt at which it and every smaller rung keep the energy (and
    the conserved momentum) within the tolerance over the whole run. ``methods`` (comma-separated):
    a subset for a scheme page, whose links are then relative to docs/schemes/."""
    data = _energy(docs)
    s, rows = data["settings"], _rows(data)
    grid = s["grid"]
    bodies = [b for b in BODIES if any(r["body"] == b for r in data["rows"])]
    link = "" if methods else "schemes/"
    lines = []
    for method in _methods(data, methods):
        cells = [_name(method, link)]
        for body in bodies:
            r = rows[method, body]
            cell = f"{_rung(r['energy_limit'], grid)} / {_rung(r['momentum_limit'], grid)}"
            if r["energy_lucky"]:
                cell += " (again at " + ", ".join(f"{x:.3g}" for x in r["energy_lucky"]) + ")"
            cells.append(cell)
        lines.append(cells)
    header = ["method"] + [f"{BODIES[b]}: energy / momentum" for b in bodies]
    ratio = grid[1] / grid[0]
    note = (
        f"\n\nThe largest |ω|Δt (rad per step, |ω| the initial rate) of a log grid of {len(grid)} rungs from "
        f"{grid[0]:.2g} to {grid[-1]:.3g} ({ratio:.2f}× apart) at which that rung and every smaller one stay "
        f"finite with max |ΔE/E₀| ≤ {_percent(s['tolerance'])} (and the conserved momentum's largest "
        f"change, relative to |L₀|, ≤ {_percent(s['tolerance'])}) over all {_power_of_ten(s['steps'])} "
        "steps: the "
        f"limit lies between it and the next rung. “< {grid[0]:.2g}”: the smallest rung fails; "
        f"“≥ {grid[-1]:.3g}”: none does; “again at”: larger rungs that pass the energy test after one "
        "below them failed (not counted)."
    )
    # Accuracy only: the load it ran beside changes no figure, so the provenance line leaves it out.
    machine = {k: v for k, v in data["machine"].items() if k != "load"}
    return _table(header, lines) + note + _provenance(NAME, machine, _context(data))


def _drift(r, i):
    step = r["first_nonfinite_step"][i]
    if step is not None:
        return f"non-finite at step {step}"
    return f"{r['energy_end'][i]:+.1e}"


def energy_drift_table(docs, body="tumbling", methods=None):
    """The signed ΔE/E₀ after the whole run on ``body`` at the settings' fixed rungs, per method."""
    data = _energy(docs)
    s, rows = data["settings"], _rows(data)
    grid = s["grid"]
    # The grid's rungs nearest the fixed ones (they are rungs: 10^(k/10)).
    index = [min(range(len(grid)), key=lambda i, x=x: abs(grid[i] / x - 1)) for x in s["fixed_rungs"]]
    link = "" if methods else "schemes/"
    lines = [
        [_name(m, link)] + [_drift(rows[m, body], i) for i in index]
        for m in _methods(data, methods)
        if (m, body) in rows
    ]
    header = ["method"] + [f"ΔE/E₀ at \\|ω\\|Δt = {grid[i]:.3g}" for i in index]
    return _table(header, lines)


def readme_energy_sentence(docs):
    """README's sentence on why its example ("Use") takes its scheme, from the results file: the
    example's step as |ω|Δt on the heavy top, and the 1 % steps of its scheme and of `zhao`
    (tests/test_energy_growth.py checks README quotes it and runs the scheme and step it names)."""
    data = _energy(docs)
    s, rows = data["settings"], _rows(data)
    scheme, dt, steps = README_EXAMPLE
    grid, tol = s["grid"], _percent(s["tolerance"])
    limit = rows[scheme, "heavy_top"]["energy_limit"]
    if limit is not None and limit >= grid[-1]:
        reach = f"at every step measured, up to |ω|Δt = {grid[-1]:.3g}"
    else:
        reach = f"up to |ω|Δt = {_rung(limit, grid)}"
    return (
        f"The example takes `{scheme}` because over {_power_of_ten(s['steps'])} steps "
        f"({s['steps'] // steps}× this run) it keeps this top's energy within {tol} {reach} (here "
        f"{dt * s['bodies']['heavy_top']['omega0']:.2g}), where `{README_RIVAL}`, second order with any "
        f"torque too and cheaper per step, does only up to "
        f"{_rung(rows[README_RIVAL, 'heavy_top']['energy_limit'], grid)} and gains energy without bound "
        "past it."
    )
