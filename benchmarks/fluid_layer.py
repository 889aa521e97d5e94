"""The exponential schemes' orders across ζΔt/I from 5e-3 to 2.5e4, started off and on the slow manifold.

The body: principal moments ``ζ / R`` (frictions ζ = (1, 1, 0.4), decay rates ``ζ/I = R`` = 10, 1e3,
1e5) carrying a magnetic moment (3 × (0.3, 0, 1)) in a field rotating about z at 2 rad/s with a
static z part 0.3, a torque that depends on q and t (`jaxrot.Fluid` without flow). Started at rest
("off": the body relaxes onto the field's pull within I/ζ, a boundary layer) or at the slow velocity
``S`` ("on"). Over t = 4 each ladder halves the step from 0.25 nine times; the reference is the same
scheme, graded, at a 16th of the finest step (at R = 1e3 its distance to `jaxrot.reference_rollout`,
Dopri8 at 1e-13 with the fluid's torque as a plain callable, is recorded). Each scheme runs with its
graded start (the default: `jaxrot.schemes._exponential`) and without (``graded_start=False``).
Accuracy only, no timing:

    python benchmarks/fluid_layer.py            # writes docs/fluid_layer.json (~1 min on 2 cores)
    python benchmarks/fluid_layer.py --quick    # R = 1e3 only, to stdout
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
from _fluid_probe import final_orientation_runner  # benchmarks/, beside this script

import jaxrot
from jaxrot import quaternion as quat
from jaxrot._fluid._fluid import check_fluid
from jaxrot.comparison import machine_info
from jaxrot.schemes import FLUID_SCHEMES
from jaxrot.schemes._exponential import FluidArgs


ROOT = Path(__file__).resolve().parents[1]
FRICTION = jnp.array([1.0, 1.0, 0.4])
FIELD = {"moment": 3.0, "angular_frequency": 2.0}
Q0 = quat.exp(jnp.array([0.3, -0.5, 0.7]))
T_END = 4.0
RATES = (10.0, 1e3, 1e5)
STEPS = [16 * 2**k for k in range(10)]
REFINE = 16


def torque(t, q, omega, args):
    phase = jnp.asarray(args["angular_frequency"] * t, q.dtype)
    field = jnp.stack([jnp.cos(phase), jnp.sin(phase), jnp.full_like(phase, 0.3)])
    return jnp.cross(args["moment"] * quat.rotate(q, jnp.array([0.3, 0.0, 1.0], q.dtype)), field)


def fluid():
    return jaxrot.Fluid(FRICTION)


def start(kind):
    omega = jnp.zeros(3) if kind == "off" else fluid().angular_velocity(Q0, torque(0.0, Q0, None, FIELD))
    return jaxrot.RotState(Q0, omega)


def runner(scheme, rate):
    """``run(state, dt, n) -> q``: one compilation for any dt and n."""
    args = FluidArgs(FIELD, check_fluid(fluid(), (), jnp.float64)[0])
    return final_orientation_runner(scheme, jaxrot.body_inertia(FRICTION / rate), torque, args)


@functools.cache  # one compiled program per scheme, start rule and rate, shared by both starts
def scheme_runner(name, graded, rate):
    return runner(type(FLUID_SCHEMES[name])(graded_start=graded), rate)


@functools.cache  # the graded run at a 16th of the finest step: one per scheme, rate and start
def reference(name, rate, kind):
    return scheme_runner(name, True, rate)(start(kind), T_END / (REFINE * STEPS[-1]), REFINE * STEPS[-1])


def ladder(name, rate, graded, kind):
    state = start(kind)
    run = scheme_runner(name, graded, rate)
    errors = [float(quat.angle_between(run(state, T_END / n, n), reference(name, rate, kind))) for n in STEPS]
    return {
        "scheme": name,
        "rate": rate,
        "graded_start": graded,
        "start": kind,
        "zeta_dt_over_inertia": [rate * T_END / n for n in STEPS],
        "errors": errors,
        "local_orders": [float(np.log2(a / b)) for a, b in zip(errors, errors[1:], strict=False)],
    }


def reference_gap(name, rate, kind):
    """Distance of the fine reference to Dopri8 (1e-13) with the fluid's torque as a plain callable."""
    state = start(kind)
    fine = reference(name, rate, kind)

    def plain(t, q, omega, args):
        return fluid().torque(q, omega) + torque(t, q, omega, args)

    dopri = jaxrot.reference_rollout(
        state, FRICTION / rate, jnp.array([0.0, T_END]), torque=plain, args=FIELD,
        rtol=1e-13, atol=1e-13, max_steps=10**7,
    ).q[-1]  # fmt: skip
    return float(quat.angle_between(dopri, fine))


def main(argv=None):
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--out", default=str(ROOT / "docs" / "fluid_layer.json"))
    options = parser.parse_args(argv)
    rates = (1e3,) if options.quick else RATES
    rows = []
    for name in ("exp_rk4", "exp_midpoint"):
        for rate in rates:
            for kind in ("off", "on"):
                for graded in (True, False):
                    row = ladder(name, rate, graded, kind)
                    rows.append(row)
                    orders = " ".join(f"{o:5.2f}" for o in row["local_orders"])
                    print(f"{name:13s} R={rate:7.0e} {kind:3s} graded={graded!s:5s} {orders}", flush=True)
    gaps = {
        f"{name} {kind}": reference_gap(name, 1e3, kind) for name in ("exp_rk4",) for kind in ("off", "on")
    }
    print("reference gap to Dopri8 at R = 1e3:", gaps)
    if options.quick:
        return
    result = {"machine": machine_info(), "t_end": T_END, "reference_gap_rate_1e3": gaps, "rows": rows}
    Path(options.out).write_text(json.dumps(result, indent=1) + "\n")
    print("wrote", options.out)


if __name__ == "__main__":
    sys.exit(main())
