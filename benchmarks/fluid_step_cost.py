"""Cost of one exponential step in a fluid against a Runge–Kutta step with the same torque in vacuum.

Issue 66 asks that an ``exp_rk4`` step cost no more than 1.3× an ``rkmk4`` step given the same
physics as a plain torque callable. Every row integrates ``N`` copies of the fluid race's body (the
``spheroid_shear`` scene at ``St = 1e-1``: a prolate spheroid in simple shear, each body at a random
orientation turning at its slow velocity), float64, vmapped over the bodies and looped over
``--steps`` steps at the race's coarsest useful step (``t_end / 256``), dt a runtime value:

- ``rkmk4`` and ``zhao`` in vacuum with the fluid's torque as a plain callable
  (`jaxrot.comparison._fluid.plain_fluid_torque`: what a user gives an explicit scheme);
- ``exp_rk4`` and ``exp_midpoint`` with ``fluid=`` (their steps alone: no start);
- the same pair in a fluid at rest (the friction alone), which isolates the flow's share;
- ``exp_rk4``'s first `GRADED_STEPS` steps of a run through `jaxrot.schemes._base.advance` (the
  graded start) against as many plain steps, the bodies on their slow manifold.

Each row is one compiled program; the rows are timed in interleaved rounds and the median round of
each is kept, in wall time and in the process's CPU time (all its threads: less moved by other
programs on a shared machine), as ns per body-step and as the ratio to ``rkmk4``'s.

    python benchmarks/fluid_step_cost.py --json docs/fluid_step_cost_cpu.json   # ~3 minutes, 2 cores
    python benchmarks/fluid_step_cost.py --n 200 --rounds 3                      # the quick check
"""

import argparse
import json
import statistics
import time

import jax


jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402

import jaxrot  # noqa: E402
from jaxrot import quaternion as quat  # noqa: E402
from jaxrot._fluid._fluid import check_fluid  # noqa: E402
from jaxrot._particles import PARTICLES  # noqa: E402
from jaxrot.comparison import machine_info  # noqa: E402
from jaxrot.comparison._fluid import plain_fluid_torque  # noqa: E402
from jaxrot.scenes import spheroid_shear  # noqa: E402
from jaxrot.schemes import ExpRK4  # noqa: E402
from jaxrot.schemes._base import advance  # noqa: E402
from jaxrot.schemes._exponential import FluidArgs  # noqa: E402


GRADED_STEPS = 7  # the steps timed from a run's start (the graded start's window at hL ~ 1e6)


STOKES = 1e-1
BASE = "rkmk4, vacuum, the fluid's torque as a callable"


def bodies(scene, n):
    q = quat.normalize(jax.random.normal(jax.random.PRNGKey(0), (n, 4), dtype=jnp.float64))
    return jaxrot.RotState(q, scene.fluid.angular_velocity(q))


def runner(scheme, inertia, torque, args, steps, start=False):
    """``run(state, dt)`` of ``steps`` steps of ``scheme`` per body; with ``start``, through `advance`
    from a run's first step (the graded start's steps); one compilation."""
    inertia = jaxrot.body_inertia(inertia)

    def run(state, dt):
        def one(q, omega):
            t0 = jnp.zeros((), dt.dtype)
            carry = scheme.init(jaxrot.RotState(q, omega), t0, inertia, torque, args)

            def step(i, c):
                t = i.astype(dt.dtype) * dt
                if start:
                    return advance(scheme, c, i, t, t0, dt, inertia, torque, args)
                return scheme.step(c, t, dt, inertia, torque, args)

            return scheme.state(jax.lax.fori_loop(0, steps, step, carry))

        return jax.vmap(one, axis_name=PARTICLES)(state.q, state.omega)

    return jax.jit(run)


def runners(steps):
    """``{label: (run, steps)}``: every row of the module's docstring."""
    scene = spheroid_shear(stokes=STOKES)
    fluid, _ = check_fluid(scene.fluid, (), jnp.float64)
    at_rest = jaxrot.Fluid(scene.fluid.friction)
    rest, _ = check_fluid(at_rest, (), jnp.float64)
    plain = plain_fluid_torque(scene)

    def friction(t, q, omega, args):
        return at_rest.torque(q, omega)

    exp_rk4, exp_midpoint = (jaxrot.FLUID_SCHEMES[n].in_fluid() for n in ("exp_rk4", "exp_midpoint"))
    inertia = scene.inertia
    return scene, {
        BASE: (runner(jaxrot.SCHEMES["rkmk4"], inertia, plain, None, steps), steps),
        "zhao, vacuum, the fluid's torque as a callable": (
            runner(jaxrot.SCHEMES["zhao"], inertia, plain, None, steps),
            steps,
        ),
        "exp_rk4, fluid=": (runner(exp_rk4, inertia, None, FluidArgs(None, fluid), steps), steps),
        "exp_midpoint, fluid=": (runner(exp_midpoint, inertia, None, FluidArgs(None, fluid), steps), steps),
        "rkmk4, vacuum, a fluid at rest's torque as a callable": (
            runner(jaxrot.SCHEMES["rkmk4"], inertia, friction, None, steps),
            steps,
        ),
        "exp_rk4, fluid= at rest": (runner(exp_rk4, inertia, None, FluidArgs(None, rest), steps), steps),
        f"exp_rk4, fluid=, the first {GRADED_STEPS} steps with the graded start": (
            runner(exp_rk4, inertia, None, FluidArgs(None, fluid), GRADED_STEPS, start=True),
            GRADED_STEPS,
        ),
        f"exp_rk4, fluid=, the first {GRADED_STEPS} steps without it": (
            runner(
                ExpRK4(graded_start=False).in_fluid(), inertia, None, FluidArgs(None, fluid), GRADED_STEPS
            ),
            GRADED_STEPS,
        ),
    }


def measure(n_bodies, steps, rounds):
    scene, rows = runners(steps)
    state = bodies(scene, n_bodies)
    dt = jnp.asarray(scene.t_end / 256, jnp.float64)
    for run, _ in rows.values():
        jax.block_until_ready(run(state, dt))  # compile
    wall, cpu = ({label: [] for label in rows} for _ in range(2))
    for _ in range(rounds):
        for label, (run, _) in rows.items():
            start, start_cpu = time.perf_counter(), time.process_time()
            jax.block_until_ready(run(state, dt))
            wall[label].append(time.perf_counter() - start)
            cpu[label].append(time.process_time() - start_cpu)
    out = []
    for label in rows:
        per = 1e9 / (n_bodies * rows[label][1])
        out.append({"scheme": label, "ns_per_body_step": statistics.median(wall[label]) * per,
                    "cpu_ns_per_body_step": statistics.median(cpu[label]) * per})  # fmt: skip
    base = next(r for r in out if r["scheme"] == BASE)
    for row in out:
        row["vs_rkmk4"] = row["ns_per_body_step"] / base["ns_per_body_step"]
        row["cpu_vs_rkmk4"] = row["cpu_ns_per_body_step"] / base["cpu_ns_per_body_step"]
    return out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=1000, help="bodies (the fluid race's 1000)")
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--rounds", type=int, default=15)
    parser.add_argument("--json", default=None)
    opts = parser.parse_args(argv)
    info = machine_info()
    print(info)
    rows = measure(opts.n, opts.steps, opts.rounds)
    for row in rows:
        print(
            f"{row['scheme']:<62} {row['ns_per_body_step']:8.1f} ns/body-step "
            f"({row['vs_rkmk4']:5.2f} × rkmk4); "
            f"CPU time {row['cpu_ns_per_body_step']:8.1f} ({row['cpu_vs_rkmk4']:5.2f} ×)"
        )
    if opts.json:
        with open(opts.json, "w") as f:
            json.dump({"machine": info, "stokes": STOKES, "bodies": opts.n, "steps": opts.steps,
                       "rounds": opts.rounds, "rows": rows}, f, indent=2)  # fmt: skip


if __name__ == "__main__":
    main()
