"""mkdocs hook: the measured tables of the docs, rendered from the data files under docs/.

A page writes ``{{ name }}`` of a table in `TABLES` on a line of its own; the hook replaces it
with a Markdown table built from ``docs/throughput_cpu.json``, ``docs/memory_cpu.json``,
``docs/compare_heavy_top.json`` or the GPU results under ``docs/gpu_h100/``,
so the pages show exactly what the benchmarks wrote.
"""

import json
from pathlib import Path


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
    data = json.loads((docs / "throughput_cpu.json").read_text())
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
    note = (
        f"\n\n*From `docs/throughput_cpu.json`: {machine['cpus']} CPU cores, Python {machine['python']}, "
        f"jax {machine['jax']}, jax_md {machine.get('jax_md', '–')}.*"
    )
    return _table(header, rows) + note


def throughput_table(docs):
    return _pivot(docs, "particle_steps_per_s", 1e-6, 3)


def compile_table(docs):
    return _pivot(docs, "compile_s", 1.0, 2)


def memory_table(docs):
    data = json.loads((docs / "memory_cpu.json").read_text())
    header = [
        "scheme",
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
            r["save_every"],
            r["chunk_steps"] or "–",
            r["saved_states"],
            f"{r['peak_rss_mib']:.0f}",
            f"{r['rss_before_mib']:.0f}",
            f"{r['xla_output_mib']:.0f}",
            f"{r['xla_temp_mib']:.0f}",
            f"{r['seconds']:.0f}",
        ]
        for r in data
    ]
    return _table(header, rows)


def _compare(docs):
    """``docs/compare_heavy_top.json``, written by ``python -m jaxrot compare`` (`jaxrot.comparison`)."""
    return json.loads((docs / "compare_heavy_top.json").read_text())


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
    (`jaxrot.comparison.recommend` on each side's rows, at the budgets of the run's own recommendation)."""
    from jaxrot.comparison import recommend

    data = _compare(docs)
    budgets = [b["budget_rad"] for b in data["recommendation"]]
    ours = [r for r in data["rows"] if not r["method"].startswith("diffrax")]
    theirs = [r for r in data["rows"] if r["method"].startswith("diffrax")]
    out = []
    for (budget, mine), (_, best) in zip(recommend(ours, budgets), recommend(theirs, budgets), strict=True):
        ratio = f"{_run_time(best) / _run_time(mine):.1f}×" if mine and best else "—"
        out.append([f"{budget:.0e}", _pick(mine), _pick(best), ratio])
    header = ["budget [rad]", "fastest jaxrot row", "fastest diffrax row", "diffrax time / jaxrot time"]
    return _table(header, out) + _provenance("compare_heavy_top.json", data["machine"])


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


def gpu_race_table(docs):
    """The heavy-top race on the H100, from docs/gpu_h100/race_heavy_top_float64.json."""
    data = json.loads((docs / "gpu_h100" / "race_heavy_top_float64.json").read_text())
    lines = [
        "| budget [rad] | fastest jaxrot | fastest diffrax | diffrax time / jaxrot time |",
        "|---|---|---|---|",
    ]
    for row in data["scenes"]["heavy_top"]["table"]:
        ratio = "—" if row["ratio"] is None else f"{row['ratio']:.2f}"
        lines.append(f"| {row['budget']:.0e} | {row['jaxrot']} | {row['diffrax'] or 'none'} | {ratio} |")
    m = data["machine"]
    lines.append(f"\n*From `docs/gpu_h100/race_heavy_top_float64.json`: {m['device']}, jax {m['jax']}.*")
    return "\n".join(lines)


def gradient_compile_table(docs):
    """`benchmarks/compile.py`'s table of ``docs/compile_cpu.json`` (that script loaded by its path)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(
        "_compile_benchmark", docs.parent / "benchmarks" / "compile.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    data = json.loads((docs / "compile_cpu.json").read_text())
    note = _provenance("compile_cpu.json", data["machine"], f" ({data['problem']})")
    return module.table(data["rows"]) + note


TABLES = {
    "throughput_table": throughput_table,
    "compile_table": compile_table,
    "gradient_compile_table": gradient_compile_table,
    "memory_table": memory_table,
    "compare_table": compare_table,
    "compare_budget_table": compare_budget_table,
    "compare_orders": compare_orders,
    "gpu_throughput_table": gpu_throughput_table,
    "gpu_race_table": gpu_race_table,
}


def on_page_markdown(markdown, page, config, files):
    """Replace each ``{{ name }}`` line naming a table in `TABLES` by that table."""
    docs = Path(config["docs_dir"])
    lines = markdown.split("\n")
    for i, line in enumerate(lines):
        stripped = line.strip()
        if stripped.startswith("{{") and stripped.endswith("}}"):
            name = stripped[2:-2].strip()
            if name not in TABLES:
                raise KeyError(
                    f"{page.file.src_path}: unknown table {{{{ {name} }}}}; known: {sorted(TABLES)}"
                )
            indent = line[: len(line) - len(line.lstrip())]
            lines[i] = "\n".join(indent + row for row in TABLES[name](docs).split("\n"))
    return "\n".join(lines)
