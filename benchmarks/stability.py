"""Stability limits of every scheme, as markdown tables for the docs (issue 6).

1. The largest rotation per step |ω|Δt (rad) at which the error per step stays below 1e-3 rad
   (`jaxrot.stability.max_stable_rotation_per_step`: 8 steps of a torque-free body against its
   exact motion), for a generic body, a needle of inertia ratio 1e6, the flattest disc and a
   sphere, in float64 and float32.
2. The smallest |ω|Δt, from 1e-12 to 10, at which a scheme returns a NaN or an infinity within
   8 steps (its blow-up), and the largest | |q| - 1 | below it.
3. Drifts over 10^6 steps of the default free body (dt = 0.01, |ω|Δt = 0.023): | |q| - 1 |,
   relative energy and angular-momentum drift (`jaxrot.stability.long_run_drift`).
4. Each bad input tried and the message it produces.

    python benchmarks/stability.py                 # everything: a few minutes on one CPU core
    python benchmarks/stability.py --steps 100000  # shorter long runs
    python benchmarks/stability.py --json docs/stability_cpu.json  # the results file the docs render
"""

import argparse
import json
import os
import platform
import sys
import time
import warnings

import jax


jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np
from tqdm.auto import tqdm

import jaxrot
from jaxrot import analytic, quaternion as quat, stability
from jaxrot.comparison import machine_info
from jaxrot.schemes import Rozmanov


DTYPES = {"float64": jnp.float64, "float32": jnp.float32}
BODIES = {
    "generic (1, 2, 3)": (1.0, 2.0, 3.0),
    "needle (1e-6, 1, 1)": (1e-6, 1.0, 1.0),
    "flat disc (1, 1, 2)": (1.0, 1.0, 2.0),
    "sphere (1, 1, 1)": (1.0, 1.0, 1.0),
}


def header():
    device = jax.devices()[0]
    return "\n".join(
        [
            f"- machine: {platform.platform()}, {platform.machine()}, {os.cpu_count()} CPU(s); "
            f"device: {device.platform} ({device.device_kind})",
            f"- python {sys.version.split()[0]}, jax {jax.__version__}, jaxrot {jaxrot.__version__}, "
            f"numpy {np.__version__}",
        ]
    )


def fmt(x):
    if x is None:
        return "—"
    if not np.isfinite(x):
        return "inf"
    return f"{x:.3g}" if x != 0 else "0"


def limits(schemes):
    """Rows ``{scheme, body, dtype, limit}``: `stability.max_stable_rotation_per_step` (rad per step)."""
    rows = []
    for name in tqdm(schemes, desc="limits"):
        for body in BODIES:
            for dtype in DTYPES:
                inertia, dtype_ = BODIES[body], DTYPES[dtype]
                limit = stability.max_stable_rotation_per_step(name, inertia=inertia, dtype=dtype_)
                rows.append({"scheme": name, "body": body, "dtype": dtype, "limit": float(limit)})
    return rows


def blow_ups(schemes):
    """Rows ``{scheme, dtype, first_nonfinite, max_norm_error_below}`` on a ladder 1e-12 … 10 rad per step."""
    ladder = np.logspace(-12, 1, 131)
    rows = []
    for name in tqdm(schemes, desc="blow-up"):
        for dtype in DTYPES:
            result = stability.rotation_ladder(name, ladder, dtype=DTYPES[dtype])
            bad = ladder[~result.finite]
            first = float(bad[0]) if bad.size else None
            below = result.norm_error[ladder < (first if first is not None else np.inf)]
            rows.append(
                {
                    "scheme": name,
                    "dtype": dtype,
                    "first_nonfinite": first,
                    "max_norm_error_below": float(below.max()),
                }
            )
    return rows


def drifts(schemes, n_steps):
    """Rows of `stability.long_run_drift` over ``n_steps`` steps, with the wall time (compile included)."""
    rows = []
    for dtype in DTYPES:
        for name in tqdm(schemes, desc=f"{n_steps} steps {dtype}"):
            start = time.perf_counter()
            drift = stability.long_run_drift(name, n_steps, dtype=DTYPES[dtype])
            rows.append(
                {
                    "scheme": name,
                    "dtype": dtype,
                    "steps": n_steps,
                    "norm": float(drift.norm),
                    "energy": float(drift.energy),
                    "momentum": float(drift.momentum),
                    "first_nonfinite_step": drift.first_nonfinite_step,
                    "wall_s": time.perf_counter() - start,
                }
            )
    return rows


def limits_table(rows):
    columns = [(body, dtype) for body in BODIES for dtype in DTYPES]
    value = {(r["scheme"], r["body"], r["dtype"]): r["limit"] for r in rows}
    lines = [
        "| scheme | " + " | ".join(f"{body} {dtype}" for body, dtype in columns) + " |",
        "|---" * (len(columns) + 1) + "|",
    ]
    for name in dict.fromkeys(r["scheme"] for r in rows):
        cells = ["≥ 10" if value[name, *c] >= 10 else fmt(value[name, *c]) for c in columns]
        lines.append(f"| `{name}` | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def blow_up_table(rows):
    lines = [
        "| scheme | first non-finite |ω|Δt, float64 | max ‖q‖−1 below it | "
        "first non-finite, float32 | max ‖q‖−1 below it |",
        "|---|---|---|---|---|",
    ]
    for name in dict.fromkeys(r["scheme"] for r in rows):
        cells = []
        for r in (r for r in rows if r["scheme"] == name):
            first = r["first_nonfinite"]
            cells += ["none ≤ 10" if first is None else fmt(first), fmt(r["max_norm_error_below"])]
        lines.append(f"| `{name}` | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def drift_table(rows):
    lines = [
        "| scheme | dtype | max ‖q‖−1 | max ΔE/E₀ | max ‖ΔL‖/‖L₀‖ | wall s (incl. compile) |",
        "|---|---|---|---|---|---|",
    ]
    for r in rows:
        step = r["first_nonfinite_step"]
        nonfinite = "" if step is None else f" (non-finite at {step})"
        lines.append(
            f"| `{r['scheme']}` | {r['dtype']} | {fmt(r['norm'])} | {fmt(r['energy'])}{nonfinite} | "
            f"{fmt(r['momentum'])} | {r['wall_s']:.1f} |"
        )
    return "\n".join(lines)


def bad_inputs():
    """(description, callable) pairs: each should raise a clear ValueError."""
    q0 = quat.exp(jnp.array([0.1, 0.2, 0.3]))
    state = jaxrot.RotState(q0, quat.rotate(q0, jnp.array([1.0, 2.0, 0.5])))
    moments = jnp.array([1.0, 2.0, 3.0])
    rot = quat.to_matrix(q0)

    def run(state=state, inertia=moments, dt=0.01, n_steps=3, scheme="zhao", **kwargs):
        return lambda: jaxrot.rollout(scheme, state, inertia, dt, n_steps, **kwargs)

    f32 = jaxrot.RotState(state.q.astype(jnp.float32), state.omega.astype(jnp.float32))
    return [
        ("zero moment (0, 1, 1)", run(inertia=jnp.array([0.0, 1.0, 1.0]))),
        ("zero moment in a full tensor", run(inertia=rot @ jnp.diag(jnp.array([0.0, 1.0, 1.0])) @ rot.T)),
        ("negative moment (-1, 2, 2)", run(inertia=jnp.array([-1.0, 2.0, 2.0]))),
        ("disc of ratio 1e6 (1, 1, 1e6)", run(inertia=jnp.array([1.0, 1.0, 1e6]))),
        ("needle of ratio 1e20 (1e-20, 1, 1), float64", run(inertia=jnp.array([1e-20, 1.0, 1.0]))),
        ("needle of ratio 1e10 (1e-10, 1, 1), float32", run(state=f32, inertia=jnp.array([1e-10, 1.0, 1.0]))),
        ("subnormal moments (1e-320, 1e-320, 1e-320)", run(inertia=jnp.full(3, 1e-320))),
        ("inertia not symmetric", run(inertia=jnp.diag(moments).at[0, 1].set(0.1))),
        ("inertia NaN", run(inertia=moments.at[0].set(jnp.nan))),
        ("inertia of shape (4,)", run(inertia=jnp.ones(4))),
        ("q not unit (|q| = 1 + 1e-4)", run(state=jaxrot.RotState(state.q * (1 + 1e-4), state.omega))),
        ("q zero", run(state=jaxrot.RotState(jnp.zeros(4), state.omega))),
        ("q NaN", run(state=jaxrot.RotState(state.q.at[0].set(jnp.nan), state.omega))),
        ("omega infinite", run(state=jaxrot.RotState(state.q, state.omega.at[1].set(jnp.inf)))),
        ("omega of shape (4,)", run(state=jaxrot.RotState(state.q, jnp.zeros(4)))),
        ("dt = 0", run(dt=0.0)),
        ("dt = -0.1", run(dt=-0.1)),
        ("dt = inf", run(dt=float("inf"))),
        ("n_steps = -1", run(n_steps=-1)),
        ("n_steps = 2.5", run(n_steps=2.5)),
        ("save_every = 0", run(save_every=0)),
        ("unknown scheme 'rk4'", run(scheme="rk4")),
        ("torque not callable", run(torque=jnp.zeros(3))),
        ("torque returning shape (2,)", run(torque=lambda t, q, omega, args: jnp.zeros(2))),
        ("Rozmanov(max_iter=0)", lambda: Rozmanov(max_iter=0)),
        ("Rozmanov(tol=-1.0)", lambda: Rozmanov(tol=-1.0)),
        (
            "reference_rollout, ratio-1e6 disc",
            lambda: jaxrot.reference_rollout(state, jnp.array([1.0, 1.0, 1e6]), jnp.array([0.0, 1.0])),
        ),
        (
            "analytic.free_top, zero moment",
            lambda: analytic.free_top(state, jnp.array([0.0, 1.0, 1.0]), jnp.array([0.0, 1.0])),
        ),
        ("stability.rotation_ladder, negative |ω|Δt", lambda: stability.rotation_ladder("zhao", [-1.0])),
    ]


def runtime_examples():
    """Valid but extreme inputs that overflow: what runtime_check=True says."""
    q0 = quat.exp(jnp.array([0.1, 0.2, 0.3]))
    direction = quat.rotate(q0, jnp.array([1.0, 2.0, 0.5]) / np.sqrt(5.25))
    return [
        (
            "zhao at |ω|Δt = 10 (|ω| = 1e4 rad/s, dt = 1e-3)",
            lambda: jaxrot.rollout(
                "zhao",
                jaxrot.RotState(q0, 1e4 * direction),
                jnp.array([1.0, 2.0, 3.0]),
                1e-3,
                20,
                runtime_check=True,
            ),
        ),
        (
            "euler, |ω| = 1e200 rad/s (overflows ω × Iω)",
            lambda: jaxrot.rollout(
                "euler",
                jaxrot.RotState(q0, 1e200 * direction),
                jnp.array([1.0, 2.0, 3.0]),
                0.01,
                5,
                runtime_check=True,
            ),
        ),
    ]


def messages(cases, expected):
    rows = []
    for description, fn in cases:
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                fn()
            text = "**no error**"
        except expected as error:
            text = f"`{type(error).__name__}`: {error}"
        rows.append(f"| {description} | {text.replace('|', '∣')} |")
    return "\n".join(["| input | message |", "|---|---|", *rows])


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=1_000_000, help="steps of the long runs (default 10^6)")
    parser.add_argument(
        "--schemes", default=",".join(jaxrot.SCHEMES), help="comma-separated scheme names (default: all)"
    )
    parser.add_argument("--json", default=None, help="also write the rows here")
    opts = parser.parse_args(argv)
    schemes = opts.schemes.split(",")
    info = machine_info()
    results = {
        "machine": info,
        "options": vars(opts),
        "limits": limits(schemes),
        "blow_up": blow_ups(schemes),
        "drift": drifts(schemes, opts.steps),
    }
    if opts.json:
        with open(opts.json, "w") as f:
            json.dump(results, f, indent=2)
    print("# jaxrot stability limits\n")
    print(header(), "\n")
    print("## Largest |ω|Δt (rad per step) with error per step ≤ 1e-3 rad\n")
    print(limits_table(results["limits"]), "\n")
    print("## Blow-up within 8 steps (generic body)\n")
    print(blow_up_table(results["blow_up"]), "\n")
    print(f"## Drift over {opts.steps} steps (free body, dt = 0.01, sampled every 1000 steps)\n")
    print(drift_table(results["drift"]), "\n")
    print("## Bad input\n")
    print(messages(bad_inputs(), ValueError), "\n")
    print("## Valid but extreme input, with `runtime_check=True`\n")
    print(messages(runtime_examples(), jaxrot.IntegrationError))


if __name__ == "__main__":
    main()
