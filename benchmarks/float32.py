"""float32 horizons: how far each scheme's float32 run stays on its own float64 run.

Accuracy only (no timing). Two parts, both written to the results file:

1. **Horizon.** Every scheme of `jaxrot.SCHEMES` runs the same start in float32 and in float64
   (the float64 start is the float32 one, converted): the tumbling free body (I = (1, 2, 3),
   q = exp((0.1, 0.2, 0.3)), ω_b = (1, 2, 0.5), dt = 0.01, |ω|Δt = 0.023) and the ``heavy_top``
   scene (dt = 0.005). The angle between the two runs' orientations, sampled every 10 steps up to
   ``--steps``, is float32 round-off and what the dynamics make of it; reported: the angle after
   10², 10³, 10⁴ and 10⁵ steps and the first step at which it exceeds 1e-4 and 1e-2 rad.
2. **Where the splittings' round-off grows.** One rotor flow of length Δt/15 (an SRKN₁₄ᵃ flow at
   Δt = 0.01), chained 15 000 times in float32 on the tumbling body, through the two interfaces of
   the DMV rotor: `free_rotor`, which takes and returns the world ω (each call turns it into the
   body frame and back), and `free_rotor_momentum`, which flows the principal-frame momentum the
   splittings now carry. Reported: the drift of the world angular momentum's direction (rad),
   of |L| and of the energy (relative), and the orientation error against the same chain in float64.

    python benchmarks/float32.py --json docs/float32_horizon.json   # the results file (~10 min)
    python benchmarks/float32.py --steps 2000 --schemes zhao,srkn14a  # a quick check
"""

import argparse
import json
import sys

import jax


jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np

import jaxrot
from jaxrot import quaternion as quat
from jaxrot._free_body._rotor import free_rotor, free_rotor_momentum
from jaxrot.comparison import machine_info


MOMENTS = (1.0, 2.0, 3.0)
SAMPLE_EVERY = 10
THRESHOLDS = (1e-4, 1e-2)
CHECKPOINTS = (100, 1000, 10_000, 100_000)


def problems():
    """``name -> (state, inertia, torque, args, dt)`` in float64."""
    q0 = quat.exp(jnp.array([0.1, 0.2, 0.3]))
    tumbling = jaxrot.RotState(q0, quat.rotate(q0, jnp.array([1.0, 2.0, 0.5])))
    heavy = jaxrot.SCENES["heavy_top"]()
    return {
        "tumbling free body": (tumbling, jnp.array(MOMENTS), None, None, 0.01),
        "heavy top": (heavy.state, heavy.inertia, heavy.torque, heavy.args, 0.005),
    }


def _cast(tree, dtype):
    return jax.tree_util.tree_map(lambda x: jnp.asarray(x).astype(dtype), tree)


def horizon(name, problem, steps):
    """One scheme on one problem: the float32-against-float64 angle over ``steps`` steps."""
    state, inertia, torque, args, dt = problem
    state32 = _cast(state, jnp.float32)
    runs = {}
    for dtype, start in ((jnp.float32, state32), (jnp.float64, _cast(state32, jnp.float64))):
        traj = jaxrot.rollout(
            name,
            start,
            _cast(inertia, dtype),
            dt,
            steps,
            torque=torque,
            args=None if args is None else _cast(args, dtype),
            save_every=SAMPLE_EVERY,
            check_finite=False,
        )
        runs[dtype] = traj.q.astype(jnp.float64)
    angle = np.asarray(quat.angle_between(runs[jnp.float32], runs[jnp.float64]))
    angle = np.where(np.isfinite(angle), angle, np.inf)
    row = {"scheme": name, "steps": steps, "dt": dt}
    for n in CHECKPOINTS:
        row[f"angle_after_{n}"] = float(angle[n // SAMPLE_EVERY]) if n <= steps else None
    for threshold in THRESHOLDS:
        above = np.nonzero(angle > threshold)[0]
        row[f"steps_to_{threshold:g}"] = int(above[0]) * SAMPLE_EVERY if above.size else None
    return row


def rotor_round_off(calls=15_000, dt=0.01):
    """Part 2: the two rotor interfaces chained ``calls`` times, float32 against float64."""
    state, inertia, _, _, _ = problems()["tumbling free body"]
    flow_t = dt / 15

    def chain(dtype, momentum):
        moments = inertia.astype(dtype)
        q = state.q.astype(jnp.float32).astype(dtype)  # the body axes are the principal axes here
        omega = state.omega.astype(jnp.float32).astype(dtype)
        m = moments * quat.rotate(quat.conjugate(quat.normalize(q)), omega)
        t = jnp.asarray(flow_t, dtype)

        def body(carry, _):
            q, v = carry
            if momentum:
                return free_rotor_momentum(q, v, moments, t), None
            return free_rotor(q, v, moments, t), None

        (q, v), _ = jax.lax.scan(body, (q, m if momentum else omega), None, length=calls)
        q = quat.normalize(q.astype(jnp.float64))
        v = v.astype(jnp.float64)
        omega = quat.rotate(q, v / inertia) if momentum else v
        return q, omega

    def invariants(q, omega):
        body = quat.rotate(quat.conjugate(q), omega)
        return quat.rotate(q, inertia * body), jnp.sum(inertia * body * body)

    rows = []
    for label, momentum in (("free_rotor (world ω in and out)", False), ("free_rotor_momentum", True)):
        q32, w32 = chain(jnp.float32, momentum)
        q64, w64 = chain(jnp.float64, momentum)
        l32, e32 = invariants(q32, w32)
        l64, e64 = invariants(q64, w64)
        cos = jnp.dot(l32, l64) / (jnp.linalg.norm(l32) * jnp.linalg.norm(l64))
        rows.append(
            {
                "interface": label,
                "calls": calls,
                "flow_time": flow_t,
                "momentum_direction_rad": float(jnp.arccos(jnp.clip(cos, -1.0, 1.0))),
                "momentum_norm_rel": float(abs(jnp.linalg.norm(l32) / jnp.linalg.norm(l64) - 1)),
                "energy_rel": float(abs(e32 / e64 - 1)),
                "orientation_rad": float(quat.angle_between(q32, q64)),
            }
        )
        print(rows[-1], flush=True)
    return rows


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=100_000, help="steps of each run (a multiple of 10)")
    parser.add_argument("--schemes", default=None, help="comma-separated names (default: all)")
    parser.add_argument("--json", default=None, help="write the results file here")
    opts = parser.parse_args(argv)
    machine = machine_info()  # the commit as the run starts
    names = opts.schemes.split(",") if opts.schemes else list(jaxrot.SCHEMES)
    results = {"machine": machine, "thresholds": list(THRESHOLDS), "problems": {}}
    for problem_name, problem in problems().items():
        rows = []
        for name in names:
            rows.append(horizon(name, problem, opts.steps))
            r = rows[-1]
            print(
                f"{problem_name:18s} {name:12s} "
                + " ".join(f"{n}: {r[f'angle_after_{n}']}" for n in CHECKPOINTS if n <= opts.steps)
                + " | "
                + " ".join(f"> {t:g} at {r[f'steps_to_{t:g}']}" for t in THRESHOLDS),
                flush=True,
            )
        results["problems"][problem_name] = rows
    results["rotor"] = rotor_round_off()
    if opts.json:
        with open(opts.json, "w") as f:
            json.dump(results, f, indent=2)
            f.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
