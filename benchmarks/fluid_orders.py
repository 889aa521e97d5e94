"""Orders of accuracy with a fluid, from ζΔt/I = 0 to 1e8: docs/fluid_orders.json (accuracy only, no timing).

The body: a prolate spheroid of aspect ratio 4 (Perrin's frictions at viscosity 1) in the simple
shear u = (y, 0, 0) of rate 1, with the moments of a uniform spheroid scaled to a Stokes number
St = I_⊥ γ̇ / ζ_⊥, with and without a magnetic torque m × B (m = 100 along the body axis,
B = (0, 1, 0.3)), started on the slow manifold (turning at the overdamped angular velocity), over
t = 4. Each row halves the step from 16 (exp_rk4) or 32 (exp_midpoint) steps four times and fits the
slope of log(final orientation error) against log(dt). The reference: `jaxrot.reference_rollout`
(Dopri8, 1e-13) with the fluid's torque as a plain callable where St >= 1e-3; below, where that
would take 10^5 to 10^9 steps, the same scheme at a 16th of the finest step (at St = 1e-3 both are
computed and their distance is recorded). Row "none" runs without a fluid (ζ = 0: the heavy top
scene, reference Dopri8); the overdamped rows run `jaxrot.overdamped_rollout`'s schemes over one
Jeffery period against RKMK4 at 16384 steps.

    python benchmarks/fluid_orders.py                # writes docs/fluid_orders.json (~1 min on 2 cores)
    python benchmarks/fluid_orders.py --quick        # a smaller table to stdout (written only with --out)
"""

import argparse
import functools
import json
import sys
from pathlib import Path

import jax


jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np

import jaxrot
from jaxrot import quaternion as quat
from jaxrot._fluid._fluid import check_fluid
from jaxrot._integrate._overdamped import velocity_field
from jaxrot.comparison import machine_info
from jaxrot.comparison._fluid import FLUID_ROWS, OVERDAMPED_ROWS
from jaxrot.schemes import OVERDAMPED_SCHEMES
from jaxrot.schemes._exponential import FluidArgs


ROOT = Path(__file__).resolve().parents[1]
SHEAR = jnp.zeros((3, 3)).at[0, 1].set(1.0)
ASPECT = 4.0
Q0 = quat.exp(jnp.array([0.3, -0.5, 0.7]))
T_END = 4.0
MAGNET = {"moment": 100.0, "field": jnp.array([0.0, 1.0, 0.3])}


def fluid():
    return jaxrot.Fluid.spheroid(ASPECT, 1.0, 1.0, velocity_gradient=SHEAR)


def inertia(stokes):
    shape = jnp.array([ASPECT**2 + 1, ASPECT**2 + 1, 2.0]) / 5
    return stokes * fluid().friction[0] / shape[0] * shape


def magnetic_torque(t, q, omega, args):
    return jnp.cross(args["moment"] * quat.rotate(q, jnp.array([0.0, 0.0, 1.0])), args["field"])


@functools.cache  # one function per torque: reference_rollout's compiled program is reused
def plain_torque(with_magnet):
    def torque(t, q, omega, args):
        tau = fluid().torque(q, omega)
        return tau + magnetic_torque(t, q, omega, args) if with_magnet else tau

    return torque


def _final_q(scheme, body_inertia, torque, args, state, dt, n):
    """The orientation after ``n`` plain `step`s of ``scheme`` from t = 0 (traced in a runner's jit)."""
    carry = scheme.init(state, jnp.zeros(()), body_inertia, torque, args)
    step = lambda i, c: scheme.step(c, i * dt, dt, body_inertia, torque, args)  # noqa: E731
    return scheme.state(jax.lax.fori_loop(0, n, step, carry)).q


def runner(scheme, body_inertia, torque, args, fluid_values):
    """``run(state, dt, n) -> q``: one compilation for any dt and n."""
    if fluid_values is not None:
        scheme, args = scheme.in_fluid(), FluidArgs(args, fluid_values)
    return jax.jit(functools.partial(_final_q, scheme, jaxrot.body_inertia(body_inertia), torque, args))


@functools.cache
def fluid_runner(name, with_magnet):
    """``run(state, moments, args, fluid_values, dt, n) -> q``: the scheme in the fluid, one compilation
    for every Stokes number (the moments, the torque's arguments, dt and n are runtime values)."""
    scheme = jaxrot.FLUID_SCHEMES[name].in_fluid()
    torque = magnetic_torque if with_magnet else None

    @jax.jit
    def run(state, moments, args, fluid_values, dt, n):
        fluid_args = FluidArgs(args, fluid_values)
        return _final_q(scheme, jaxrot.body_inertia(moments), torque, fluid_args, state, dt, n)

    return run


@functools.cache
def dopri8_reference(stokes, with_magnet):
    """The final orientation by `jaxrot.reference_rollout` (Dopri8, 1e-13), shared by every scheme."""
    body, args = inertia(stokes), (MAGNET if with_magnet else None)
    return jaxrot.reference_rollout(
        start(with_magnet), body, jnp.array([0.0, T_END]), torque=plain_torque(with_magnet), args=args,
        rtol=1e-13, atol=1e-13, max_steps=10**7,
    ).q[-1]  # fmt: skip


def start(with_magnet):
    """On the slow manifold: turning at the overdamped angular velocity."""
    tau0 = magnetic_torque(0.0, Q0, None, MAGNET) if with_magnet else None
    return jaxrot.RotState(Q0, fluid().angular_velocity(Q0, tau0))


def fit(steps, errors, t_end):
    dts = t_end / np.asarray(steps)
    return float(np.polyfit(np.log(dts), np.log(errors), 1)[0])


def fluid_row(name, stokes, with_magnet, levels):
    scheme = jaxrot.FLUID_SCHEMES[name]
    body = inertia(stokes)
    state = start(with_magnet)
    values, _ = check_fluid(fluid(), (), jnp.float64)
    compiled = fluid_runner(name, with_magnet)
    run = lambda state, dt, n: compiled(state, body, MAGNET if with_magnet else None, values, dt, n)  # noqa: E731
    first = 16 if scheme.order >= 4 else 32
    steps = [first * 2**k for k in range(levels)]
    fine = run(state, T_END / (16 * steps[-1]), 16 * steps[-1])
    reference, source, gap = fine, "same scheme, 16x finer", None
    if stokes >= 1e-3:
        dopri = dopri8_reference(stokes, with_magnet)
        gap = float(quat.angle_between(dopri, fine))
        reference, source = dopri, "reference_rollout (Dopri8, 1e-13)"
    errors = [float(quat.angle_between(run(state, T_END / n, n), reference)) for n in steps]
    rates = np.asarray(fluid().friction / body)
    return {
        "scheme": name,
        "stokes": stokes,
        "torque": "magnet" if with_magnet else "none",
        "zeta_dt_over_inertia": [
            float(rates.min() * T_END / steps[-1]),
            float(rates.max() * T_END / steps[0]),
        ],
        "steps": steps,
        "errors": errors,
        "order": fit(steps, errors, T_END),
        "local_orders": [float(np.log2(a / b)) for a, b in zip(errors, errors[1:], strict=False)],
        "reference": source,
        "reference_gap": gap,
    }


def frictionless_row(name, levels):
    """ζ = 0: the scheme without a fluid, on the heavy top (reference Dopri8 1e-13)."""
    scene = jaxrot.SCENES["heavy_top"]()
    run = runner(jaxrot.FLUID_SCHEMES[name], scene.inertia, scene.torque, scene.args, None)
    reference = jaxrot.reference_rollout(
        scene.state,
        scene.inertia,
        jnp.array([0.0, 1.0]),
        torque=scene.torque,
        args=scene.args,
        rtol=1e-13,
        atol=1e-13,
    ).q[-1]
    first = 16 if jaxrot.FLUID_SCHEMES[name].order >= 4 else 32
    steps = [first * 2**k for k in range(levels)]
    errors = [float(quat.angle_between(run(scene.state, 1.0 / n, n), reference)) for n in steps]
    return {
        "scheme": name, "stokes": None, "torque": "heavy top, no fluid", "zeta_dt_over_inertia": [0.0, 0.0],
        "steps": steps, "errors": errors, "order": fit(steps, errors, 1.0),
        "local_orders": [float(np.log2(a / b)) for a, b in zip(errors, errors[1:], strict=False)],
        "reference": "reference_rollout (Dopri8, 1e-13)", "reference_gap": None,
    }  # fmt: skip


def overdamped_row(name, levels):
    scheme = OVERDAMPED_SCHEMES[name].overdamped()  # the stepper of the overdamped model
    values, _ = check_fluid(fluid(), (), jnp.float64)
    velocity = velocity_field(values, None, None)

    @jax.jit
    def run(dt, n):
        carry = scheme.init(Q0, 0.0, velocity)
        return jax.lax.fori_loop(0, n, lambda i, c: scheme.step(c, i * dt, dt, velocity), carry).q

    period = float(2 * np.pi * (ASPECT + 1 / ASPECT))
    reference = jaxrot.overdamped_rollout(Q0, fluid(), period / 16384, 16384, save_every=16384).q[-1]
    first = 128 if scheme.order >= 4 else 256
    steps = [first * 2**k for k in range(levels)]
    errors = [float(quat.angle_between(run(period / n, n), reference)) for n in steps]
    return {
        "scheme": f"overdamped {name}", "stokes": 0.0, "torque": "none", "zeta_dt_over_inertia": None,
        "steps": steps, "errors": errors, "order": fit(steps, errors, period),
        "local_orders": [float(np.log2(a / b)) for a, b in zip(errors, errors[1:], strict=False)],
        "reference": "rkmk4 at 16384 steps a period", "reference_gap": None,
    }  # fmt: skip


def table(rows):
    lines = [f"{'scheme':<22} {'St':>7} {'torque':<20} {'ζΔt/I':>19} {'order':>6}  local orders"]
    for r in rows:
        zeta = r["zeta_dt_over_inertia"]
        span = "—" if zeta is None else f"{zeta[0]:.2g}…{zeta[1]:.2g}"
        stokes = "—" if r["stokes"] is None else f"{r['stokes']:.0e}"
        local = " ".join(f"{x:.2f}" for x in r["local_orders"])
        lines.append(
            f"{r['scheme']:<22} {stokes:>7} {r['torque']:<20} {span:>19} {r['order']:>6.2f}  {local}"
        )
    return "\n".join(lines)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--quick", action="store_true", help="2 Stokes numbers, 3 rungs; written to --out if not docs/"
    )
    parser.add_argument("--out", default=str(ROOT / "docs" / "fluid_orders.json"))
    ns = parser.parse_args(argv)
    stokes_numbers = (1.0, 1e-6) if ns.quick else (1.0, 1e-1, 1e-2, 1e-3, 1e-4, 1e-6, 1e-8)
    levels = 3 if ns.quick else 5
    rows = []
    for name in FLUID_ROWS:
        rows.append(frictionless_row(name, levels))
        for stokes in stokes_numbers:
            for with_magnet in (False, True):
                rows.append(fluid_row(name, stokes, with_magnet, levels))
                print(table(rows[-1:]).splitlines()[-1], flush=True)
    rows += [overdamped_row(name, levels) for name in OVERDAMPED_ROWS]
    print(table(rows))
    # A quick run is written only elsewhere than the published file (regenerate.py --quick: a scratch folder).
    if not ns.quick or Path(ns.out).resolve() != (ROOT / "docs" / "fluid_orders.json").resolve():
        Path(ns.out).write_text(json.dumps({"machine": machine_info(), "rows": rows}, indent=2))
        print(f"wrote {ns.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
