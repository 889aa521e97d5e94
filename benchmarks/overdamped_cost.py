"""Cost per body-step of `jaxrot.overdamped_rollout`'s schemes against a ``"zhao"`` step of the same body.

Issue 54 asks that the overdamped model cost no more per step than ``zhao``. Both run the
``spheroid_shear`` scene's body (a prolate spheroid in simple shear): ``zhao`` the inertial model
with the fluid's torque as a plain callable (`jaxrot.comparison._fluid.plain_fluid_torque`), the
overdamped schemes (Lie–Euler, Lie midpoint, RKMK4 in the exponential and the Cayley chart) the
orientation alone, on ``N`` copies of the body, ``STEPS`` steps saving only the end. Timed through
the public entry points, compiled, in interleaved rounds (the median of each), float64.

    python benchmarks/overdamped_cost.py --json docs/overdamped_cost_cpu.json   # ~2 minutes
"""

import argparse
import json
import statistics
import time

import jax


jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402

import jaxrot  # noqa: E402
from jaxrot.comparison import machine_info  # noqa: E402
from jaxrot.comparison._fluid import OVERDAMPED_ROWS, plain_fluid_torque  # noqa: E402
from jaxrot.scenes import spheroid_shear  # noqa: E402
from jaxrot.schemes import OVERDAMPED_SCHEMES  # noqa: E402


STEPS = 200


def runners(n_bodies):
    """``{label: zero-argument run}`` for ``n_bodies`` copies of the spheroid."""
    scene = spheroid_shear()
    state = jaxrot.RotState(*(jnp.broadcast_to(x, (n_bodies, *x.shape)) for x in scene.state))
    torque = plain_fluid_torque(scene)
    dt = scene.dt
    out = {
        "zhao (inertial, the fluid's torque as a callable)": lambda: (
            jaxrot.rollout(
                "zhao", state, scene.inertia, dt, STEPS, torque=torque, save_every=STEPS, check_finite=False
            ).q
        )
    }
    schemes = dict(OVERDAMPED_ROWS)
    schemes["rkmk4, Cayley chart"] = type(OVERDAMPED_SCHEMES["rkmk4"])(chart="cayley")
    for name, scheme in schemes.items():
        out[f"overdamped {name}"] = lambda scheme=scheme: (
            jaxrot.overdamped_rollout(state.q, scene.fluid, dt, STEPS, scheme=scheme, save_every=STEPS).q
        )
    return out


def measure(n_bodies, rounds):
    fns = runners(n_bodies)
    for fn in fns.values():
        jax.block_until_ready(fn())  # compile
    samples = {label: [] for label in fns}
    for _ in range(rounds):
        for label, fn in fns.items():
            start = time.perf_counter()
            jax.block_until_ready(fn())
            samples[label].append(time.perf_counter() - start)
    return {label: statistics.median(s) / (n_bodies * STEPS) * 1e9 for label, s in samples.items()}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", default="1000,10000", help="numbers of bodies")
    parser.add_argument("--rounds", type=int, default=15)
    parser.add_argument("--json", default=None)
    opts = parser.parse_args(argv)
    info = machine_info()
    print(info)
    rows = []
    for n in [int(x) for x in opts.n.split(",")]:
        costs = measure(n, opts.rounds)
        base = next(v for k, v in costs.items() if k.startswith("zhao"))
        for label, ns in costs.items():
            rows.append({"scheme": label, "bodies": n, "ns_per_body_step": ns, "vs_zhao": ns / base})
            print(f"N = {n:>6}  {label:<52} {ns:8.1f} ns per body-step  {ns / base:5.2f} × zhao")
    if opts.json:
        with open(opts.json, "w") as f:
            json.dump({"machine": info, "steps": STEPS, "rows": rows}, f, indent=2)


if __name__ == "__main__":
    main()
