"""mkdocs hook: the measured tables of the docs, rendered from the data files under docs/.

A page writes ``{{ name }}`` of a table in `TABLES` on a line of its own; the hook replaces it
with a Markdown table built from ``docs/throughput_cpu.json``, ``docs/memory_cpu.json``,
``docs/compare_heavy_top.json`` or the GPU results under ``docs/gpu_h100/`` and ``docs/gpu_h200/``,
so the pages show exactly what the benchmarks wrote.
"""

import json
from pathlib import Path


def _read(docs, name):
    """The results file ``docs/name``, parsed."""
    return json.loads((docs / name).read_text())


def _table(header, rows):
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(cell) for cell in row) + " |" for row in rows]
    return "\n".join(lines)


def _sig(x, digits=3):
    return f"{x:.{digits}g}"


def _power_of_ten(n):
    exponent = len(str(n)) - 1
    superscript = str(exponent).translate(str.maketrans("0123456789", "⁰¹²³⁴⁵⁶⁷⁸⁹"))
    return f"10{superscript}" if n == 10**exponent else str(n)


def _pivot(docs, field, scale, digits):
    data = _read(docs, "throughput_cpu.json")
    methods = list(dict.fromkeys(row["method"] for row in data["rows"]))
    cases = list(dict.fromkeys((row["dtype"], row["n"]) for row in data["rows"]))
    values = {(row["dtype"], row["n"], row["method"]): row[field] for row in data["rows"]}
    rows = [
        [dtype, _power_of_ten(n)]
        + [_sig(values[dtype, n, m] * scale, digits) if (dtype, n, m) in values else "–" for m in methods]
        for dtype, n in cases
    ]
    header = ["dtype", "N"] + [f"`{m}`" if m != "jax_md" else "jax_md (NO_SQUISH)" for m in methods]
    machine = data["machine"]
    return _table(header, rows) + _provenance(
        "throughput_cpu.json", machine, f" (jax_md {machine.get('jax_md', '–')})"
    )


def throughput_table(docs):
    return _pivot(docs, "particle_steps_per_s", 1e-6, 3)


def compile_table(docs):
    return _pivot(docs, "compile_s", 1.0, 2)


def memory_table(docs):
    data = _read(docs, "memory_cpu.json")
    header = [
        "scheme",
        "steps",
        "save every",
        "chunk steps",
        "saved states",
        "peak RSS [MiB]",
        "peak before the run [MiB]",
        "XLA output [MiB]",
        "XLA temp [MiB]",
        "wall time [s]",
    ]
    rows = [
        [
            f"`{r['scheme']}`",
            r["steps"],
            r["save_every"],
            r["chunk_steps"] or "–",
            r["saved_states"],
            f"{r['peak_rss_mib']:.0f}",
            f"{r['rss_before_mib']:.0f}",
            f"{r['xla_output_mib']:.0f}",
            f"{r['xla_temp_mib']:.0f}",
            f"{r['seconds']:.1f}",
        ]
        for r in data["rows"]
    ]
    n = data["rows"][0]["n"]
    return _table(header, rows) + _provenance(
        "memory_cpu.json", data["machine"], f" ({n:.0e} bodies, float64)"
    )


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


def _provenance(name, machine, context=""):
    """The italic line under a table from a schema-2 results file: where, on what, from which commit."""
    m = machine
    return (
        f"\n\n*From `docs/{name}`{context}: {m['cpus']} CPU cores, Python {m['python']}, "
        f"jax {m['jax']}, diffrax {m['diffrax']}, commit {m['commit']}, {m['date']}.*"
    )


def _run_time(r):
    return r["us_per_particle_run"]


def _pick(r):
    return "none" if r is None else f"`{r['method']}` {_setting(r)}: {_sig(_run_time(r), 3)} µs"


def _gpu_throughput_rows(docs):
    """(dtype, N, barriers, {scheme: G particle-steps/s}) from every throughput file."""
    out = []
    for path in sorted((docs / "gpu_h100").glob("tp_*.json")):
        data = json.loads(path.read_text())
        barriers = data["machine"]["stage_barriers"]
        for dtype, n in dict.fromkeys((r["dtype"], r["n"]) for r in data["rows"]):
            rates = {
                r["method"]: r["particle_steps_per_s"] / 1e9
                for r in data["rows"]
                if (r["dtype"], r["n"]) == (dtype, n)
            }
            out.append((dtype, n, barriers, rates, data["machine"]))
    return out


def gpu_throughput_table(docs):
    """G particle-steps/s without `stage` barriers, (×) against with them: docs/gpu_h100/tp_*.json."""
    rows = _gpu_throughput_rows(docs)
    schemes = list(rows[0][3])
    lines = [
        "| dtype | N | " + " | ".join(schemes) + " |",
        "|" + "---|" * (len(schemes) + 2),
    ]
    keys = sorted({(d, n) for d, n, *_ in rows})
    for dtype, n in keys:
        by = {b: rates for d, m, b, rates, _ in rows if (d, m) == (dtype, n)}
        if True in by and False in by:
            cells = [f"{by[False][s]:.2f} ({by[False][s] / by[True][s]:.2f}×)" for s in schemes]
            lines.append(f"| {dtype} | {n:.0e} | " + " | ".join(cells) + " |")
    m = rows[0][4]
    lines.append(f"\n*From `docs/gpu_h100/tp_*.json`: {m['device']}, Python {m['python']}, jax {m['jax']}.*")
    return "\n".join(lines)


def gpu_race_table(docs, name="gpu_h100/race_heavy_top_float64.json"):
    """A race on a lent GPU, one table per scene, from ``docs/name`` (`benchmarks/race.py`'s json, or
    its ``--from-log`` rebuild, flagged as first-pass timings)."""
    data = _read(docs, name)
    lines = []
    for scene, result in data["scenes"].items():
        lines += [
            f"| {scene}: budget [rad] | fastest jaxrot | fastest diffrax | diffrax time / jaxrot time |",
            "|---|---|---|---|",
        ]
        for row in result["table"]:
            ratio = "—" if row["ratio"] is None else f"{row['ratio']:.2f}"
            lines.append(f"| {row['budget']:.0e} | {row['jaxrot']} | {row['diffrax'] or 'none'} | {ratio} |")
        lines.append("")
    if data.get("retimed", True):
        m = data["machine"]
        flags = f", XLA_FLAGS `{m['xla_flags']}`" if m.get("xla_flags") else ""
        lines.append(f"*From `docs/{name}`: {m['device']}, jax {m['jax']}{flags}.*")
    else:
        lines.append(
            f"*From `docs/{name}`, rebuilt from the log `{data['source']}` of a run stopped before its "
            "side-by-side re-timing: first-pass timings, each row timed apart from the others.*"
        )
    return "\n".join(lines)


def gpu_peer_throughput_table(docs, name="gpu_h200/tp_f32_nobar_jax_md.json"):
    """M particle-steps/s of every scheme and jax_md on a lent GPU, and the ratio over jax_md."""
    data = _read(docs, name)
    methods = list(dict.fromkeys(r["method"] for r in data["rows"]))
    lines = [
        "| dtype | N | steps | " + " | ".join(methods) + " |",
        "|" + "---|" * (len(methods) + 3),
    ]
    for dtype, n in dict.fromkeys((r["dtype"], r["n"]) for r in data["rows"]):
        by = {r["method"]: r for r in data["rows"] if (r["dtype"], r["n"]) == (dtype, n)}
        base = by["jax_md"]["particle_steps_per_s"]
        cells = [
            f"{by[m]['particle_steps_per_s'] / 1e6:.3g}"
            + ("" if m == "jax_md" else f" ({by[m]['particle_steps_per_s'] / base:.2f}×)")
            for m in methods
        ]
        steps = next(iter(by.values()))["steps"]
        lines.append(f"| {dtype} | {_power_of_ten(n)} | {steps} | " + " | ".join(cells) + " |")
    m = data["machine"]
    lines.append(
        f"\n*From `docs/{name}`: {m['device']}, Python {m['python']}, jax {m['jax']}, "
        f"jax_md {m['jax_md']}, stage barriers {'on' if m['stage_barriers'] else 'off'}.*"
    )
    return "\n".join(lines)


def gpu_throughput_ratio_table(docs, name, base):
    """M particle-steps/s of each jaxrot scheme in ``docs/name`` and, in brackets, the factor over
    the same scheme in ``docs/base``: two throughput runs of one GPU session differing in one setting."""
    data, ref = _read(docs, name), _read(docs, base)
    rate = {(r["dtype"], r["n"], r["method"]): r["particle_steps_per_s"] for r in ref["rows"]}
    methods = [m for m in dict.fromkeys(r["method"] for r in data["rows"]) if m != "jax_md"]
    lines = ["| dtype | N | " + " | ".join(methods) + " |", "|" + "---|" * (len(methods) + 2)]
    for dtype, n in dict.fromkeys((r["dtype"], r["n"]) for r in data["rows"]):
        by = {
            r["method"]: r["particle_steps_per_s"] for r in data["rows"] if (r["dtype"], r["n"]) == (dtype, n)
        }
        cells = [f"{by[m] / 1e6:.3g} ({by[m] / rate[(dtype, n, m)]:.2f}×)" for m in methods]
        lines.append(f"| {dtype} | {_power_of_ten(n)} | " + " | ".join(cells) + " |")
    m = data["machine"]
    lines.append(
        f"\n*From `docs/{name}` over `docs/{base}`: {m['device']}, Python {m['python']}, jax {m['jax']}.*"
    )
    return "\n".join(lines)


def gpu_passes_table(docs, name="gpu_h100/passes.json"):
    """Kernels in one step's loop body and time per particle-step (`benchmarks/gpu_passes.py`)."""
    data = _read(docs, name)
    header = [
        "program",
        "fusions",
        "copies, transposes",
        "ns per particle-step",
        "bytes per particle-step at the card's bandwidth",
    ]
    rows = [
        [
            r["program"],
            r["fusion"],
            r["copy/transpose"],
            f"{r['ns_per_particle_step']:.3f}",
            f"{r['bytes_at_bandwidth']:.0f}",
        ]
        for r in data["rows"]
    ]
    m = data["machine"]
    footer = f"\n\n*From `docs/{name}`: N = {data['n']:.0e}, float32, {m['device']}, jax {m['jax']}.*"
    return _table(header, rows) + footer


def cpu_vector_width_table(docs, name="cpu_vector_width.json"):
    """Throughput with 512-bit vectors over XLA:CPU's 256, per scheme (`benchmarks/cpu_options.py`)."""
    data = _read(docs, name)
    schemes = list(dict.fromkeys(r["scheme"] for r in data["rows"]))
    rows = []
    for dtype, n in dict.fromkeys((r["dtype"], r["n"]) for r in data["rows"]):
        by = {r["scheme"]: r for r in data["rows"] if (r["dtype"], r["n"]) == (dtype, n)}
        rows.append(
            [dtype, _power_of_ten(n), *(f"{by[s]['rate_512'] / by[s]['rate_256']:.2f}" for s in schemes)]
        )
    m = data["machine"]
    n_same = sum(r["same_bits"] for r in data["rows"])
    same = f"final states the same bits in {n_same} of {len(data['rows'])} cells"
    footer = (
        f"\n\n*From `docs/{name}`: {m['cpu_model']} ({m['cpus']} cores, AVX-512 {m['avx512f']}), "
        f"Python {m['python']}, jax {m['jax']}; {same}.*"
    )
    return _table(["dtype", "N", *schemes], rows) + footer


def gpu_rotor_loop_table(docs, name="gpu_h200/rotor_loop.json"):
    """ms per run of the rotor schemes for each setting of the rotor's while loop (DMV steps per
    iteration; ``fixedK``: no loop, K steps), and the factor over one step per iteration."""
    data = _read(docs, name)
    settings = list(dict.fromkeys(r["loop_batch"] for r in data["rows"]))

    def describe(s):
        if isinstance(s, int):
            return f"{s} per iteration"
        if s.endswith("+cb"):
            return f"{s[:-3]} per iteration, command buffers"
        return f"no loop ({s})"

    label = {s: describe(s) for s in settings}
    lines = [
        "| scheme | steps | " + " | ".join(label[s] for s in settings) + " |",
        "|" + "---|" * (len(settings) + 2),
    ]
    for scheme, steps in dict.fromkeys((r["scheme"], r["steps"]) for r in data["rows"]):
        ms = {r["loop_batch"]: r["ms"] for r in data["rows"] if (r["scheme"], r["steps"]) == (scheme, steps)}
        cells = [
            f"{ms[s]:.3g}" + ("" if s == settings[0] else f" ({ms[settings[0]] / ms[s]:.2f}×)")
            for s in settings
        ]
        lines.append(f"| {scheme} | {steps} | " + " | ".join(cells) + " |")
    m = data["machine"]
    flags = f", XLA_FLAGS `{m['xla_flags']}`" if m["xla_flags"] else ""
    lines.append(f"\n*From `docs/{name}`: {m['device']}, Python {m['python']}, jax {m['jax']}{flags}.*")
    return "\n".join(lines)


def gradient_compile_table(docs):
    """`benchmarks/compile.py`'s table of ``docs/compile_cpu.json`` (that script loaded by its path)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(
        "_compile_benchmark", docs.parent / "benchmarks" / "compile.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    data = _read(docs, "compile_cpu.json")
    note = _provenance("compile_cpu.json", data["machine"], f" ({data['problem']})")
    return module.table(data["rows"]) + note


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


def identify_speed_table(docs):
    """`benchmarks/identify_speed.py`'s fits: jaxrot.identify and the diffrax + optimistix rows."""
    data = _read(docs, "identify_speed_cpu.json")
    base = data["rows"][0]["compiled_s"]
    header = ["fit", "first call [s]", "compiled [s]", "loss", "max Δ vs jaxrot [se]", "model error [rad]"]
    header.append("time / jaxrot's")
    rows = [
        [
            r["fit"],
            f"{r['first_call_s']:.1f}",
            f"{r['compiled_s']:.2f}",
            f"{r['loss']:.1f}",
            f"{r['max_gap_se']:.2f}",
            f"{r['model_error_rad']:.1e}",
            f"{r['compiled_s'] / base:.2f}",
        ]
        for r in data["rows"]
    ]
    ours = data["rows"][0]
    same = [r for r in data["rows"][1:] if r["max_gap_se"] < 0.1]
    best = min(same, key=lambda r: r["compiled_s"])
    run, first = best["compiled_s"] / ours["compiled_s"], best["first_call_s"] / ours["first_call_s"]
    summary = (
        f"\n\nThe fastest diffrax + optimistix fit within 0.1 standard errors of jaxrot's is {best['fit']}: "
        f"compiled {best['compiled_s']:.2f} s against `identify`'s {ours['compiled_s']:.2f} s "
        f"(jaxrot {run:.2f}× as fast), first call {best['first_call_s']:.1f} s against "
        f"{ours['first_call_s']:.1f} s ({first:.2f}×)."
    )
    return _table(header, rows) + summary + _provenance("identify_speed_cpu.json", data["machine"])


def identify_sysid_table(docs):
    """`benchmarks/identify_speed.py`'s comparison with mujoco.sysid on MuJoCo's own telemetry."""
    data = _read(docs, "identify_speed_cpu.json")
    rows = data.get("mujoco")
    if not rows:
        return "*Not measured yet: `benchmarks/identify_speed.py` ran without `mujoco[sysid]`.*"
    header = ["fit", "median wall time [s]", "first call [s]", "relative error", "95 % interval coverage"]
    table = [
        [
            r["fit"],
            f"{r['median_s']:.2f}",
            "—" if r["first_call_s"] is None else f"{r['first_call_s']:.1f}",
            f"{r['relative_error']:.1e}",
            f"{r['coverage95']:.2f}",
        ]
        for r in rows
    ]
    ours, theirs = rows[0], rows[1]
    summary = (
        f"\n\nOver {ours['seeds']} noise seeds (6 inertia elements each): `jaxrot.identify` "
        f"{theirs['median_s'] / ours['median_s']:.0f}× as fast as `mujoco.sysid` fitting the same "
        f"parameters, with {theirs['relative_error'] / ours['relative_error']:.1f}× smaller errors."
    )
    return _table(header, table) + summary + _provenance("identify_speed_cpu.json", data["machine"])


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


def rotor_choice_table(docs, name="rotor_choice_cpu.json"):
    """The rotor's per-body step count against a fixed two at |ω|t = 0.3 (`benchmarks/rotor.py`, 2.)."""
    data = _read(docs, name)
    header = [
        "dtype",
        "program",
        "fixed two [ns per body-step]",
        "per body [ns]",
        "per body / fixed two: median (IQR)",
    ]
    rows = []
    for r in data["rows"]:
        q1, q2, q3 = r["ratio_quartiles"]
        ratio = f"{q2:.3f} ({q1:.3f}–{q3:.3f})"
        rows.append([r["dtype"], r["program"], f"{r['fixed_2_ns']:.1f}", f"{r['per_body_ns']:.1f}", ratio])
    rounds = f"\n\n*N = {data['n']}, ratios per round over {data['rounds']} interleaved rounds.*"
    return _table(header, rows) + rounds + _provenance(name, data["machine"])


def throughput_peer_ratios(docs):
    """One sentence per dtype: each scheme's throughput over jax_md's NO_SQUISH at the largest N."""
    data = _read(docs, "throughput_cpu.json")
    rate = {(r["dtype"], r["n"], r["method"]): r["particle_steps_per_s"] for r in data["rows"]}
    if not any(m == "jax_md" for _, _, m in rate):
        return "*jax_md was not installed for this run: no peer column.*"
    out = []
    for dtype in dict.fromkeys(d for d, _, _ in rate):
        n = max(k for d, k, m in rate if d == dtype and m == "jax_md")
        ratios = [
            f"`{m}` {rate[dtype, n, m] / rate[dtype, n, 'jax_md']:.2f}×"
            for d, k, m in rate
            if (d, k) == (dtype, n) and m != "jax_md"
        ]
        out.append(f"{dtype}, N = {_power_of_ten(n)}: " + ", ".join(ratios))
    return "Throughput over jax_md's NO_SQUISH in the same run (> 1: faster) — " + "; ".join(out) + "."


def _throughput_grid(base, other, cell):
    """``(methods, rows)``: a row ``[dtype, N, cell(base rate, other's) per method]`` per base row."""
    rate = {
        name: {(r["dtype"], r["n"], r["method"]): r["particle_steps_per_s"] for r in data["rows"]}
        for name, data in (("base", base), ("other", other))
    }
    methods = list(dict.fromkeys(r["method"] for r in base["rows"]))
    rows = []
    for dtype, n in dict.fromkeys((r["dtype"], r["n"]) for r in base["rows"]):
        cells = [cell(rate["base"].get((dtype, n, m)), rate["other"].get((dtype, n, m))) for m in methods]
        rows.append([dtype, _power_of_ten(n), *cells])
    return methods, rows


def throughput_jax_versions(docs):
    """Throughput with jax 0.10.2 (M/s) and, in brackets, its ratio to the newest jax's run."""
    old = _read(docs, "throughput_cpu_jax010.json")
    new = _read(docs, "throughput_cpu.json")

    def cell(mine, theirs):
        ratio = f" ({mine / theirs:.2f}×)" if mine and theirs else ""
        return "–" if mine is None else f"{mine * 1e-6:.3g}{ratio}"

    methods, rows = _throughput_grid(old, new, cell)
    m = new["machine"]
    note = f" (ratios against `docs/throughput_cpu.json`: jax {m['jax']}, commit {m['commit']})"
    return _table(["dtype", "N", *[f"`{m}`" for m in methods]], rows) + _provenance(
        "throughput_cpu_jax010.json", old["machine"], note
    )


def ynn_trap_table(docs):
    """jax 0.10.2, float64: XLA's default options against `jaxrot.compiler_options` (M/s and ratio)."""
    default = _read(docs, "throughput_cpu_jax010_xla_defaults.json")
    ours = _read(docs, "throughput_cpu_jax010.json")

    def cell(before, after):
        now = "–" if after is None else f"{after * 1e-6:.3g} ({after / before:.2f}×)"
        return f"{before * 1e-6:.3g} → {now}"

    methods, rows = _throughput_grid(default, ours, cell)
    note = f" (with the options: `docs/throughput_cpu_jax010.json`, commit {ours['machine']['commit']})"
    return _table(["dtype", "N", *[f"`{m}`" for m in methods]], rows) + _provenance(
        "throughput_cpu_jax010_xla_defaults.json", default["machine"], note
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


def gradient_compile_summary(docs):
    """Which schemes compile their gradient within 2× of diffrax's fastest, the looped derivative
    stages against the unrolled ones, and the gradients' run times, from ``docs/compile_cpu.json``."""
    import jaxrot

    rows = _read(docs, "compile_cpu.json")["rows"]
    grad = {r["method"]: r for r in rows if r["kind"] == "gradient"}
    diffrax_rows = [r for m, r in grad.items() if m.startswith("diffrax_")]
    best = min(diffrax_rows, key=lambda r: r["total_s"])
    fastest_run = min(diffrax_rows, key=lambda r: r["run_ms"])
    ratio = {m: grad[m]["total_s"] / best["total_s"] for m in jaxrot.SCHEMES if m in grad}
    within = [f"`{m}`" for m, x in ratio.items() if x <= 2]
    over = [f"`{m}` ({x:.1f}×)" for m, x in ratio.items() if x > 2]
    text = (
        f"Against diffrax's fastest-compiling gradient (`{best['method']}`, {best['total_s']:.1f} s), "
        + (f"{', '.join(within)} compile within 2×" if within else "no scheme compiles within 2×")
        + (f"; {', '.join(over)} {'does' if len(over) == 1 else 'do'} not." if over else ": every scheme.")
    )
    pairs = [
        f"`{m}` {grad[m]['total_s']:.1f} s against {grad[m + '+unrolled']['total_s']:.1f} s"
        for m in jaxrot.SCHEMES
        if m in grad and m + "+unrolled" in grad
    ]
    if pairs:
        text += (
            " With the looped derivative stages (the default) against the unrolled ones "
            "(`loop_derivative_stages=False`, the `+unrolled` rows): " + ", ".join(pairs) + "."
        )
    faster = [f"`{m}`" for m in jaxrot.SCHEMES if m in grad and grad[m]["run_ms"] <= fastest_run["run_ms"]]
    slower = [
        f"`{m}` {grad[m]['run_ms']:.0f} ms"
        for m in jaxrot.SCHEMES
        if m in grad and grad[m]["run_ms"] > fastest_run["run_ms"]
    ]
    text += (
        f"\n\nRunning the gradient (one body, median of 7 runs): against diffrax's fastest "
        f"(`{fastest_run['method']}`, {fastest_run['run_ms']:.0f} ms), "
        + (", ".join(faster) + " run as fast or faster" if faster else "no scheme runs as fast")
        + ("; " + ", ".join(slower) + " take longer." if slower else ".")
    )
    return text


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
            parts.append(f"`{method}` failed at tol {tol:.0e} ({bodies} bodies)")
        if run["reference_vs_dopri8"] is not None:
            parts.append(f"reference within {_sig(run['reference_vs_dopri8'], 2)} rad of Dopri8")
        lines.append(f"- St = {run['stokes']:.0e}: " + "; ".join(parts) + ".")
    return "\n".join(lines)


def fluid_race_figure(docs, name="fluid_race_cpu.png"):
    """The race's figure, once the benchmark has drawn it (a missing image would fail the strict build)."""
    if not (docs / name).exists():
        return ""
    return f"![Error against wall time, one panel per Stokes number]({name})"


# --- Bodies at a temperature (docs/thermal.md) -------------------------------------------------------

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
        order = "exact" if r["order"] is None and r["exact"] is not None else "—"
        if r["order"] is not None:
            order = f"{r['order']:.2f} ± {r['order_stderr']:.2f}"
        if r["exact"] is None:
            limit = f"limit {r['limit']:.4f} ± {r['limit_stderr']:.0e} (no closed form)"
        else:
            gap = r["limit"] - r["exact"]
            limit = f"{gap:+.1e} ({gap / r['limit_stderr']:+.1f} σ)"
        quantity = f"{r['quantity']}, {r['setting']}"
        biases = [_bias_cell(r, i) for i in (0, 2, 5)]
        rows.append(
            [f"`{r['scheme']}`", r["nominal_order"], _ORACLES[r["oracle"]], quantity, order, *biases, limit]
        )
    steps = ["bias at dt = t/8", "bias at dt = t/32", "bias at dt = t/256"]
    header = ["scheme", "nominal", "oracle", "quantity", "fitted weak order", *steps, "extrapolated − exact"]
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


TABLES = {
    "fluid_orders_table": fluid_orders_table,
    "fluid_race_figure": fluid_race_figure,
    "fluid_race_table": fluid_race_table,
    "fluid_race_notes": fluid_race_notes,
    "thermal_orders_table": thermal_orders_table,
    "thermal_peers_table": thermal_peers_table,
    "thermal_jax_md_diagnosis": thermal_jax_md_diagnosis,
    "throughput_table": throughput_table,
    "compile_table": compile_table,
    "gradient_compile_table": gradient_compile_table,
    "memory_table": memory_table,
    "compare_table": compare_table,
    "compare_budget_table": compare_budget_table,
    "compare_orders": compare_orders,
    "gpu_throughput_table": gpu_throughput_table,
    "gpu_race_table": gpu_race_table,
    "gpu_peer_throughput_table": gpu_peer_throughput_table,
    "gpu_rotor_loop_table": gpu_rotor_loop_table,
    "gpu_throughput_ratio_table": gpu_throughput_ratio_table,
    "gpu_passes_table": gpu_passes_table,
    "cpu_vector_width_table": cpu_vector_width_table,
    "race_table_float64": race_table_float64,
    "race_table_float32": race_table_float32,
    "race_summary": race_summary,
    "stability_limits_table": stability_limits_table,
    "stability_blow_up_table": stability_blow_up_table,
    "stability_drift_table": stability_drift_table,
    "identify_speed_table": identify_speed_table,
    "identify_sysid_table": identify_sysid_table,
    "overdamped_cost_table": overdamped_cost_table,
    "order4_table": order4_table,
    "float32_horizon_table": float32_horizon_table,
    "float32_rotor_table": float32_rotor_table,
    "order4_summary": order4_summary,
    "rotor_choice_table": rotor_choice_table,
    "mujoco_free_body_accuracy": mujoco_free_body_accuracy,
    "mujoco_free_body_speed": mujoco_free_body_speed,
    "throughput_peer_ratios": throughput_peer_ratios,
    "throughput_jax_versions": throughput_jax_versions,
    "ynn_trap_table": ynn_trap_table,
    "measured": measured,
    "front_door_speed": front_door_speed,
    "gradient_compile_summary": gradient_compile_summary,
}


def on_page_markdown(markdown, page, config, files):
    """Replace each ``{{ name }}`` (or ``{{ name argument }}``) line naming a table in `TABLES` by
    that table."""
    docs = Path(config["docs_dir"])
    lines = markdown.split("\n")
    for i, line in enumerate(lines):
        stripped = line.strip()
        if stripped.startswith("{{") and stripped.endswith("}}"):
            name, *arguments = stripped[2:-2].split()
            if name not in TABLES:
                raise KeyError(
                    f"{page.file.src_path}: unknown table {{{{ {name} }}}}; known: {sorted(TABLES)}"
                )
            indent = line[: len(line) - len(line.lstrip())]
            lines[i] = "\n".join(indent + row for row in TABLES[name](docs, *arguments).split("\n"))
    return "\n".join(lines)
