"""The jax_md page's tables (docs/jax_md.md): temperatures per axis, NVE energy error, cost per body-step."""

from _tables_format import _provenance, _read, _table


def _axes(r):
    return ", ".join(f"{m:.3f}" for m in r["axes"]) + f" (± {max(r['axes_error']):.3f})"


def jax_md_temperature_table(docs, name="jax_md_cpu.json"):
    """Per-axis rotational and translational temperature / kT of both thermostats against dt."""
    data = _read(docs, name)
    by = {}
    for r in data["rows"]:
        by.setdefault((r["system"], r["dt"]), {})[r["method"]] = r
    methods = ["jaxrot baoab", "jax_md nvt_langevin"]
    rows = []
    for (system, dt), found in by.items():
        first = found[methods[0]]
        label = f"{system} ({first['bodies']} bodies × {first['snapshots']} snapshots)"
        cells = [_axes(found[m]) for m in methods]
        centres = " / ".join(f"{found[m]['centres']:.3f}" for m in methods)
        rows.append([label, f"1/{round(1 / dt)}", *cells, centres])
    header = ["system", "dt", "jaxrot.jax_md baoab: axes 1, 2, 3", "jax_md nvt_langevin: axes 1, 2, 3",
              "centres (jaxrot / jax_md)"]  # fmt: skip
    s = data["setting"]
    gamma = f"RigidBody({s['gamma'][0]:g}, {s['gamma'][1]:g})"
    note = f" (kT = {s['kT']:g}, gamma = {gamma}; ± the largest standard error)"
    return _table(header, rows) + _provenance(name, data["machine"], note)


def jax_md_energy_table(docs, name="jax_md_cpu.json"):
    """max |E(t)/E(0) − 1| of jax_md's nve and jaxrot.jax_md.nve at equal dt."""
    data = _read(docs, name)
    methods = list(dict.fromkeys(r["method"] for r in data["energy"]))
    dts = sorted({r["dt"] for r in data["energy"]})
    value = {(r["method"], r["dt"]): r["max_relative_energy_error"] for r in data["energy"]}
    rows = [[f"1/{round(1 / dt)}", *(f"{value[m, dt]:.2e}" for m in methods)] for dt in dts]
    note = " (40 soft-sphere tetrahedra, density 0.1, kT = 1, t = 20)"
    return _table(["dt", *methods], rows) + _provenance(name, data["machine"], note)


def jax_md_cost_table(docs, name="jax_md_cpu.json"):
    """Seconds per body-step of both thermostats, free bodies and interacting ones, and their ratio."""
    data = _read(docs, name)
    by = {}
    for r in data["cost"]:
        by.setdefault(r["system"], {})[r["method"]] = r
    rows = []
    for system, found in by.items():
        ours, theirs = found["jaxrot baoab"], found["jax_md nvt_langevin"]
        a, b = ours["seconds_per_body_step"], theirs["seconds_per_body_step"]
        label = f"{system} ({ours['bodies']} bodies, dt = 1/{round(1 / ours['dt'])})"
        rows.append([label, f"{a * 1e9:.0f} ns", f"{b * 1e9:.0f} ns", f"{a / b:.2f}"])
    header = ["system", "jaxrot.jax_md baoab", "jax_md nvt_langevin", "jaxrot / jax_md"]
    note = f" (median of {data['cost'][0]['rounds']} interleaved rounds of {data['cost'][0]['steps']} steps)"
    return _table(header, rows) + _provenance(name, data["machine"], note)


def jax_md_brownian_table(docs, name="jax_md_brownian.json"):
    """jaxrot.jax_md.brownian against closed forms: Favro's P1, P2 per body axis, the centres' spread, and
    dipoles' mean cosine against the Langevin function; each with its standard error."""
    data = _read(docs, name)
    axes = ("x", "y", "z")

    def cell(value, error, exact):
        return f"{value:.4f} ± {error:.4f} ({exact:.4f})"

    rows = [
        [f"t = {r['t']:g}", *(cell(r["p1"][k], r["p1_error"][k], r["p1_favro"][k]) for k in range(3))]
        + [cell(r["msd_over_6Dt"], r["msd_over_6Dt_error"], 1.0)]
        for r in data["free"]
    ]
    favro = _table(["free body", *(f"⟨P₁⟩ body {a} (Favro)" for a in axes), "centres' msd / 6Dt"], rows)
    rows = [
        [f"μB/kT = {r['field_over_kT']:g}", cell(r["cos"], r["cos_error"], r["langevin"])]
        for r in data["dipole"]
    ]
    dipole = _table(["dipole", "⟨cos θ⟩ (Langevin function)"], rows)
    s = data["setting"]
    note = (
        f" ({data['free'][0]['bodies']} bodies, kT = {s['kT']:g},"
        f" rotational friction {s['rotational_friction']},"
        f" dt = {data['free'][0]['dt']:g} free and {data['dipole'][0]['dt']:g} in the field; accuracy only)"
    )
    return favro + "\n\n" + dipole + _provenance(name, data["machine"], note)
