"""The performance page's tables (docs/performance.md): throughput, compile time, memory, GPUs,
XLA options."""

import json
import statistics
from pathlib import Path

from _tables_format import _power_of_ten, _provenance, _read, _sig, _table


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
    context = f" ({m['cpu_model']}, AVX-512 {m['avx512f']})"
    return (
        _table(["dtype", "N", *schemes], rows) + _provenance(name, m, context) + "\n\n" + _width_summary(data)
    )


def _width_summary(data):
    """The sentence under the vector-width table: median, extremes, the schemes that gain in every cell,
    and the cells whose final states differ in the last bits."""
    ratio = {(r["scheme"], r["dtype"], r["n"]): r["rate_512"] / r["rate_256"] for r in data["rows"]}
    (lo_scheme, lo_dtype, lo_n), lo = min(ratio.items(), key=lambda kv: kv[1])
    per_scheme = {}
    for (scheme, _, _), value in ratio.items():
        per_scheme.setdefault(scheme, []).append(value)
    gain = ", ".join(f"{s} ({min(v):.2f}–{max(v):.2f}×)" for s, v in per_scheme.items() if min(v) > 1)
    rows = data["rows"]
    differ = [f"{r['scheme']} {r['dtype']} {_power_of_ten(r['n'])}" for r in rows if not r["same_bits"]]
    return (
        f"Median {statistics.median(ratio.values()):.2f}× over the {len(ratio)} cells, from {lo:.2f}× "
        f"({lo_scheme}, {lo_dtype}, {_power_of_ten(lo_n)} bodies) to {max(ratio.values()):.2f}×; "
        f"{'gaining in every cell: ' + gain if gain else 'no scheme gains in every cell'}. "
        f"Final states differ in the last bits in {len(differ)} of {len(ratio)} cells"
        f"{' (' + ', '.join(differ) + ')' if differ else ''}."
    )


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


def first_call_table(docs):
    """`benchmarks/first_call.py`'s table of ``docs/first_call_cpu.json`` (that script loaded by its path)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(
        "_first_call_benchmark", Path(__file__).resolve().parents[2] / "benchmarks" / "first_call.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    data = _read(docs, "first_call_cpu.json")
    context = f" (cache columns: `{data['cache_line']}`; whole job {data['wall_s'] / 60:.1f} min)"
    return module.table(data) + _provenance("first_call_cpu.json", data["machine"], context)


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
