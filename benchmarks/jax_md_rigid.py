"""jaxrot.jax_md against jax_md's rigid-body simulators as shipped, in one run: temperature, energy, cost.

On jax_md's own system, the tetrahedra of its tests/rigid_body_test.py (`rigid_body.point_union_shape`
of `rigid_body.tetrahedron` stretched by (1, 2, 3): principal moments (5.4, 10.4, 13.4), mass 4) with
soft-sphere interactions in a periodic box at number density 0.1, and the same bodies free (no
interactions: the thermostat alone):

- ``temperature``: per body axis ``⟨L_l²/I_l⟩ / kT`` and the centres' ``⟨p²/m⟩ / kT`` of
  `jaxrot.jax_md.nvt_langevin` (``"baoab"``) and ``jax_md.simulate.nvt_langevin`` against ``dt``, kT = 1,
  ``gamma = RigidBody(10, 10)``; free bodies (``--bodies``, snapshots one time unit apart, several
  relaxation times) and the interacting tetrahedra at one dt; each with its standard error.
- ``energy``: max ``|E(t)/E(0) − 1|`` over t = 20 in NVE on the interacting tetrahedra (40 bodies,
  kT = 1), jax_md's ``nve`` against `jaxrot.jax_md.nve` (``"splitting"``, the exact rotor, and
  ``"no_squish"``), at equal dt.
- ``cost``: seconds per body-step of each thermostat's compiled step (the median of interleaved
  rounds), free bodies and interacting ones (the energy's cost then included on both sides);
  ``first_call``: seconds of the first call of a 1000-step loop on 40 tetrahedra (trace, compile,
  run; fresh closures each round). The cost table, with the ratios, is printed at the end.

Needs jax_md (``pip install -e ".[jax_md]"``, Python 3.12: jax_md excludes jax 0.10.2)::

    python benchmarks/jax_md_rigid.py                    # writes docs/jax_md_cpu.json
    python benchmarks/jax_md_rigid.py --quick            # the cost table only (a few minutes), printed
    python benchmarks/regenerate.py --only jax_md_rigid --python /path/to/py312/bin/python
"""

import argparse
import importlib.metadata
import json
import statistics
import sys
import time
from pathlib import Path

import jax


jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from jaxrot.comparison import machine_info  # noqa: E402


try:
    from jax_md import rigid_body, simulate
    from jax_md_systems import free_system, shape, tetrahedra

    import jaxrot.jax_md as jm
except ImportError:  # regenerate.py's other jobs run on Python 3.11, where jax_md is not installed
    print(
        "jax_md is not installed: docs/jax_md_cpu.json is left as it is (pip install -e '.[jax_md]' under "
        "Python 3.12, then rerun with that interpreter)",
        file=sys.stderr,
    )
    sys.exit(0)


ROOT = Path(__file__).resolve().parents[1]
KT, G = 1.0, 10.0
DTS = (1 / 64, 1 / 16, 1 / 4, 1 / 2)
NVE_DTS = (1 / 64, 1 / 16, 1 / 4)
METHODS = {"jaxrot baoab": jm.nvt_langevin, "jax_md nvt_langevin": simulate.nvt_langevin}


def axis_temperature(state):
    q, p = state.position.orientation.vec, state.momentum.orientation.vec
    moments = jnp.broadcast_to(state.mass.orientation, q.shape[:-1] + (3,))
    return jnp.mean(jm.angular_momentum(q, p) ** 2 / moments, axis=0)


def translational_temperature(state):
    return jnp.mean(state.momentum.center**2 / state.mass.center)


def temperatures(system, method, dt, snapshots, spacing):
    """Per-axis and translational temperature (mean, standard error over independent snapshots)."""
    energy_fn, shift, body = system
    init_fn, apply_fn = METHODS[method](energy_fn, shift, dt, KT, rigid_body.RigidBody(G, G))
    per = max(1, round(spacing / dt))

    @jax.jit
    def run(state):
        def snapshot(s, _):
            s = jax.lax.fori_loop(0, per, lambda i, s_: apply_fn(s_), s)
            return s, (axis_temperature(s), translational_temperature(s))

        state, _ = snapshot(state, None)
        return jax.lax.scan(snapshot, state, None, length=snapshots)[1]

    rot, trans = (np.asarray(x) for x in run(init_fn(jax.random.key(2), body, mass=shape().mass())))

    def stats(x):
        return x.mean(axis=0).tolist(), (x.std(axis=0, ddof=1) / np.sqrt(len(x))).tolist()

    (rot_mean, rot_err), (tr_mean, tr_err) = stats(rot), stats(trans)
    return {"axes": rot_mean, "axes_error": rot_err, "centres": tr_mean, "centres_error": tr_err}


def energy_errors(dts, n=40, t_end=20.0):
    energy_fn, shift, body = tetrahedra(n)

    def total(s):
        return energy_fn(s.position) + rigid_body.kinetic_energy(s.position, s.momentum, s.mass)

    sims = {
        "jax_md nve": simulate.nve,
        "jaxrot nve splitting": jm.nve,
        "jaxrot nve no_squish": lambda e, s, dt: jm.nve(e, s, dt, scheme="no_squish"),
    }
    found = []
    for dt in dts:
        for name, sim in sims.items():
            init_fn, apply_fn = sim(energy_fn, shift, dt)
            state = init_fn(jax.random.key(5), body, KT, mass=shape().mass())
            e0 = total(state)
            steps = round(t_end / dt)

            def run(s, apply_fn=apply_fn, steps=steps):
                def step(s_, _):
                    s_ = apply_fn(s_)
                    return s_, total(s_)

                return jax.lax.scan(step, s, None, length=steps)[1]

            err = float(jnp.max(jnp.abs(jax.jit(run)(state) / e0 - 1)))
            found.append({"method": name, "dt": dt, "max_relative_energy_error": err})
            print(f"nve {name:22s} dt={dt:.4f} max|dE/E| = {err:.3e}", file=sys.stderr, flush=True)
    return found


def cost(system, label, dt, steps, rounds):
    """Seconds per body-step of each method's step (one compiled loop of ``steps``), interleaved rounds."""
    energy_fn, shift, body = system
    n = body.center.shape[0]
    runs = {}
    for method, sim in METHODS.items():
        init_fn, apply_fn = sim(energy_fn, shift, dt, KT, rigid_body.RigidBody(G, G))
        state = init_fn(jax.random.key(3), body, mass=shape().mass())
        loop = jax.jit(lambda s, f=apply_fn: jax.lax.fori_loop(0, steps, lambda i, s_: f(s_), s))
        start = time.perf_counter()
        compiled = loop.lower(state).compile()
        compile_s = time.perf_counter() - start
        jax.block_until_ready(compiled(state))
        runs[method] = (compiled, state, compile_s, [])
    for _ in range(rounds):
        for compiled, state, _, times in runs.values():
            start = time.perf_counter()
            jax.block_until_ready(compiled(state))
            times.append(time.perf_counter() - start)
    found = []
    for method, (_, _, compile_s, times) in runs.items():
        per = statistics.median(times) / (n * steps)
        found.append(
            {"system": label, "method": method, "bodies": n, "dt": dt, "steps": steps, "rounds": rounds,
             "seconds_per_body_step": per, "compile_s": compile_s}
        )  # fmt: skip
        print(f"cost {label:12s} {method:20s} {per * 1e9:9.1f} ns per body-step", file=sys.stderr, flush=True)
    return found


def first_call(system, label, dt, steps, rounds):
    """Seconds of each method's first call of a jitted ``steps``-step loop (trace, compile and run, as a
    user's first call), each round with fresh closures (nothing cached), methods interleaved; median."""
    energy_fn, shift, body = system
    times = {method: [] for method in METHODS}
    for _ in range(rounds):
        for method, sim in METHODS.items():
            init_fn, apply_fn = sim(energy_fn, shift, dt, KT, rigid_body.RigidBody(G, G))
            state = init_fn(jax.random.key(3), body, mass=shape().mass())
            loop = jax.jit(lambda s, f=apply_fn: jax.lax.fori_loop(0, steps, lambda i, s_: f(s_), s))
            start = time.perf_counter()
            jax.block_until_ready(loop(state))
            times[method].append(time.perf_counter() - start)
    found = []
    for method, ts in times.items():
        found.append(
            {"system": label, "method": method, "bodies": body.center.shape[0], "dt": dt, "steps": steps,
             "rounds": rounds, "first_call_s": statistics.median(ts)}
        )  # fmt: skip
        median = statistics.median(ts)
        print(f"first call {label:12s} {method:20s} {median:7.2f} s", file=sys.stderr, flush=True)
    return found


def print_cost_table(cost_rows, first_rows):
    """jaxrot and jax_md side by side with their ratio: per body-step (free, interacting), first call."""
    print("| system | jaxrot.jax_md baoab | jax_md nvt_langevin | jaxrot / jax_md |")
    print("|---|---|---|---|")
    parts = ((cost_rows, "seconds_per_body_step", "ns", 1e9), (first_rows, "first_call_s", "s", 1))
    for rows, key, unit, scale in parts:
        by = {}
        for r in rows:
            by.setdefault(r["system"], {})[r["method"]] = r
        for system, found in by.items():
            a, b = (found[m][key] for m in METHODS)
            n = found["jaxrot baoab"]["bodies"]
            what = "first call" if key == "first_call_s" else "per body-step"
            sides = f"{a * scale:.4g} {unit} | {b * scale:.4g} {unit}"
            print(f"| {system} ({n} bodies), {what} | {sides} | {a / b:.2f} |")


def plot(json_path, png_path):
    """Per-axis rotational temperature / kT against dt, both thermostats (free bodies), from the results."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    data = json.loads(Path(json_path).read_text())
    fig, ax = plt.subplots(figsize=(6.4, 3.8))
    styles = {"jaxrot baoab": ("tab:blue", "o"), "jax_md nvt_langevin": ("tab:red", "s")}
    for method, (color, marker) in styles.items():
        rows = sorted((r for r in data["rows"] if r["system"] == "free" and r["method"] == method),
                      key=lambda r: r["dt"])  # fmt: skip
        dts = np.array([r["dt"] for r in rows])
        for axis, fill in zip(range(3), ("full", "left", "none"), strict=True):
            ax.errorbar(dts * (1 + 0.04 * (axis - 1)), [r["axes"][axis] for r in rows],
                        yerr=[2 * r["axes_error"][axis] for r in rows], color=color, marker=marker,
                        fillstyle=fill, ls="-" if axis == 0 else ":", capsize=2,
                        label=f"{method}, axis {axis + 1}")  # fmt: skip
    ax.axhline(1.0, color="k", lw=0.8)
    ax.axhline(5 / 6, color="gray", lw=0.8, ls="--")
    ax.set_xscale("log", base=2)
    ax.set_xlabel("dt")
    ax.set_ylabel("⟨L_l² / I_l⟩ / kT")
    ax.set_title("Rotational temperature per body axis (free tetrahedra, ±2σ)")
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(png_path, dpi=110)


def report(label, row):
    axes, errors = np.round(row["axes"], 3), np.round(row["axes_error"], 3)
    print(f"{label} {row['method']:20s} axes {axes} ± {errors} centres {row['centres']:.3f}", file=sys.stderr)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--bodies", type=int, default=4000, help="free bodies for the temperatures")
    parser.add_argument("--snapshots", type=int, default=40, help="snapshots per temperature")
    parser.add_argument(
        "--quick", action="store_true", help="the cost table only; written to --out if not docs/"
    )
    parser.add_argument("--out", default=str(ROOT / "docs" / "jax_md_cpu.json"))
    parser.add_argument("--plot-only", action="store_true", help="redraw the figure from --out and exit")
    args = parser.parse_args(argv)
    png = str(Path(args.out).with_suffix(".png"))
    if args.plot_only:
        plot(args.out, png)
        return
    if args.quick:  # the cost table alone, at sizes a few minutes cover
        cost_rows = cost(free_system(2000), "free", 1 / 16, 50, 5)
        cost_rows += cost(tetrahedra(64), "tetrahedra", 1 / 64, 50, 5)
        first_rows = first_call(tetrahedra(40), "tetrahedra", 1 / 64, 1000, 1)
        print_cost_table(cost_rows, first_rows)
        # Written only elsewhere than the published file (regenerate.py --quick gives a scratch folder).
        if Path(args.out).resolve() != (ROOT / "docs" / "jax_md_cpu.json").resolve():
            result = {"machine": machine_info(), "quick": True, "cost": cost_rows, "first_call": first_rows}
            Path(args.out).write_text(json.dumps(result, indent=1) + "\n")
        return
    n, snapshots = args.bodies, args.snapshots
    free = free_system(n)
    rows = []
    for dt in DTS:
        for method in METHODS:
            row = {"system": "free", "method": method, "dt": dt, "bodies": n, "snapshots": snapshots}
            row.update(temperatures(free, method, dt, snapshots, 1.0))
            rows.append(row)
            report(f"free dt={dt:.4f}", row)
    interacting = tetrahedra(40)
    snaps = 400
    for method in METHODS:
        row = {"system": "tetrahedra", "method": method, "dt": 1 / 64, "bodies": 40, "snapshots": snaps}
        row.update(temperatures(interacting, method, 1 / 64, snaps, 0.5))
        rows.append(row)
        report("tetrahedra dt=0.0156", row)
    energy_rows = energy_errors(NVE_DTS, t_end=20.0)
    cost_rows = cost(free_system(10_000), "free", 1 / 16, 100, 7)
    cost_rows += cost(tetrahedra(128), "tetrahedra", 1 / 64, 100, 7)
    first_rows = first_call(tetrahedra(40), "tetrahedra", 1 / 64, 1000, 3)
    print_cost_table(cost_rows, first_rows)
    info = machine_info()
    info["jax_md"] = importlib.metadata.version("jax-md")
    command = ["python benchmarks/jax_md_rigid.py", *(argv if argv is not None else sys.argv[1:])]
    result = {
        "machine": info,
        "command": " ".join(command),
        "setting": {"kT": KT, "gamma": [G, G], "moments": [5.4, 10.4, 13.4], "density": 0.1},
        "rows": rows,
        "energy": energy_rows,
        "cost": cost_rows,
        "first_call": first_rows,
    }
    Path(args.out).write_text(json.dumps(result, indent=1) + "\n")
    plot(args.out, png)
    print(f"wrote {args.out} and {png}", file=sys.stderr)


if __name__ == "__main__":
    main()
