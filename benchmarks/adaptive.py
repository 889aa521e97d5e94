"""Adaptive Lie-group pairs against diffrax's Tsit5 and Dopri8, all on one `jaxrot.RigidBodyTerm`.

Every solver runs in `diffrax.diffeqsolve` with `PIDController(rtol=tol, atol=tol)` on
the same term and state (``N`` bodies with random orientations and spins of a few rad/s,
a scene's inertia, torque and horizon; `jax.vmap` over bodies, so each body adapts its own
steps). diffrax's solvers integrate ``q`` in R⁴ (normalised here only to measure the
error); jaxrot's step on the group. For each tolerance: the largest geodesic orientation
error at the final time against Dopri8 at 1e-14, the mean number of steps (accepted +
rejected) per body, torque calls per body, the largest | |q| − 1 | before normalising,
and the compiled wall time of the batch (median of ``--repeats``).

    python benchmarks/adaptive.py                      # heavy_top, N = 100, float64
    python benchmarks/adaptive.py --scene viscous_drag --n 1000
"""

import argparse
import sys
from pathlib import Path

import jax


jax.config.update("jax_enable_x64", True)

import diffrax
import jax.numpy as jnp
import numpy as np

import jaxrot
from jaxrot import quaternion as quat
from jaxrot.comparison import machine_info


sys.path.insert(0, str(Path(__file__).parent))
from race import error_of, random_bodies, timed  # noqa: E402


SOLVERS = {
    "jaxrot rkmk_dopri5": jaxrot.solver("rkmk_dopri5"),
    "jaxrot rkmk_dopri8": jaxrot.solver("rkmk_dopri8"),
    "diffrax Tsit5": diffrax.Tsit5(),
    "diffrax Dopri8": diffrax.Dopri8(),
}


def torque_calls(solver, mean_steps):
    """Calls per body: each stage after the first (FSAL reuses it), plus one at the start."""
    tableau = getattr(solver, "scheme", solver).tableau
    return (tableau.num_stages - (1 if tableau.fsal else 0)) * mean_steps + 1


def runner(solver, term, t_end, args):
    def run(state, tol):
        def one(q, omega):
            sol = diffrax.diffeqsolve(
                term, solver, 0.0, t_end, None, jaxrot.RotState(q, omega), args=args,
                stepsize_controller=diffrax.PIDController(rtol=tol, atol=tol), max_steps=1_000_000,
                throw=False,
            )  # fmt: skip
            return sol.ys.q[-1], sol.result, sol.stats["num_steps"]

        return jax.vmap(one)(state.q, state.omega)

    return jax.jit(run)


def main():
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--scene", default="heavy_top")
    parser.add_argument("--n", type=int, default=100)
    parser.add_argument("--tols", default="1e-4,1e-6,1e-8,1e-10,1e-12")
    parser.add_argument("--repeats", type=int, default=3)
    opts = parser.parse_args()
    scene = jaxrot.SCENES[opts.scene]()
    state = random_bodies(scene, opts.n, jnp.float64)
    ref = jaxrot.reference_rollout(
        state, scene.inertia, jnp.array([0.0, scene.t_end]), torque=scene.torque, args=scene.args,
        rtol=1e-14, atol=1e-14,
    )  # fmt: skip
    term = jaxrot.RigidBodyTerm(scene.inertia, scene.torque)
    print(f"machine: {machine_info()}")
    print(f"scene {opts.scene}, N = {opts.n}, t = {scene.t_end}, float64, rtol = atol = tol\n")
    print("| tol | solver | max error [rad] | steps / body | torque calls / body | max ||q|−1| | wall [ms] |")
    print("|---|---|---|---|---|---|---|")
    compiled = {name: runner(solver, term, scene.t_end, scene.args) for name, solver in SOLVERS.items()}
    for tol in [float(x) for x in opts.tols.split(",")]:
        for name, solver in SOLVERS.items():
            (q, result, steps), seconds = timed(compiled[name], state, jnp.asarray(tol), repeats=opts.repeats)
            if np.any(np.asarray(result != diffrax.RESULTS.successful)):
                print(f"| {tol:.0e} | {name} | failed | | | | |")
                continue
            drift = float(jnp.max(jnp.abs(jnp.linalg.norm(q, axis=-1) - 1)))
            err = error_of(quat.normalize(q), ref.q[-1])
            mean_steps = float(np.mean(np.asarray(steps)))
            calls = 0 if scene.torque is None else torque_calls(solver, mean_steps)
            print(
                f"| {tol:.0e} | {name} | {err:.2e} | {mean_steps:.1f} | {calls:.0f} | {drift:.1e} | "
                f"{seconds * 1e3:.2f} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
