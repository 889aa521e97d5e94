"""Memory of a gradient through N Zhao steps with and without checkpointing, and the wall time of a fit.

Run: ``python benchmarks/fit_memory.py`` (float64, CPU). Prints markdown tables:

1. XLA's temporary buffer size (``compiled.memory_analysis().temp_size_in_bytes``)
   of ``jax.grad`` of the `fit_inertia` objective through ``N`` steps of the heavy
   top, for ``N`` = 10³, 10⁴, 10⁵, with ``checkpoint=True`` (outer scan over
   ``jax.checkpoint``-ed chunks of ``⌈√N⌉`` steps) and ``checkpoint=False`` (one
   scan, every step's residuals stored). Nothing is executed for this table.
2. The wall time of ``fit_inertia`` on 200 noisy reference observations
   (first call, with compilation, and a second call), the iterations and the
   recovery errors; plus Adam alone on the same problem for comparison.
"""

import argparse
import os
import platform
import time

import jax


jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np

import jaxrot
from jaxrot import quaternion as quat
from jaxrot._fit._fit_inertia import _model, _residuals


MOMENTS = jnp.array([2.0, 3.0, 4.0])
R = quat.to_matrix(quat.exp(jnp.array([0.4, -0.7, 0.25])))
TENSOR = R @ jnp.diag(MOMENTS) @ R.T
STATE = jaxrot.RotState(quat.exp(jnp.array([0.1, 0.2, 0.3])), jnp.array([0.8, -0.5, 1.5]))
ARGS = {"offset": jnp.array([0.1, 0.05, 0.3]), "weight": jnp.array([0.0, 0.0, -9.81])}


def gravity(t, q, omega, args):
    return jnp.cross(quat.rotate(q, args["offset"]), args["weight"])


def gradient_memory(n_steps, checkpoint, n_obs=101):
    substeps = n_steps // (n_obs - 1)
    obs = jaxrot.rollout(
        "zhao", STATE, TENSOR, 0.001, n_steps, torque=gravity, args=ARGS, save_every=substeps
    )
    problem, _ = _model.build_model(
        obs, torque=gravity, args=ARGS, segments=1, unit_trace=False, substeps=substeps, checkpoint=checkpoint
    )

    def loss(inertia, q0, omega0):
        return _residuals.single_shooting_loss(problem, inertia, q0, omega0)

    start = time.perf_counter()
    compiled = jax.jit(jax.grad(loss, argnums=(0, 1, 2))).lower(TENSOR, STATE.q, STATE.omega).compile()
    compile_s = time.perf_counter() - start
    analysis = compiled.memory_analysis()
    start = time.perf_counter()
    jax.block_until_ready(compiled(TENSOR, STATE.q, STATE.omega))
    run_s = time.perf_counter() - start
    return analysis.temp_size_in_bytes, compile_s, run_s, (problem.n_outer, problem.n_inner)


def fit_timing(noise=1e-3, n=200, t_end=10.0, adam=(300, 1e-2)):
    ts = jnp.linspace(0.0, t_end, n)
    ref = jaxrot.reference_rollout(STATE, TENSOR, ts, torque=gravity, args=ARGS)
    q = quat.multiply(quat.exp(noise * jax.random.normal(jax.random.PRNGKey(0), (n, 3))), ref.q)
    obs = jaxrot.Trajectory(ts, q, None)
    rows = []
    for label in ("first call (compiles)", "second call"):
        start = time.perf_counter()
        fit = jaxrot.fit_inertia(obs, torque=gravity, args=ARGS)
        rows.append((label, time.perf_counter() - start, fit))
    steps, rate = adam
    start = time.perf_counter()
    # Adam alone: the same start and objective, `max_iter=0` skips L-BFGS.
    adam_fit = jaxrot.fit_inertia(
        obs, torque=gravity, args=ARGS, adam_steps=steps, adam_learning_rate=rate, max_iter=0
    )
    rows.append((f"Adam only, {steps} steps, lr {rate:g}", time.perf_counter() - start, adam_fit))
    true_axes = jnp.linalg.eigh(TENSOR)[1]
    out = []
    for label, wall, fit in rows:
        rel = float(jnp.linalg.norm(fit.inertia - TENSOR) / jnp.linalg.norm(TENSOR))
        cos = np.clip(np.abs(np.sum(np.asarray(fit.axes * true_axes), axis=0)), 0, 1)
        out.append(
            (label, wall, fit.n_iterations, float(fit.loss), rel, float(np.degrees(np.arccos(cos)).max()))
        )
    return out, ref.q.shape[0]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--max-steps", type=int, default=100_000)
    parser.add_argument("--skip-fit", action="store_true")
    opts = parser.parse_args()
    print(
        f"machine: {platform.machine()} {platform.processor() or ''} · {os.cpu_count()} CPUs · "
        f"Python {platform.python_version()} · jax {jax.__version__} · backend {jax.default_backend()}"
    )
    print()
    print("| steps N | checkpoint | chunks (outer × inner) | gradient temp memory | compile s | run s |")
    print("|---:|---|---|---:|---:|---:|")
    n = 1000
    while n <= opts.max_steps:
        for checkpoint in (True, False):
            temp, compile_s, run_s, chunks = gradient_memory(n, checkpoint)
            shape = f"{chunks[0]} × {chunks[1]}" if checkpoint else "—"
            print(
                f"| {n} | {checkpoint} | {shape} | {temp / 2**20:.2f} MiB | {compile_s:.1f} | {run_s:.2f} |"
            )
        n *= 10
    if opts.skip_fit:
        return
    rows, n_obs = fit_timing()
    print()
    print(f"fit_inertia, heavy top, {n_obs} observations, 1e-3 rad noise, moments (2, 3, 4) rotated:")
    print()
    print("| run | wall s | iterations | final loss | tensor rel. Frobenius error | worst axis error (deg) |")
    print("|---|---:|---:|---:|---:|---:|")
    for label, wall, iters, loss, rel, axis in rows:
        print(f"| {label} | {wall:.1f} | {iters} | {loss:.4g} | {rel:.2e} | {axis:.3f} |")


if __name__ == "__main__":
    main()
