"""The rows of `benchmarks/fluid_race.py` that are not jaxrot's fluid runners: its bodies, an explicit
scheme with the fluid's torque as a plain callable, and diffrax's solvers as a user would write them."""

import diffrax
import jax
import jax.numpy as jnp

import jaxrot
from jaxrot import quaternion as quat
from jaxrot._diffrax._reference import adaptive_solve
from jaxrot._particles import PARTICLES
from jaxrot.comparison._fluid import plain_fluid_torque


def bodies(scene, n, seed=0):
    """``n`` copies of the scene's spheroid at random orientations, each turning at its overdamped ω."""
    q = quat.normalize(jax.random.normal(jax.random.PRNGKey(seed), (n, 4), dtype=jnp.float64))
    return jaxrot.RotState(q, scene.fluid.angular_velocity(q))


def explicit_runner(name, scene):
    """A scheme of `jaxrot.SCHEMES` with the fluid's torque as a plain callable (no fluid=)."""
    scheme = jaxrot.SCHEMES[name]
    inertia = jaxrot.body_inertia(scene.inertia)
    torque = plain_fluid_torque(scene)

    def run(state, dt, n, saves):
        def one(q, omega):
            carry = scheme.init(jaxrot.RotState(q, omega), jnp.zeros(()), inertia, torque, None)
            step = lambda i, c: scheme.step(c, i.astype(dt.dtype) * dt, dt, inertia, torque, None)  # noqa: E731
            return scheme.state(jax.lax.fori_loop(0, n, step, carry))

        final = jax.vmap(one, axis_name=PARTICLES)(state.q, state.omega)
        return jax.tree_util.tree_map(lambda x: x[None], final)

    return run


def imex_runner(scene, max_steps):
    """diffrax's IMEX ``KenCarp4`` as a user who knows stiff solvers writes it: the friction's linear
    part ``−I⁻¹ ζ ⊙ ω_b`` implicit, the rest (the flow's torque, Euler's gyroscopic term, q̇) explicit,
    on the Euclidean quaternion of `jaxrot.reference_rollout`, a PID controller at rtol = atol = tol."""
    fluid = scene.fluid
    inertia = jaxrot.body_inertia(scene.inertia)
    friction = jnp.asarray(fluid.friction)

    def explicit(t, y, args):
        q, omega_b = y
        unit = quat.normalize(q)
        tau_b = quat.rotate(quat.conjugate(unit), fluid.torque(unit, quat.rotate(unit, omega_b)))
        tau_b = tau_b + friction * omega_b  # the implicit part's, taken back out
        return 0.5 * quat.multiply(q, quat.pure(omega_b)), inertia.angular_acceleration(omega_b, tau_b)

    def implicit(t, y, args):
        q, omega_b = y
        return jnp.zeros_like(q), -inertia.solve(friction * omega_b)

    terms = diffrax.MultiTerm(diffrax.ODETerm(explicit), diffrax.ODETerm(implicit))

    def run(state, tol):
        def one(q0, omega0):
            sol = diffrax.diffeqsolve(
                terms, diffrax.KenCarp4(), t0=0.0, t1=scene.t_end, dt0=None,
                y0=(q0, quat.rotate(quat.conjugate(q0), omega0)),
                stepsize_controller=diffrax.PIDController(rtol=tol, atol=tol),
                max_steps=max_steps, throw=False,
            )  # fmt: skip
            return quat.normalize(sol.ys[0][-1]), sol.result, sol.stats["num_steps"]

        return jax.vmap(one)(state.q, state.omega)

    return jax.jit(run)


def diffrax_runner(solver_cls, scene, max_steps):
    if solver_cls is None:
        return imex_runner(scene, max_steps)
    torque = plain_fluid_torque(scene)
    ts = jnp.array([0.0, scene.t_end])

    def run(state, tol):
        traj, result, steps = adaptive_solve(
            solver_cls(),
            state.q,
            state.omega,
            scene.inertia,
            False,
            ts,
            torque,
            None,
            tol,
            tol,
            max_steps,
            None,
        )
        return traj.q[-1], result, steps

    return jax.jit(run)
