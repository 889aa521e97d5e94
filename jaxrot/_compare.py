"""The speed/accuracy comparison behind ``python -m jaxrot compare``."""

import csv
import json
import os
import platform
import statistics
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from tqdm.auto import tqdm

from . import quaternion as quat
from ._reference import reference_rollout
from ._rollout import rollout
from ._scenes import SCENES
from .schemes import SCHEMES


REFERENCE_TOL = 1e-13


def orientation_error(q, q_ref):
    """Largest geodesic angle (radians) between two orientation histories ``(n, ..., 4)``."""
    return float(jnp.max(quat.angle_between(q, q_ref)))


def fit_order(dts, errors) -> float:
    """Slope of log(error) against log(dt): the measured order of accuracy."""
    slope, _ = np.polyfit(np.log(np.asarray(dts)), np.log(np.asarray(errors)), 1)
    return float(slope)


def _time_per_step(run, state, n_steps, repeats):
    """Median wall time (s) per step of a compiled rollout, and its compile time (s)."""
    start = time.perf_counter()
    jax.block_until_ready(run(state))
    compile_s = time.perf_counter() - start
    samples = []
    for _ in range(repeats):
        start = time.perf_counter()
        jax.block_until_ready(run(state))
        samples.append(time.perf_counter() - start)
    return statistics.median(samples) / max(n_steps, 1), compile_s


def compare(scene="heavy_top", *, t_end=None, coarse_steps=100, levels=6, repeats=5, progress=True):
    """Run every scheme at a ladder of time steps against the diffrax reference.

    The ladder halves ``dt`` from ``t_end / coarse_steps`` ``levels`` times; each
    run is compared with the reference (Dopri8, rtol = atol = 1e-13) at the
    coarse grid's times, which every rung of the ladder visits.

    Returns a list of rows (dicts), one per scheme and ``dt``.
    """
    if scene not in SCENES:
        raise ValueError(f"`scene` must be one of {sorted(SCENES)}; got {scene!r}.")
    if not jax.config.jax_enable_x64:
        raise ValueError(
            'compare needs float64 for its reference: call jax.config.update("jax_enable_x64", True) first.'
        )
    sc = SCENES[scene]()
    t_end = sc.t_end if t_end is None else float(t_end)
    if not t_end > 0:
        raise ValueError(f"`t_end` must be > 0; got {t_end}.")
    dt_coarse = t_end / coarse_steps
    ts = jnp.arange(coarse_steps + 1, dtype=jnp.float64) * dt_coarse
    ref = reference_rollout(
        sc.state, sc.inertia, ts, torque=sc.torque, args=sc.args, rtol=REFERENCE_TOL, atol=REFERENCE_TOL
    )

    rows = []
    jobs = [(name, k) for name in SCHEMES for k in range(levels)]
    for name, k in tqdm(jobs, desc="compare", disable=not progress, leave=False):
        scheme = SCHEMES[name]
        factor = 2**k
        dt = dt_coarse / factor
        n_steps = coarse_steps * factor

        def run(state, scheme=scheme, dt=dt, n_steps=n_steps, factor=factor):
            return rollout(
                scheme, state, sc.inertia, dt, n_steps, torque=sc.torque, args=sc.args, save_every=factor
            )

        run = jax.jit(run)
        traj = run(sc.state)
        seconds_per_step, compile_s = _time_per_step(run, sc.state, n_steps, repeats)
        rows.append(
            {
                "scene": scene,
                "scheme": name,
                "order": scheme.order,
                "dt": dt,
                "n_steps": n_steps,
                "max_orientation_error_rad": orientation_error(traj.q, ref.q),
                "final_omega_error": float(jnp.linalg.norm(traj.omega[-1] - ref.omega[-1])),
                "torque_evals": scheme.torque_evals_per_step * n_steps + scheme.torque_evals_at_init,
                "us_per_step": seconds_per_step * 1e6,
                "compile_s": compile_s,
            }
        )
    return rows


ASYMPTOTIC_ERROR = 0.1  # rad; above this the error saturates and says nothing about the order


def measured_orders(rows) -> dict:
    """Per scheme, the fitted order over the rungs with error below `ASYMPTOTIC_ERROR` (None if < 3)."""
    orders = {}
    for name in dict.fromkeys(r["scheme"] for r in rows):
        mine = [r for r in rows if r["scheme"] == name and r["max_orientation_error_rad"] < ASYMPTOTIC_ERROR]
        errors = [r["max_orientation_error_rad"] for r in mine]
        orders[name] = fit_order([r["dt"] for r in mine], errors) if len(mine) >= 3 else None
    return orders


def format_table(rows) -> str:
    header = (
        f"{'scheme':<10} {'dt':>10} {'steps':>7} {'max q err [rad]':>16} {'|Δω| final':>11} {'µs/step':>9}"
    )
    lines = [header, "-" * len(header)]
    for r in rows:
        lines.append(
            f"{r['scheme']:<10} {r['dt']:>10.3e} {r['n_steps']:>7d} {r['max_orientation_error_rad']:>16.3e} "
            f"{r['final_omega_error']:>11.3e} {r['us_per_step']:>9.3f}"
        )
    for name, order in measured_orders(rows).items():
        fitted = "n/a: fewer than 3 rungs below 0.1 rad" if order is None else f"{order:.3f}"
        lines.append(f"measured order ({name}): {fitted} (nominal {SCHEMES[name].order})")
    return "\n".join(lines)


def machine_info() -> dict:
    return {
        "machine": platform.machine(),
        "processor": platform.processor() or platform.machine(),
        "cpus": os.cpu_count(),
        "python": platform.python_version(),
        "jax": jax.__version__,
        "backend": jax.default_backend(),
    }


def write_outputs(rows, out_dir, plot=True) -> list[Path]:
    """Write ``compare.csv``, ``compare.json`` and (optionally) ``compare.png`` to ``out_dir``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = [out / "compare.csv", out / "compare.json"]
    with open(written[0], "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    with open(written[1], "w") as f:
        json.dump({"machine": machine_info(), "orders": measured_orders(rows), "rows": rows}, f, indent=2)
    if plot:
        written.append(_plot(rows, out / "compare.png"))
    return written


def _plot(rows, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax_dt, ax_cost) = plt.subplots(1, 2, figsize=(10, 4), constrained_layout=True)
    for name in dict.fromkeys(r["scheme"] for r in rows):
        mine = [r for r in rows if r["scheme"] == name]
        err = [r["max_orientation_error_rad"] for r in mine]
        ax_dt.loglog([r["dt"] for r in mine], err, "o-", label=name)
        ax_cost.loglog([r["us_per_step"] * r["n_steps"] / 1e6 for r in mine], err, "o-", label=name)
    ax_dt.set(xlabel="dt", ylabel="max orientation error [rad]", title=f"error vs dt ({rows[0]['scene']})")
    ax_cost.set(
        xlabel="wall time of the run [s]", ylabel="max orientation error [rad]", title="work-precision"
    )
    for ax in (ax_dt, ax_cost):
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
