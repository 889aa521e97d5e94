"""Throughput: particle-steps per second against the number of bodies, every scheme, and jax_md.

Each scheme advances N heavy tops (I = (1, 2, 3), gravity on an offset centre of
mass, random orientations) for ``work / N`` steps (clamped to [10, 10⁴]) in one
compiled `jaxrot.rollout` that saves only the first and last state. The peer is
jax_md's rigid-body NVE (NO_SQUISH, Miller et al. 2002) on the same torque,
derived by jax_md from the potential ``U = −F·r(q)``, measured in the same run
when ``jax-md`` is installed (``pip install -e ".[peers]"``; jax-md excludes
jax 0.10.2, so use Python 3.12). jax_md also integrates the centres of mass
(at zero force); that is part of its step and is not removed.

Ratios are printed against jax_md in the same dtype at the same N; absolute
numbers drift from machine to machine.

    python benchmarks/throughput.py                      # N = 1 … 10⁶, float32 and float64
    python benchmarks/throughput.py --n 10000 --dtype float64 --schemes zhao,no_squish
"""

import argparse
import json
import sys

import jax


jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np
from tqdm import tqdm

import jaxrot
import jaxrot._core._fusion
from jaxrot import quaternion as quat
from jaxrot.comparison import machine_info, time_compiled
from jaxrot.scenes import heavy_top


DT = 1e-3


def bodies(n, dtype, seed=0):
    """``n`` copies of the `heavy_top` scene's body, with random orientations and its body-frame spin."""
    scene = heavy_top(dtype)
    omega_body = quat.rotate(quat.conjugate(scene.state.q), scene.state.omega)
    q = quat.normalize(jax.random.normal(jax.random.PRNGKey(seed), (n, 4), dtype=dtype))
    omega = quat.rotate(q, jnp.broadcast_to(omega_body, (n, 3)))
    return jaxrot.RotState(q, omega), scene


def jaxrot_run(scheme, scene, n_steps):
    def run(state):
        traj = jaxrot.rollout(
            scheme,
            state,
            scene.inertia,
            DT,
            n_steps,
            torque=scene.torque,
            args=scene.args,
            save_every=n_steps,
        )
        return traj.q[-1]

    return run


def jax_md_run(scene, n_steps):
    """jax_md NVE on the heavy-top potential; returns a function of a `RotState` batch → final q."""
    from jax_md import rigid_body, simulate, space

    inertia, args = scene.inertia, scene.args["gravity"]

    def energy(body, **kwargs):
        r_world = rigid_body.quaternion_rotate(body.orientation, args["offset_body"])
        return -jnp.sum(r_world @ args["weight"])

    _, shift = space.free()
    init_fn, step_fn = simulate.nve(energy, shift, DT)

    def run(state):
        n, dtype = state.q.shape[0], state.q.dtype
        position = rigid_body.RigidBody(jnp.zeros((n, 3), dtype), rigid_body.Quaternion(state.q))
        mass = rigid_body.RigidBody(jnp.ones((n,), dtype), jnp.broadcast_to(inertia, (n, 3)))
        l_body = inertia * quat.rotate(quat.conjugate(state.q), state.omega)
        momenta = rigid_body.RigidBody(
            jnp.zeros((n, 3), dtype),
            rigid_body.angular_momentum_to_conjugate_momentum(position.orientation, l_body),
        )
        md = init_fn(jax.random.PRNGKey(0), position, 0.0, mass=mass, momenta=momenta)
        md = jax.lax.fori_loop(0, n_steps, lambda i, s: step_fn(s), md)
        return md.position.orientation.vec

    return run


def have_jax_md():
    try:
        import jax_md  # noqa: F401
    except ImportError:
        return False
    return True


def machine():
    info = machine_info() | {"stage_barriers": jaxrot._core._fusion._barriers()}
    if have_jax_md():
        import importlib.metadata

        info["jax_md"] = importlib.metadata.version("jax-md")
    return info


def measure(ns, dtypes, schemes, work, repeats, peer, xla_defaults=False):
    rows = []
    jobs = [(dtype, n) for dtype in dtypes for n in ns]
    for dtype_name, n in tqdm(jobs, desc="throughput"):
        dtype = {"float32": jnp.float32, "float64": jnp.float64}[dtype_name]
        n_steps = int(np.clip(work // n, 10, 10_000))
        state, scene = bodies(n, dtype)
        runs = {name: jaxrot_run(name, scene, n_steps) for name in schemes}
        if peer:
            runs["jax_md"] = jax_md_run(scene, n_steps)
        finals = {}
        for name, run in runs.items():
            # jaxrot's programs compile with its options, as `jaxrot.rollout` does at top level;
            # jax_md's with XLA's defaults, as its users get them.
            options = None if name == "jax_md" or xla_defaults else jaxrot.compiler_options()
            final_q, compile_s, seconds = time_compiled(run, state, repeats, options)
            finals[name] = final_q
            rows.append(
                {
                    "dtype": dtype_name,
                    "n": n,
                    "steps": n_steps,
                    "method": name,
                    "particle_steps_per_s": n * n_steps / seconds,
                    "compile_s": compile_s,
                }
            )
        if peer and "no_squish" in finals:
            # Same scheme, same torque: the two codes must agree (jax_md rounds dt to float32).
            gap = float(jnp.max(quat.angle_between(finals["no_squish"], finals["jax_md"])))
            rows[-1]["max_angle_vs_no_squish_rad"] = gap
    return rows


def table(rows, peer):
    methods = list(dict.fromkeys(r["method"] for r in rows))
    head = "| dtype | N | steps | " + " | ".join(f"{m} [M/s]" for m in methods)
    if peer:
        head += " | " + " | ".join(f"{m} / jax_md" for m in methods if m != "jax_md")
        head += " | jax_md vs no_squish [rad]"
    lines = [head + " |", "|" + "---|" * (head.count("|"))]
    for (dtype, n), group in _groups(rows):
        by = {r["method"]: r for r in group}
        cells = [dtype, f"{n:.0e}", str(group[0]["steps"])]
        cells += [f"{by[m]['particle_steps_per_s'] / 1e6:.3g}" for m in methods]
        if peer:
            base = by["jax_md"]["particle_steps_per_s"]
            cells += [f"{by[m]['particle_steps_per_s'] / base:.2f}" for m in methods if m != "jax_md"]
            gap = by["jax_md"].get("max_angle_vs_no_squish_rad")
            cells.append("—" if gap is None else f"{gap:.1e}")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def compile_table(rows):
    """Seconds to trace, lower and compile each timed program (a whole `rollout`)."""
    methods = list(dict.fromkeys(r["method"] for r in rows))
    head = "| dtype | N | " + " | ".join(f"{m} compile [s]" for m in methods) + " |"
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    for (dtype, n), group in _groups(rows):
        by = {r["method"]: r for r in group}
        cells = " | ".join(f"{by[m]['compile_s']:.2f}" for m in methods)
        lines.append(f"| {dtype} | {n:.0e} | {cells} |")
    return "\n".join(lines)


def _groups(rows):
    keys = list(dict.fromkeys((r["dtype"], r["n"]) for r in rows))
    return [(k, [r for r in rows if (r["dtype"], r["n"]) == k]) for k in keys]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--n", default="1,10,100,1000,10000,100000,1000000", help="comma-separated N")
    parser.add_argument("--dtype", default="float32,float64")
    parser.add_argument("--schemes", default=",".join(jaxrot.SCHEMES))
    parser.add_argument("--work", type=float, default=2e6, help="particle-steps per timed run (default 2e6)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--no-peer", action="store_true", help="skip jax_md even when installed")
    parser.add_argument("--json", default=None, help="also write the rows here")
    parser.add_argument(
        "--xla-defaults",
        action="store_true",
        help="compile jaxrot's programs with XLA's default options instead of jaxrot.compiler_options()",
    )
    parser.add_argument(
        "--barriers", choices=["auto", "on", "off"], default="auto", help="`stage` barriers (auto: CPU only)"
    )
    ns = parser.parse_args(argv)
    jaxrot._core._fusion.BARRIERS = {"auto": None, "on": True, "off": False}[ns.barriers]
    sizes = [int(float(x)) for x in ns.n.split(",")]
    dtypes = ns.dtype.split(",")
    schemes = ns.schemes.split(",")
    unknown = [s for s in schemes if s not in jaxrot.SCHEMES]
    if unknown or any(d not in ("float32", "float64") for d in dtypes) or min(sizes) < 1:
        parser.error(f"--schemes from {list(jaxrot.SCHEMES)}, --dtype float32/float64, --n >= 1")
    peer = have_jax_md() and not ns.no_peer
    info = machine()
    info["jaxrot_compiler_options"] = {} if ns.xla_defaults else jaxrot.compiler_options()
    print("jaxrot throughput — heavy top, dt = 1e-3, particle-steps per second (millions), median of repeats")
    print(", ".join(f"{k} {v}" for k, v in info.items()))
    if not peer:
        print('jax_md: not measured (pip install -e ".[peers]", needs jax != 0.10.2, e.g. Python 3.12)')
    rows = measure(sizes, dtypes, schemes, int(ns.work), ns.repeats, peer, ns.xla_defaults)
    print(table(rows, peer))
    print(compile_table(rows))
    gaps = [r["max_angle_vs_no_squish_rad"] for r in rows if "max_angle_vs_no_squish_rad" in r]
    if gaps:
        print(
            f"jax_md vs jaxrot no_squish, final orientation: max {max(gaps):.2e} rad "
            "(same scheme, same torque)"
        )
    if ns.json:
        with open(ns.json, "w") as f:
            json.dump({"machine": info, "rows": rows}, f, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
