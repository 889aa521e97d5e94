"""MuJoCo XLA (MJX) against jaxrot: `benchmarks/mjx_peer.py`'s results file ``docs/mjx_cpu.json``."""

from _tables_format import _provenance, _read, _sig, _table


NAME = "mjx_cpu.json"


def _mjx(docs):
    return _read(docs, NAME)


def _context(data):
    s, m = data["settings"], data["machine"]
    sizes = ", **quick sizes**" if s.get("quick") else ""
    return f" (MJX {m.get('mujoco_mjx', '–')}, MuJoCo {m.get('mujoco', '–')}{sizes})"


def _provenance_line(data):
    return _provenance(NAME, data["machine"], _context(data))


def mjx_orders_table(docs):
    """Each method's observed order per problem, its finest error, and MJX-against-reference agreement."""
    data = _mjx(docs)
    problems = list(data["orders"])
    methods = list(dict.fromkeys(m for p in problems for m in data["orders"][p]))
    finest = {}
    for r in data["rows"]:
        if r["error_rad"] is not None:
            finest[r["problem"], r["method"]] = r  # the last rung with an error
    rows = []
    for m in methods:
        cells = [f"`{m}`"]
        for p in problems:
            order = data["orders"][p].get(m)
            f = finest.get((p, m))
            cells.append("–" if order is None else f"{order:.2f}")
            cells.append("–" if f is None else f"{_sig(f['error_rad'], 2)} ({f['n_steps']} steps)")
        rows.append(cells)
    header = ["method"] + [h for p in problems for h in (f"order, {p}", f"finest error [rad], {p}")]
    s = data["settings"]
    agree = "; ".join(
        f"{p}: {_sig(a['error_rad'], 2)} rad at dt = {_sig(a['mjx_rk4_finest_dt'], 3)}"
        for p, a in data["agreement"].items()
    )
    note = (
        f"\n\nOrder: the slope of log error against log dt over the rungs between {s['fit_range_rad'][0]:g} "
        f"and {s['fit_range_rad'][1]:g} rad (steps doubling from 16 to at most {s['max_steps']}; – where "
        "fewer than two rungs fall there: `splitting`'s exact rotor solves the torque-free body to "
        "round-off at any step, `rkmk_dopri8` is below 1e-10 from 32 steps on); error: the "
        f"orientation at t = {s['t_free']:g} (free body) and {s['t_top']:g} (heavy top) against "
        "`jaxrot.reference_rollout` (Dopri8, tolerances 1e-12). Same physics on both sides: MJX RK4's finest "
        f"rung against jaxrot's reference, {agree}, and falling with the step at MJX's order."
    )
    return _table(header, rows) + note + _provenance_line(data)


def mjx_cost_table(docs):
    """Cost per body-step of each method, and each error budget's cheapest method per side."""
    data = _mjx(docs)
    s = data["settings"]
    cost_rows = [
        [f"`{m}`", _sig(c["ns_per_body_step"], 3), "–" if "compile_s" not in c else _sig(c["compile_s"], 2)]
        for m, c in data["costs"].items()
    ]
    cost = _table(["method", f"ns per body-step ({s['n']} bodies)", "compile [s]"], cost_rows)

    def cell(r):
        if r is None:
            return "none"
        return f"`{r['method']}`, {r['n_steps']} steps: {_sig(r['us_per_body'], 3)} µs"

    budget_rows = [
        [
            f"{b['budget_rad']:.0e}",
            cell(b["mjx"]),
            cell(b["jaxrot"]),
            "–" if b["ratio"] is None else f"{b['ratio']:.0f}",
        ]
        for b in data["budgets"]
    ]
    budgets = _table(
        ["budget [rad]", "MJX's cheapest (per body)", "jaxrot's cheapest (per body)", "MJX / jaxrot"],
        budget_rows,
    )
    note = (
        f"\n\nHeavy top, t = {s['t_top']:g}, float64 (not the free body: `splitting`'s exact rotor solves "
        f"it at any step). MJX: `jax.vmap(mjx.step)` over {s['n']} `mjx.Data` in a `fori_loop`, its cost "
        "per body-step the same at any dt; jaxrot: `jaxrot.rollout` on "
        f"{s['n']} bodies (jaxrot's cost timed at the rung's dt). Steps: the fewest of the method's ladder "
        "(above) that meet the budget; µs per body over the horizon = steps × cost per body-step."
    )
    return cost + "\n\n" + budgets + note + _provenance_line(data)


def mjx_gradient_table(docs):
    """The gradient's compile and run time, and the gradient at rest on both sides."""
    data = _mjx(docs)
    s, g = data["settings"], data["gradient"]
    cost = _table(
        ["gradient", "compile [s]", "run [s]", "finite"],
        [[f"`{k}`", _sig(v["compile_s"], 3), _sig(v["run_s"], 3), str(v["finite"])] for k, v in g.items()],
    )

    def vec(x):
        return "(" + ", ".join(f"{v:.4g}" for v in x) + ")"

    rest = _table(
        ["method", "its gradient at ω = 0", "central finite differences of its own map (h = 1e-5)"],
        [
            [f"`{k}`", vec(v["gradient"]), vec(v["finite_difference"])]
            for k, v in data["gradient_at_rest"].items()
        ],
    )
    note = (
        f"\n\nLoss `1 − (q(T)·q_target)²`, q_target = exp({tuple(s['q_target'])}), w.r.t. the initial body "
        f"rates. Cost: {s['grad_n']} free bodies, {s['grad_steps']} steps of {s['grad_dt']:g} "
        "(`jax.lax.scan` over `mjx.step`, `jaxrot.rollout`). At rest: one free body, "
        f"{s['rest_steps']} steps of "
        f"{s['rest_dt']:g}; to first order in ω the motion is q0 ⊗ exp(Tω) (rotation vector Tω) for "
        "every consistent scheme, so every row's finite differences agree."
    )
    return cost + "\n\n" + rest + note + _provenance_line(data)
