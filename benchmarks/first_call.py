"""First-call cost of jaxrot's public entries beside the peer a user would take, with and without JAX's
persistent compilation cache.

Each cell runs in a fresh Python process (JAX's in-memory caches of traced and compiled functions
empty, as at a user's first call), three times:

- ``off`` (persistent cache off): a single jitted function is split into JAX's ahead-of-time stages,
  ``jax.jit(f).trace(*args)`` (``trace_s``), ``.lower()`` (``lower_s``), ``.compile()``
  (``compile_s``) and its first run (``run_s``), with the optimised HLO's instruction count
  (``hlo_ops``, as `benchmarks/compile.py` counts it); jaxrot's programs compile with
  `jaxrot.compiler_options`, as `jaxrot.rollout` does at top level, the peers' with XLA's defaults.
  An entry that is not one jitted function (``identify``, ``fit_inertia``, the ``compare`` command)
  is timed as one whole first call (wall), with the programs it compiled and their XLA seconds
  counted by `jax.monitoring` (``/jax/core/compile/backend_compile_duration``).
- ``cold`` and ``warm``: the entry as a user calls it (`jaxrot.rollout` at top level, ``jax.jit`` of
  a gradient or of a ``diffeqsolve``, the whole call), after the one line that switches the
  persistent cache on, ``jax.config.update("jax_compilation_cache_dir", DIR)``, with JAX's other
  settings at their defaults (only programs that take over a second to compile are written): first
  with an empty DIR, then in a second process sharing it. ``cache_hits`` counts the programs read
  back. Everything a cell builds before its call (data, scenes) is compiled first and then
  `jax.clear_caches` empties the in-memory caches.

The problems: the heavy top of `benchmarks/compile.py` (200 steps of 0.005, saving every 10th,
one body, float64) for the vacuum rollouts, their gradient and diffrax's Tsit5 on the same
`jaxrot.RigidBodyTerm`; the spheroid in shear (Stokes number 0.1, 200 steps) for ``exp_rk4`` with
``fluid=`` against Tsit5 on the fluid's torque as a callable; 256 magnetic nanoparticles at kT = 1
for ``baoab`` (its peer, jax_md's rigid-body ``nvt_langevin``, needs Python 3.12); the heavy top over
2 s for `jaxrot.solver` in ``diffrax.diffeqsolve`` with a PID controller against Tsit5; the test
satellite of `benchmarks/identify_speed.py` for ``identify`` against diffrax Tsit5 at the sample
spacing + optimistix Gauss–Newton (tolerance 1e-4, the fastest fit of the same quality there); the
MuJoCo free body of that script for ``identify`` against ``mujoco.sysid``'s whole fit (skipped
without ``mujoco[sysid]``); the fitting notebook's heavy top for ``fit_inertia``; and
``python -m jaxrot compare`` as a whole command (wall time of the process).

    python benchmarks/first_call.py                   # writes docs/first_call_cpu.json (~10 min, 2 cores)
    python benchmarks/first_call.py --quick --out /tmp/f.json   # no compare, no MuJoCo (~6 min)
    python benchmarks/first_call.py --entries rollout_zhao,diffrax_tsit5 --out /tmp/f.json
"""

import argparse
import json
import logging
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path


HERE = Path(__file__).resolve().parent
MODES = ("off", "cold", "warm")
CACHE_LINE = 'jax.config.update("jax_compilation_cache_dir", DIR)'
BACKEND_COMPILE = "/jax/core/compile/backend_compile_duration"
CACHE_HIT = "/jax/compilation_cache/cache_hits"

# name: (kind, peer row or None, what it measures). kind: "jit" (one jitted function), "call" (a whole
# first call), "command" (a whole process).
ENTRIES = {
    "rollout_zhao": ("jit", "diffrax_tsit5", "`rollout('zhao')`, vacuum"),
    "rollout_rkmk4": ("jit", "diffrax_tsit5", "`rollout('rkmk4')`, vacuum"),
    "rollout_rkmk_dopri8": ("jit", "diffrax_tsit5", "`rollout('rkmk_dopri8')`, vacuum"),
    "diffrax_tsit5": ("jit", None, "diffrax `Tsit5` on `RigidBodyTerm`, same steps"),
    "grad_zhao": ("jit", "grad_diffrax_tsit5", "`jit(grad)` of a `rollout('zhao')` misfit"),
    "grad_rkmk4": ("jit", "grad_diffrax_tsit5", "`jit(grad)` of a `rollout('rkmk4')` misfit"),
    "grad_diffrax_tsit5": ("jit", None, "`jit(grad)` of the same misfit, diffrax `Tsit5`"),
    "rollout_exp_rk4_fluid": ("jit", "diffrax_tsit5_fluid", "`rollout('exp_rk4', fluid=)`"),
    "diffrax_tsit5_fluid": ("jit", None, "diffrax `Tsit5`, the fluid's torque as a callable"),
    "rollout_baoab_thermal": ("jit", None, "`rollout('baoab', fluid=, key=)`, kT > 0, 256 bodies"),
    "solver_rkmk_dopri5": ("jit", "diffeqsolve_tsit5", "`diffeqsolve(solver('rkmk_dopri5'))`, PID"),
    "diffeqsolve_tsit5": ("jit", None, "`diffeqsolve(Tsit5())`, PID, same tolerances"),
    "identify": ("call", "diffrax_optimistix", "`identify`, the test satellite (whole call)"),
    "diffrax_optimistix": ("call", None, "diffrax `Tsit5` + optimistix `GaussNewton`"),
    "identify_mujoco": ("call", "mujoco_sysid", "`identify`, MuJoCo's free body (whole call)"),
    "mujoco_sysid": ("call", None, "`mujoco.sysid` (no JAX: the whole fit)"),
    "fit_inertia": ("call", None, "`fit_inertia`, the fitting notebook's heavy top"),
    "jax_md_nvt_langevin_jaxrot": ("jit", "jax_md_nvt_langevin", "`jaxrot.jax_md.nvt_langevin`, 1000 steps"),
    "jax_md_nvt_langevin": ("jit", None, "jax_md `simulate.nvt_langevin`, rigid bodies"),
    "compare": ("command", None, "`python -m jaxrot compare --repeats 1 --no-plot` (imports aside)"),
}
# The default run leaves out grad_rkmk4 (10 minutes in all); --entries measures any of them.
DEFAULT = [name for name in ENTRIES if name != "grad_rkmk4"]
QUICK = [name for name in DEFAULT if name not in ("compare", "identify_mujoco", "mujoco_sysid")]
# Entries measured in fewer modes: sysid compiles nothing (no JAX); the command and identify on MuJoCo's
# data, the longest cells, run cold and warm only (their first call in the table is the cold one: an
# empty cache, its entries written), so that the whole job fits in 10 minutes.
ENTRY_MODES = {"mujoco_sysid": ("off",), "compare": ("cold", "warm"), "identify_mujoco": ("cold", "warm")}


def _hlo_ops(compiled):
    hlo = compiled.as_text() or ""
    return sum(1 for line in hlo.splitlines() if " = " in line and not line.lstrip().startswith("//"))


def _on_path():
    """This checkout's package first (not an editable install of another checkout: a git worktree's
    scripts would measure the main one's jaxrot), then benchmarks/ and tests/ (the problems' helpers)."""
    sys.path[:0] = [str(HERE.parent), str(HERE), str(HERE.parent / "tests")]


def measure_one(name, mode, cache_dir):
    """One cell in this process (a fresh one): the entry's first call in ``mode``."""
    import jax

    if mode != "off":
        jax.config.update("jax_compilation_cache_dir", cache_dir)  # the documented line
    before = dict(jax.config.values)
    _on_path()
    import jaxrot

    changed = sorted(k for k, v in jax.config.values.items() if before.get(k) != v)
    jax.config.update("jax_enable_x64", True)
    events = {"compiles": 0, "compile_s": 0.0, "cache_hits": 0}

    def on_duration(event, seconds, **_):
        if event == BACKEND_COMPILE:
            events["compiles"] += 1
            events["compile_s"] += seconds

    def on_event(event, **_):
        if event == CACHE_HIT:
            events["cache_hits"] += 1

    jax.monitoring.register_event_duration_secs_listener(on_duration)
    jax.monitoring.register_event_listener(on_event)
    # Why a compiled program was not written to the cache (JAX says so at DEBUG level).
    not_written = {"host_callbacks": 0, "under_min_compile_time": 0}

    class _Why(logging.Handler):
        def emit(self, record):
            message = record.getMessage()
            if message.startswith("Not writing persistent cache entry"):
                key = "host_callbacks" if "host callbacks" in message else "under_min_compile_time"
                not_written[key] += 1

    compiler_log = logging.getLogger("jax._src.compiler")
    compiler_log.setLevel(logging.DEBUG)
    compiler_log.addHandler(_Why(logging.DEBUG))
    row = {"entry": name, "mode": mode, "import_changed_config": changed}
    kind = ENTRIES[name][0]
    if kind == "command":
        from jaxrot.__main__ import main

        with tempfile.TemporaryDirectory() as out:
            start = time.perf_counter()
            main(["compare", "--out", out, "--no-plot", "--repeats", "1"])
            row["first_call_s"] = time.perf_counter() - start
        return row | {
            "programs": events["compiles"],
            "programs_compile_s": events["compile_s"],
            "cache_hits": events["cache_hits"],
            "not_written": dict(not_written) if mode == "cold" else None,
        }
    from _first_call_problems import Skip, build

    try:
        jitted, call = build(name)
    except Skip as why:
        return row | {"skipped": str(why)}
    jax.clear_caches()
    events.update(compiles=0, compile_s=0.0, cache_hits=0)
    not_written.update(host_callbacks=0, under_min_compile_time=0)
    if mode == "off" and jitted is not None:
        fn, example = jitted
        peer = any(name == p for _, p, _ in ENTRIES.values())  # a peer compiles with XLA's defaults
        options = {} if peer else jaxrot.compiler_options()
        start = time.perf_counter()
        traced = jax.jit(fn, compiler_options=options or None).trace(*example)
        t_trace = time.perf_counter()
        lowered = traced.lower()
        t_lower = time.perf_counter()
        compiled = lowered.compile()
        t_compile = time.perf_counter()
        jax.block_until_ready(compiled(*example))
        done = time.perf_counter()
        row |= {
            "trace_s": t_trace - start,
            "lower_s": t_lower - t_trace,
            "compile_s": t_compile - t_lower,
            "run_s": done - t_compile,
            "first_call_s": done - start,
            "hlo_ops": _hlo_ops(compiled),
        }
        return row | {"programs": events["compiles"], "programs_compile_s": events["compile_s"]}
    start = time.perf_counter()
    jax.block_until_ready(call())
    row["first_call_s"] = time.perf_counter() - start
    return row | {
        "programs": events["compiles"],
        "programs_compile_s": events["compile_s"],
        "cache_hits": events["cache_hits"],
        "not_written": dict(not_written) if mode == "cold" else None,
    }


def run_cell(name, mode, cache_dir):
    """One cell in a fresh process; its row, with the process's wall time (interpreter start and imports
    included) as ``process_s``."""
    env = {**os.environ, "JAX_ENABLE_COMPILATION_CACHE": "false" if mode == "off" else "true"}
    env.pop("JAX_COMPILATION_CACHE_DIR", None)
    start = time.perf_counter()
    out = subprocess.run(
        [sys.executable, __file__, "--one", name, mode, cache_dir], capture_output=True, text=True, env=env
    )
    seconds = time.perf_counter() - start
    if out.returncode != 0:  # recorded and shown as such; the other cells still run
        print(out.stderr[-3000:], file=sys.stderr)
        error = (out.stderr.strip().splitlines() or ["no message"])[-1][:200]
        return {"entry": name, "mode": mode, "skipped": f"FAILED: {error}", "process_s": seconds}
    return json.loads(out.stdout.strip().splitlines()[-1]) | {"process_s": seconds}


def _cell(rows, name, mode, field, fmt):
    row = rows.get((name, mode))
    return "–" if row is None or row.get(field) is None else fmt.format(row[field])


def _programs(row):
    return "–" if not row or "programs" not in row else f"{row['programs']} ({row['programs_compile_s']:.1f})"


def table(data):
    """Markdown: one row per entry, its peer's row below it."""
    rows = {(r["entry"], r["mode"]): r for r in data["rows"]}
    skipped = {r["entry"]: r["skipped"] for r in data["rows"] if "skipped" in r}
    header = [
        "entry", "trace [s]", "lower [s]", "XLA compile [s]", "first run [s]", "first call [s]",
        "÷ peer", "HLO ops", "cold: programs (XLA s)", "cold cache [s]", "warm cache [s]", "warm ÷ cold",
        "warm: read back",
    ]  # fmt: skip
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    names = [n for n in dict.fromkeys(r["entry"] for r in data["rows"])]
    peers = {peer for _, peer, _ in ENTRIES.values() if peer}
    groups = {}  # each peer after the entries measured against it
    for n in names:
        groups.setdefault(n, []) if n in peers else groups.setdefault(ENTRIES[n][1] or n, []).append(n)
    order = [m for key, group in groups.items() for m in group + ([key] if key in peers else [])]
    first = {n: (rows.get((n, "off")) or rows.get((n, "cold")) or {}).get("first_call_s") for n in ENTRIES}
    for n in order:
        label = "↳ " + ENTRIES[n][2] if n in peers else ENTRIES[n][2]
        if n in skipped or (n not in names):
            reason = skipped.get(n, "not in this run")
            lines.append(f"| {label} | " + " | ".join(["–"] * 4) + f" | skipped: {reason} |" + " – |" * 7)
            continue
        off = rows.get((n, "off"), {})
        peer = ENTRIES[n][1]
        ratio = f"{first[n] / first[peer]:.2f}×" if peer and first.get(peer) and first.get(n) else "–"
        cold, warm = (rows.get((n, m), {}).get("first_call_s") for m in ("cold", "warm"))
        cells = [
            label,
            _cell(rows, n, "off", "trace_s", "{:.2f}"),
            _cell(rows, n, "off", "lower_s", "{:.2f}"),
            _cell(rows, n, "off", "compile_s", "{:.2f}"),
            _cell(rows, n, "off", "run_s", "{:.2f}"),
            "–" if first[n] is None else f"{first[n]:.2f}" + ("" if "trace_s" in off or off else " (cold)"),
            ratio,
            _cell(rows, n, "off", "hlo_ops", "{}"),
            _programs(rows.get((n, "cold"))),
            "–" if cold is None else f"{cold:.2f}",
            "–" if warm is None else f"{warm:.2f}",
            f"{warm / cold:.2f}" if cold and warm else "–",
            _cell(rows, n, "warm", "cache_hits", "{}") + "/" + _cell(rows, n, "warm", "programs", "{}")
            if (n, "warm") in rows
            else "–",
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + _not_written(data["rows"])


def _not_written(rows):
    """A sentence: what the cold runs compiled but did not write to the cache, and why."""
    cells = [
        f"{ENTRIES[r['entry']][2]} {r['not_written']['under_min_compile_time']} + "
        f"{r['not_written']['host_callbacks']}"
        for r in rows
        if r["mode"] == "cold" and r.get("not_written") and any(r["not_written"].values())
    ]
    if not cells:
        return ""
    return (
        "\n\n*Not written to the cache in the cold runs (compiled in under a second + with host "
        "callbacks): " + "; ".join(cells) + ".*"
    )


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--entries", default=None, help=f"comma-separated of {list(ENTRIES)}")
    parser.add_argument("--quick", action="store_true", help="leave out compare and the MuJoCo rows")
    parser.add_argument("--modes", default=",".join(MODES))
    parser.add_argument("--out", default=str(HERE.parent / "docs" / "first_call_cpu.json"))
    parser.add_argument("--one", nargs=3, metavar=("ENTRY", "MODE", "CACHE_DIR"), help=argparse.SUPPRESS)
    opts = parser.parse_args()
    if opts.one:
        print(json.dumps(measure_one(*opts.one)))
        return

    _on_path()
    from jaxrot.comparison import machine_info

    names = opts.entries.split(",") if opts.entries else (QUICK if opts.quick else DEFAULT)
    unknown = set(names) - set(ENTRIES)
    if unknown:
        parser.error(f"unknown entries {sorted(unknown)}; known: {list(ENTRIES)}")
    modes = opts.modes.split(",")
    rows = []
    start = time.perf_counter()
    for name in names:
        with tempfile.TemporaryDirectory(prefix="jax_cache_") as cache_dir:
            for mode in [m for m in modes if m in ENTRY_MODES.get(name, MODES)]:
                row = run_cell(name, mode, cache_dir)
                rows.append(row)
                print(f"{name:24s} {mode:5s} {row.get('first_call_s') or 0:7.2f} s "
                      f"(process {row['process_s']:.1f} s) {row.get('skipped', '')}", flush=True)  # fmt: skip
                if "skipped" in row:
                    break
    result = {
        "machine": machine_info(),
        "modes": modes,
        "cache_line": CACHE_LINE,
        "rows": rows,
        "wall_s": time.perf_counter() - start,
    }
    Path(opts.out).write_text(json.dumps(result, indent=1) + "\n")
    print(table(result))
    print(f"\n{result['wall_s']:.0f} s; written: {opts.out}")


if __name__ == "__main__":
    main()
