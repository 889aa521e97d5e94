"""Energy and angular-momentum drift against the rotation per step |ω|Δt, over long float64 runs.

Accuracy only (no timing). Issue 75: `zhao` gains energy without bound at moderate steps, where the
docs had measured it only at |ω|Δt = 0.023. Each scheme runs each body for ``--steps`` steps
(default 10⁵, sampled every 100) at the steps that turn it by ``--rotations`` rad per step
(|ω| the initial rate; default 0.023, 0.07, 0.14):

- ``tumbling``: the free body of `jaxrot.stability` (I = (1, 2, 3) kg m², q = exp((0.1, 0.2, 0.3)),
  ω_b = (1, 2, 0.5) rad/s, |ω| = 2.29 rad/s); invariants: energy and the world angular momentum.
- ``dzhanibekov``: the ``free_top`` scene (ω_b = (0.01, 2, 0.01) rad/s about the intermediate axis).
- ``heavy_top``: the ``heavy_top`` scene (|ω| = 6.09 rad/s); invariants: the energy (kinetic plus
  potential) and the angular momentum about the vertical (the weight's direction), relative to |L₀|.

Reported per run: the energy's relative change at the end (signed: + is a gain) and its largest
|ΔE/E₀| after 10⁴ steps and over the run, and the largest relative change of the conserved momentum.
A run that turns non-finite is reported as such.

    python benchmarks/energy_growth.py                         # the table in docs/stability.md (~5 min)
    PYTHONPATH=. python benchmarks/energy_growth.py            # from a git worktree: its own jaxrot
    python benchmarks/energy_growth.py --steps 10000 --schemes zhao --json out.json
"""

import argparse
import json

import jax


jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np

import jaxrot
from jaxrot import quaternion as quat
from jaxrot.diagnostics import angular_momentum


SAVE_EVERY = 100


def bodies():
    """``name -> scene`` (float64), each with an ``energy`` and the axes of its conserved momentum."""
    q0 = quat.exp(jnp.array([0.1, 0.2, 0.3]))
    free = jaxrot.SCENES["free_top"]()
    tumbling = free._replace(
        name="tumbling", state=jaxrot.RotState(q0, quat.rotate(q0, jnp.array([1.0, 2.0, 0.5])))
    )
    return {"tumbling": tumbling, "dzhanibekov": free, "heavy_top": jaxrot.SCENES["heavy_top"]()}


def measure(scheme, scene, rotation, n_steps):
    """One run: ``dict`` of the drifts at the step ``dt = rotation / |ω₀|``."""
    dt = rotation / float(jnp.linalg.norm(scene.state.omega))
    traj = jaxrot.rollout(
        scheme, scene.state, scene.inertia, dt, n_steps, torque=scene.torque, args=scene.args,
        save_every=SAVE_EVERY, check_finite=False,
    )  # fmt: skip
    q, omega = np.asarray(traj.q), np.asarray(traj.omega)
    row = {"scheme": scheme, "body": scene.name, "rotation_per_step": rotation, "dt": dt, "steps": n_steps}
    finite = np.all(np.isfinite(q), axis=-1) & np.all(np.isfinite(omega), axis=-1)
    if not finite.all():
        return {**row, "first_nonfinite_step": int(np.argmin(finite)) * SAVE_EVERY}
    energy = np.asarray(scene.energy(traj.t, q, omega))
    change = (energy - energy[0]) / abs(energy[0])
    momentum = np.asarray(angular_momentum(q, omega, scene.inertia))
    if scene.torque is not None:  # a top under its weight (world z) keeps only L_z
        drift = np.abs(momentum[:, 2] - momentum[0, 2])
    else:
        drift = np.linalg.norm(momentum - momentum[0], axis=-1)
    early = min(len(change) - 1, 10_000 // SAVE_EVERY)
    return {
        **row,
        "energy_final": float(change[-1]),
        "energy_max_1e4": float(np.max(np.abs(change[: early + 1]))),
        "energy_max": float(np.max(np.abs(change))),
        "momentum_max": float(np.max(drift) / np.linalg.norm(momentum[0])),
    }


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=100_000)
    parser.add_argument("--schemes", default="zhao,no_squish,splitting")
    parser.add_argument("--rotations", default="0.023,0.07,0.14", help="|ω|Δt values (rad per step)")
    parser.add_argument("--bodies", default="tumbling,dzhanibekov,heavy_top")
    parser.add_argument("--json", help="write the rows here")
    opts = parser.parse_args(argv)
    rows = []
    print(
        f"float64, {opts.steps} steps; ΔE/E₀ at the end, max |ΔE/E₀| over 1e4 steps and over the run; "
        "max |ΔL|/|L₀|"
    )
    for name, scene in bodies().items():
        if name not in opts.bodies.split(","):
            continue
        for rotation in map(float, opts.rotations.split(",")):
            for scheme in opts.schemes.split(","):
                row = measure(scheme, scene, rotation, opts.steps)
                rows.append(row)
                if "first_nonfinite_step" in row:
                    print(
                        f"{name:12s} |ω|Δt={rotation:<6g} {scheme:10s} "
                        f"non-finite at step {row['first_nonfinite_step']}"
                    )
                    continue
                print(
                    f"{name:12s} |ω|Δt={rotation:<6g} dt={row['dt']:.4g} {scheme:10s} "
                    f"ΔE/E₀ end {row['energy_final']:+.2e}  max(1e4) {row['energy_max_1e4']:.2e}  "
                    f"max {row['energy_max']:.2e}  ΔL {row['momentum_max']:.2e}",
                    flush=True,
                )
    if opts.json:
        with open(opts.json, "w") as f:
            json.dump({"steps": opts.steps, "save_every": SAVE_EVERY, "rows": rows}, f, indent=1)


if __name__ == "__main__":
    main()
