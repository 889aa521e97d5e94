"""``python -m jaxrot compare`` on a scene in a fluid (`jaxrot.scenes.FLUID_SCENES`).

The rows have the fields of `jaxrot.comparison.compare`'s, so its tables, plots and files serve
them. Fixed-step rows: the exponential schemes of `jaxrot.FLUID_SCHEMES` (inertial scenes) and the
overdamped model's schemes (``overdamped_…``; on an inertial scene their error includes the model's
own, of order the Stokes number). Adaptive rows: diffrax's solvers on the Euclidean ODE a user would
write, ``q̇ = ½ q ⊗ (0, ω_b)`` with Euler's equations and the fluid's torque as a plain callable
(inertial), or ``q̇ = ½ (0, ω(q)) ⊗ q`` (overdamped), with a PID controller at rtol = atol = tol;
``diffrax_kvaerno5`` is implicit (a stiff solver). The reference is a fine run of ExpRK4 (inertial,
2048 steps per coarse interval) or of the overdamped RKMK4 (4096), in float64.

The runners are shared with ``benchmarks/fluid_race.py``.
"""

import time

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
from tqdm import tqdm

from .. import quaternion as quat
from .._core._compile import compiler_options
from .._diffrax._reference import adaptive_solve
from .._fluid._fluid import check_fluid
from .._inertia import body_inertia
from .._integrate._overdamped import velocity_field
from .._integrate._saved_steps import saved_steps
from .._particles import PARTICLES
from .._state import RotState, Trajectory
from ..scenes import FLUID_SCENES
from ..schemes import FLUID_SCHEMES, OVERDAMPED_SCHEMES
from ..schemes._base import advance
from ..schemes._exponential import FluidArgs
from . import _ladder as comparison


DIFFRAX_SOLVERS = {
    "diffrax_tsit5": diffrax.Tsit5,
    "diffrax_dopri5": diffrax.Dopri5,
    "diffrax_dopri8": diffrax.Dopri8,
    "diffrax_kvaerno5": diffrax.Kvaerno5,
}
OVERDAMPED_PREFIX = "overdamped_"
# The schemes raced on a fluid's deterministic models. The thermal (Brownian) schemes run these
# models too, at kT = 0, but are measured at a temperature (benchmarks/thermal_orders.py).
FLUID_ROWS = {n: s for n, s in FLUID_SCHEMES.items() if "thermal" not in s.models}
OVERDAMPED_ROWS = {n: s for n, s in OVERDAMPED_SCHEMES.items() if "brownian" not in s.models}


def fixed_methods(scene) -> dict:
    """The fixed-step methods of ``scene``: ``{name: (kind, scheme)}``, ``"inertial"`` or ``"overdamped"``."""
    methods = {} if scene.inertia is None else {n: ("inertial", s) for n, s in FLUID_ROWS.items()}
    overdamped = {OVERDAMPED_PREFIX + n: ("overdamped", s.overdamped()) for n, s in OVERDAMPED_ROWS.items()}
    methods.update(overdamped)
    return methods


def inertial_runner(scheme, scene, n_bodies):
    """``run(state, dt, n, saves) -> RotState`` of ``saves`` states after every ``n`` steps, bodies
    vmapped; dt and n runtime values (one compilation)."""
    fluid, fluid_axes = check_fluid(scene.fluid, (), scene.state.q.dtype)
    inertia = body_inertia(scene.inertia)
    scheme = scheme.in_fluid()
    args = FluidArgs(scene.args, fluid)

    def run(state, dt, n, saves):
        def one(q, omega):
            t0 = jnp.zeros((), q.dtype)
            carry = scheme.init(RotState(q, omega), t0, inertia, scene.torque, args)
            step = lambda c, t, k: advance(scheme, c, k, t, t0, dt, inertia, scene.torque, args)  # noqa: E731
            return saved_steps(carry, step, scheme.state, dt, n, saves)

        return jax.vmap(one, axis_name=PARTICLES, out_axes=1)(state.q, state.omega)

    return run


def overdamped_runner(scheme, scene, n_bodies):
    """As `inertial_runner`, for the overdamped model (the scene's inertia is not used)."""
    fluid, _ = check_fluid(scene.fluid, (), scene.state.q.dtype)
    velocity = velocity_field(fluid, scene.torque, scene.args)

    def run(state, dt, n, saves):
        def one(q):
            carry = scheme.init(q, jnp.zeros((), q.dtype), velocity)
            step = lambda c, t, _: scheme.step(c, t, dt, velocity)  # noqa: E731
            return saved_steps(carry, step, lambda c: c, dt, n, saves)

        return jax.vmap(one, axis_name=PARTICLES, out_axes=1)(state.q)

    return run


def plain_fluid_torque(scene):
    """The scene's torque plus its fluid's, as one plain torque callable (what a user gives diffrax)."""
    fluid, user = scene.fluid, scene.torque

    def torque(t, q, omega, args):
        tau = fluid.torque(q, omega)
        return tau if user is None else tau + user(t, q, omega, args)

    return torque


def diffrax_runner(solver_cls, scene, ts, max_steps=10**6):
    """``run(state, tol) -> (RotState at ts, result, attempted steps per body)`` with a PID controller."""
    if scene.inertia is not None:
        torque = plain_fluid_torque(scene)

        def run(state, tol):
            traj, result, steps = adaptive_solve(
                solver_cls(), state.q, state.omega, scene.inertia, False, ts, torque, scene.args, tol, tol,
                max_steps, None,
            )  # fmt: skip
            return RotState(traj.q, traj.omega), result, steps

        return run

    fluid, _ = check_fluid(scene.fluid, (), scene.state.q.dtype)
    velocity = velocity_field(fluid, scene.torque, scene.args)

    def field(t, q, args):
        return 0.5 * quat.multiply(quat.pure(velocity(t, quat.normalize(q))), q)

    def solve(q0, tol):
        sol = diffrax.diffeqsolve(
            diffrax.ODETerm(field), solver_cls(), ts[0], ts[-1], None, q0, saveat=diffrax.SaveAt(ts=ts),
            stepsize_controller=diffrax.PIDController(rtol=tol, atol=tol), max_steps=max_steps, throw=False,
        )  # fmt: skip
        q = quat.normalize(sol.ys)
        return q, jax.vmap(velocity)(ts, q), sol.result, sol.stats["num_steps"]

    def run(state, tol):
        q, omega, result, steps = jax.vmap(solve, in_axes=(0, None))(state.q, tol)
        return RotState(jnp.swapaxes(q, 0, 1), jnp.swapaxes(omega, 0, 1)), result, steps

    return run


def reference(scene, state, ts):
    """Float64 reference states at ``ts`` (``(len(ts), n_bodies, ...)``), the first a copy of ``state``."""
    n = len(ts) - 1
    dt = float(ts[1] - ts[0])
    if scene.inertia is None:
        per, run = 4096, overdamped_runner(OVERDAMPED_SCHEMES["rkmk4"].overdamped(), scene, None)
    else:
        per, run = 2048, inertial_runner(FLUID_SCHEMES["exp_rk4"], scene, None)
    saved = jax.jit(run, static_argnums=3)(state, jnp.asarray(dt / per), per, n)
    return RotState(*(jnp.concatenate([x[None], y]) for x, y in zip(state, saved, strict=True)))


def compare_fluid(
    scene="spheroid_shear",
    *,
    t_end=None,
    particles=100,
    dtype="float64",
    coarse_steps=5,
    levels=8,
    tolerances=None,
    schemes=None,
    solvers=None,
    repeats=3,
    progress=True,
):
    """`jaxrot.comparison.compare` for a scene of `jaxrot.scenes.FLUID_SCENES` (see the module)."""
    if dtype not in comparison.DTYPES:
        raise ValueError(f"`dtype` must be one of {sorted(comparison.DTYPES)}; got {dtype!r}.")
    ref_scene, run_scene = FLUID_SCENES[scene](jnp.float64), FLUID_SCENES[scene](comparison.DTYPES[dtype])
    methods = fixed_methods(run_scene)
    schemes = list(methods) if schemes is None else list(schemes)
    solvers = list(DIFFRAX_SOLVERS) if solvers is None else list(solvers)
    for label, chosen, known in (("schemes", schemes, methods), ("solvers", solvers, DIFFRAX_SOLVERS)):
        unknown = [x for x in chosen if x not in known]
        if unknown:
            raise ValueError(
                f"`{label}` has unknown names {unknown} for scene {scene!r}; known: {list(known)}."
            )
    tolerances = comparison.TOLERANCES[dtype] if tolerances is None else tuple(tolerances)
    t_end = ref_scene.t_end if t_end is None else float(t_end)
    dt_coarse = t_end / coarse_steps
    ts = jnp.arange(coarse_steps + 1, dtype=jnp.float64) * dt_coarse
    copies = lambda s: jax.tree_util.tree_map(lambda x: jnp.broadcast_to(x, (particles, *x.shape)), s)  # noqa: E731
    ref = reference(ref_scene, copies(ref_scene.state), ts)
    ref = Trajectory(ts, ref.q[:, 0], ref.omega[:, 0])
    batch = copies(run_scene.state)
    problem = comparison._Problem(
        scene, dtype, run_scene, ref_scene, ts, dt_coarse, coarse_steps, ref, batch, particles, True, None,
        False, None, None,
    )  # fmt: skip
    rows = []
    jobs = [(name, k) for name in schemes for k in range(levels + comparison.MAX_SATURATED_RUNGS)]
    finished = set()
    runners = {}
    for name, level in tqdm(jobs, desc="compare", disable=not progress, leave=False):
        if name in finished:
            continue
        kind, scheme = methods[name]
        if name not in runners:
            make = inertial_runner if kind == "inertial" else overdamped_runner
            run = make(scheme, run_scene, particles)
            example = (
                problem.batch,
                jnp.asarray(dt_coarse, problem.batch.q.dtype),
                jnp.asarray(1, jnp.int32),
            )
            start = time.perf_counter()
            compiled = (
                jax.jit(run, static_argnums=3, compiler_options=compiler_options())
                .lower(*example, coarse_steps)
                .compile()
            )
            runners[name] = (compiled, time.perf_counter() - start)
        compiled, compile_s = runners[name]
        factor = 2**level
        dt, n_steps = dt_coarse / factor, coarse_steps * factor
        args = (problem.batch, jnp.asarray(dt, problem.batch.q.dtype), jnp.asarray(factor, jnp.int32))
        saved, seconds = comparison.time_runs(compiled, args, repeats)
        traj = RotState(*(jnp.concatenate([x[None], y]) for x, y in zip(problem.batch, saved, strict=True)))
        evals = scheme.torque_evals_per_step if kind == "inertial" else scheme.velocity_evals_per_step
        method = {"method": name, "kind": "fixed", "order": scheme.order, "dt": dt, "tol": None}
        rows.append(comparison._row(problem, method, traj, n_steps, evals * n_steps + 1, seconds, compile_s))
        ladder = [r["max_orientation_error_rad"] for r in rows if r["method"] == name]
        counted = sum(e <= comparison.ASYMPTOTIC_ERROR for e in ladder)
        too_long = rows[-1]["us_per_particle_run"] * particles * 1e-6 > comparison.MAX_RUN_S
        if (
            counted >= levels
            or ladder[-1] < comparison.LADDER_FLOOR
            or comparison.stalled(ladder)
            or too_long
        ):
            finished.add(name)
    for name in solvers:
        run = diffrax_runner(DIFFRAX_SOLVERS[name], run_scene, ts.astype(problem.batch.q.dtype))
        solver = DIFFRAX_SOLVERS[name]()
        order = solver.order(diffrax.ODETerm(lambda t, y, a: y))
        # One program per solver: the tolerance is a runtime value (`diffrax_runner`).
        compiled, compile_s = comparison.compile_timed(
            run, problem.batch, jnp.asarray(1e-3, problem.batch.q.dtype), compiler_options=compiler_options()
        )
        for tol in tqdm(tolerances, desc=name, disable=not progress, leave=False):
            args = (problem.batch, jnp.asarray(tol, problem.batch.q.dtype))
            (traj, result, steps), seconds = comparison.time_runs(compiled, args, repeats)
            if np.any(np.asarray(result != diffrax.RESULTS.successful)):
                raise RuntimeError(f"compare: {name} failed at tol={tol:g}; use looser tolerances.")
            mean_steps = float(np.mean(np.asarray(steps)))
            evals = (
                int(round(solver.tableau.num_stages * mean_steps)) + 1 if hasattr(solver, "tableau") else None
            )
            method = {"method": name, "kind": "adaptive", "order": order, "dt": None, "tol": tol}
            rows.append(
                comparison._row(problem, method, traj, int(round(mean_steps)), evals or 0, seconds, compile_s)
            )
    return rows
