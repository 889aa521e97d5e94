"""Why the splittings refuse a fluid: a Strang splitting with the friction's exact step, measured.

The splitting O(h/2) B(h/2) A(h) B(h/2) O(h/2): O relaxes the body-frame angular velocity exactly
towards the flow's rotation with the orientation frozen, ``u ← g(q) + e^{−ζh/2I}(u − g(q))``; B kicks
by the applied torque; A is the exact torque-free motion (`jaxrot.analytic.free_motion`). It is
stable at any ζΔt/I. The body: the aspect-4 spheroid in shear of `benchmarks/fluid_orders.py`
(with and without its magnetic torque), over t = 4 from its slow manifold; the reference is
`exp_rk4` at 2^14 steps. As ζΔt/I grows the O step erases the kicks before the rotor turns the body
(BAOAB's high-friction limit: right invariant measure, wrong time scale), and relaxing towards
g(q_n) with q frozen is Lie–Euler on the overdamped model: first order without a torque, no
convergence with one. This is what the ``ValueError`` of `jaxrot.rollout(..., fluid=...)` for the
splittings stands on. Accuracy only (no timing):

    python benchmarks/fluid_splitting.py
"""

import sys

import jax


jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np

import jaxrot
from jaxrot import quaternion as quat
from jaxrot._fluid._flow import body_flow
from jaxrot.analytic import free_motion


sys.path.insert(0, str(__import__("pathlib").Path(__file__).parent))
from fluid_orders import MAGNET, Q0, fluid, inertia, magnetic_torque  # noqa: E402


def splitting(stokes, with_magnet):
    """``run(q, omega, h, n) -> q`` of the splitting (one compilation for any h and n)."""
    body = inertia(stokes)
    friction = fluid().friction
    gradient, bretherton = fluid().velocity_gradient, fluid().bretherton

    def relax(q, omega, h):  # O: exact friction step towards the flow's rotation, q frozen
        u = quat.rotate(quat.conjugate(q), omega)
        g = body_flow(q, gradient, bretherton)[0]
        return quat.rotate(q, g + jnp.exp(-h * friction / body) * (u - g))

    def kick(t, q, omega, h):  # B: the applied torque's impulse
        if not with_magnet:
            return omega
        tau_b = quat.rotate(quat.conjugate(q), magnetic_torque(t, q, omega, MAGNET))
        return omega + quat.rotate(q, h * tau_b / body)

    @jax.jit
    def run(q, omega, h, n):
        def step(i, state):
            q, omega = state
            t = i * h
            omega = kick(t, q, relax(q, omega, h / 2), h / 2)
            q, omega = free_motion(q, omega, body, h)
            omega = relax(q, kick(t + h, q, omega, h / 2), h / 2)
            return q, omega

        return jax.lax.fori_loop(0, n, step, (q, omega))[0]

    return run


def main():
    steps = [32, 64, 128, 256, 512]
    print(f"{'St':>6} {'torque':<7} {'ζΔt/I':>15}  errors at {steps} steps (t = 4)   local orders")
    for stokes in (1e-2, 1e-6):
        for with_magnet in (False, True):
            torque, args = (magnetic_torque, MAGNET) if with_magnet else (None, None)
            tau0 = None if torque is None else torque(0.0, Q0, None, args)
            state = jaxrot.RotState(Q0, fluid().angular_velocity(Q0, tau0))
            reference = jaxrot.rollout(
                "exp_rk4",
                state,
                inertia(stokes),
                4.0 / 2**14,
                2**14,
                torque=torque,
                args=args,
                fluid=fluid(),
                save_every=2**14,
            ).q[-1]
            run = splitting(stokes, with_magnet)
            errors = np.array([float(quat.angle_between(run(*state, 4.0 / n, n), reference)) for n in steps])
            rates = np.asarray(fluid().friction / inertia(stokes))
            span = f"{rates.min() * 4 / steps[-1]:.2g}…{rates.max() * 4 / steps[0]:.2g}"
            orders = " ".join(f"{x:.2f}" for x in np.log2(errors[:-1] / errors[1:]))
            print(
                f"{stokes:6.0e} {'magnet' if with_magnet else 'none':<7} {span:>15}  "
                f"{' '.join(f'{e:.2e}' for e in errors)}   {orders}"
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
