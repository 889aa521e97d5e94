"""The identification page's tables (docs/identification.md): the fit's speed and `mujoco.sysid`."""

import importlib.util
from pathlib import Path

from _tables_format import _provenance, _read, _table


RERUN = "python benchmarks/regenerate.py --only identify_speed"


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


# One fit's columns, shared by the ideal-sensor and real-sensor sysid tables.
_FIT_HEADER = ("fit", "median wall time [s]", "first call [s]", "relative error", "95 % interval coverage")


def _fit_cells(r):
    return [
        r["fit"],
        f"{r['median_s']:.2f}",
        "—" if r["first_call_s"] is None else f"{r['first_call_s']:.1f}",
        f"{r['relative_error']:.1e}",
        f"{r['coverage95']:.2f}",
    ]


def identify_sysid_table(docs):
    """`benchmarks/identify_speed.py`'s comparison with mujoco.sysid on MuJoCo's own telemetry."""
    data = _read(docs, "identify_speed_cpu.json")
    rows = data.get("mujoco")
    if not rows:
        return "*Not measured yet: `benchmarks/identify_speed.py` ran without `mujoco[sysid]`.*"
    header = list(_FIT_HEADER)
    table = [_fit_cells(r) for r in rows]
    ours, theirs = rows[0], rows[1]
    summary = (
        f"\n\nOver {ours['seeds']} noise seeds (6 inertia elements each): `jaxrot.identify` "
        f"{theirs['median_s'] / ours['median_s']:.0f}× as fast as `mujoco.sysid` fitting the same "
        f"parameters, with {theirs['relative_error'] / ours['relative_error']:.1f}× smaller errors."
    )
    return _table(header, table) + summary + _provenance("identify_speed_cpu.json", data["machine"])


def identify_sysid_sensors_table(docs):
    """The same comparison through real sensors (``"mujoco_sensors"`` of identify_speed_cpu.json): each
    tool fitting the five sensor flaws. A file written before these rows says so instead of a table."""
    data = _read(docs, "identify_speed_cpu.json")
    rows = data.get("mujoco_sensors")
    if not rows:
        return (
            f"*Not in `docs/identify_speed_cpu.json` yet (written before these rows): `{RERUN}` adds them.*"
        )
    header = [*_FIT_HEADER, "sensor flaws left out"]
    table = [
        [
            *_fit_cells(r),
            ", ".join(f"`{name}`" for name in r["left_out"]) or "none",
        ]
        for r in rows
    ]
    ours, theirs = rows[0], rows[1]
    ratio = theirs["median_s"] / ours["median_s"]
    summary = (
        f"\n\nOver {ours['seeds']} noise seeds: `jaxrot.identify` {ratio:.0f}× "
        f"as fast as `mujoco.sysid` fitting the same flaws; median errors {ours['relative_error']:.1e} "
        f"against {theirs['relative_error']:.1e}."
    )
    ideal = data.get("mujoco")
    if ideal:
        summary += (
            f" With real sensors jaxrot's fit takes {ours['median_s'] / ideal[0]['median_s']:.2f}× its time "
            f"with ideal ones, sysid's {theirs['median_s'] / ideal[1]['median_s']:.2f}×."
        )
    return _table(header, table) + summary + _provenance("identify_speed_cpu.json", data["machine"])


def capabilities(docs):
    """`benchmarks/_identify_capabilities.CAPABILITIES`, loaded by its path (plain data, no imports)."""
    path = Path(docs).resolve().parent / "benchmarks" / "_identify_capabilities.py"
    spec = importlib.util.spec_from_file_location("_identify_capabilities", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def identify_capabilities_table(docs):
    """What each tool can express, each cell from the code that drives it (`_identify_capabilities`)."""
    module = capabilities(docs)
    rows = [[what, ours["text"], theirs["text"]] for what, ours, theirs in module.CAPABILITIES]
    drivers = "; ".join(
        f"{tool}: " + ", ".join(f"`{f}`" for f in files) for tool, files in module.DRIVERS.items()
    )
    note = (
        f"\n\n*Each cell is code the comparison runs ({drivers}); tests/test_results_identify.py checks it.*"
    )
    return _table(["what", "`jaxrot.identify`", "`mujoco.sysid`"], rows) + note
