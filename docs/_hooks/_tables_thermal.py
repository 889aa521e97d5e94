"""The thermal page's tables (docs/thermal.md): weak orders, the peers, jax_md's O step."""

from _tables_format import _provenance, _read, _sig, _table


_ORACLES = {"a": "(a) equipartition", "b": "(b) dipole, L(x)", "c": "(c) free diffusion"}


def _bias_cell(r, i):
    if r["exact"] is None:
        return "—"
    bias, err = r["mean"][i] - r["exact"], r["stderr"][i]
    return f"{bias:+.1e}" if abs(bias) > 2 * err else f"< {2 * err:.0e}"


def thermal_orders_table(docs, name="thermal_orders.json"):
    """Weak orders per scheme and oracle: the fitted slope, the bias at three steps, the limit's gap."""
    data = _read(docs, name)
    rows = []
    for r in data["rows"]:
        order = "below noise" if r["order"] is None and r["exact"] is not None else "—"
        if r["order"] is not None:
            order = f"{r['order']:.2f} ± {r['order_stderr']:.2f}"
        if r["exact"] is None:
            limit = f"limit {r['limit']:.4f} ± {r['limit_stderr']:.0e} (no closed form)"
        else:
            gap = r["limit"] - r["exact"]
            limit = f"{gap:+.1e} ({gap / r['limit_stderr']:+.1f} σ)"
        quantity = f"{r['quantity']}, {r['setting']}"
        biases = [_bias_cell(r, i) for i in (0, 2, 5)]
        resolved = [(i, p) for i, p in enumerate(r.get("local_orders") or []) if p is not None]
        local = "—"
        if resolved:
            i, (p, err) = resolved[-1]
            local = f"{p:.2f} ± {err:.2f} (h = {_sig(r['dt'][i], 2)} → {_sig(r['dt'][i + 1], 2)})"
        scheme = f"`{r['scheme']}`"
        oracle = _ORACLES[r["oracle"]]
        rows.append([scheme, r["nominal_order"], oracle, quantity, order, local, *biases, limit])
    steps = ["bias at dt = t/8", "bias at dt = t/32", "bias at dt = t/256"]
    header = ["scheme", "nominal", "oracle", "quantity", "fitted weak order", "finest local order", *steps,
              "extrapolated − exact"]  # fmt: skip
    note = f" ({data['bodies']} bodies, steps t/8 … t/256)"
    return _table(header, rows) + _provenance(name, data["machine"], note)


def _cost_at(rows, method, cost, field, budget):
    """Seconds of compute per body and unit time for ``|field| <= budget`` (the largest dt that meets it,
    with its statistical error below the budget), or None."""
    for r in sorted((r for r in rows if r["method"] == method), key=lambda r: -r["dt"]):
        bias, err = r[field], r[field + "_stderr"]
        if bias == bias and abs(bias) + 2 * err <= budget:
            return cost[method] / r["dt"]
    return None


def thermal_peers_table(docs, name="thermal_peers.json"):
    """The peers' biases against dt, the |q| drift of diffrax, and (when timed) the cost at equal bias."""
    data = _read(docs, name)
    rows = []

    def cell(r, field):
        value, err = r[field], r[field + "_stderr"]
        return "NaN / diverged" if value != value or abs(value) > 1e3 else f"{value:+.1e} ± {err:.0e}"

    for r in data["rows"]:
        drift = "—" if r["max_norm_drift"] is None else _sig(r["max_norm_drift"], 2)
        biases = [cell(r, f) for f in ("temperature_bias", "cos_theta_bias", "correlation_bias")]
        rows.append([r["method"], r["dt"], *biases, drift])
    text = _table(
        ["method", "dt", "temperature bias", "⟨cos θ⟩ bias", "⟨e_i(1)·e_i(0)⟩ bias", "max ||q| − 1|"], rows
    )
    text += _provenance(name, data["machine"], f" ({data['rows'][0]['bodies']} bodies per method)")
    if not data.get("cost"):
        return text + (
            "\n\n*Cost per body-step: not measured in this file (timings need a quiet machine: "
            "`python benchmarks/thermal_peers.py --timing`).*"
        )
    cost = {c["method"]: c["seconds_per_body_step"] for c in data["cost"]}
    methods = list(cost)
    budget_rows = []
    for field, label in (("temperature_bias", "temperature"), ("cos_theta_bias", "⟨cos θ⟩")):
        for budget in (0.1, 0.03, 0.01):
            cells = [_cost_at(data["rows"], m, cost, field, budget) for m in methods]
            ours = [
                c for m, c in zip(methods, cells, strict=True) if m.startswith("jaxrot") and c is not None
            ]
            best = min(ours) if ours else None
            shown = []
            for c in cells:
                if c is None:
                    shown.append("not reached")
                else:
                    ratio = "" if best is None else f" ({c / best:.1f}×)"
                    shown.append(f"{c * 1e9:.0f} ns{ratio}")
            budget_rows.append([f"|{label} bias| ≤ {budget:g}", *shown])
    per_step = ["cost per body-step", *(f"{cost[m] * 1e9:.0f} ns" for m in methods)]
    table = _table(["budget (bias + 2σ)", *methods], [per_step, *budget_rows])
    return (
        text + "\n\nCompute per body and unit of simulated time at the largest dt that meets each budget "
        "(× the cheapest jaxrot scheme):\n\n" + table
    )


def thermal_jax_md_diagnosis(docs, name="thermal_peers.json"):
    """jax_md's rotational temperature and tangent-space defect, shipped and with the exact O step."""
    data = _read(docs, name)
    d = data.get("jax_md_diagnosis")
    if not d:
        return "*(jax_md was not installed when `docs/thermal_peers.json` was written.)*"

    def cells(x):
        axes = ", ".join(f"{v:.3f}" for v in x["kinetic_per_axis_over_kT"])
        return [axes, _sig(x["p_dot_q_squared"], 2)]

    rows = [
        ["as shipped", *cells(d["shipped"])],
        ["O step's noise with the exact covariance", *cells(d["exact_covariance"])],
    ]
    note = f" (torque-free, dt = {d['dt']:g}, {d['steps']} steps from the Maxwell law, {d['bodies']} bodies)"
    header = ["jax_md nvt_langevin", "⟨I_k ω_k²⟩ / kT, k = 1, 2, 3", "⟨(P·q)²⟩ (0 on the tangent space)"]
    return _table(header, rows) + _provenance(name, data["machine"], note)
