"""``python -m jaxrot compare`` on a scene at a temperature (`jaxrot.scenes.THERMAL_SCENES`): weak errors.

A thermal run has no reference trajectory: its accuracy is the bias of ensemble averages. For each
thermal scheme of the scene (`jaxrot.THERMAL_SCHEMES` with inertia, `jaxrot.BROWNIAN_SCHEMES`
without) and each step of a halving ladder, the scene's bodies (started from the exact equilibrium)
are run with ``jaxrot.rollout``/``jaxrot.overdamped_rollout`` and a key, and the averages over the
second half of the horizon are compared with their closed forms: the dipole's ``⟨cos θ⟩ = L(x)``
(the Langevin function of ``x = μB/kT``) and, with inertia, equipartition ``⟨I_k ω_k²⟩/kT = 1``.
Each row has the weak error, its statistical error (the standard error over bodies: below about
twice it the error is noise, not bias) and the cost (median wall time of the compiled run per body,
`jaxrot.comparison.time_compiled`); the plot draws error against cost, with the statistical floor.
"""

import json
import math
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from tqdm import tqdm

from .. import quaternion as quat
from .._core._compile import compiler_options
from .._fluid._equilibrium import langevin_function
from .._integrate._overdamped import overdamped_rollout
from .._integrate._rollout import rollout
from ..scenes import THERMAL_SCENES
from ..schemes import BROWNIAN_SCHEMES, THERMAL_SCHEMES
from . import _ladder as comparison
from ._report import write_csv


def _exact(scene):
    field = scene.args["field"]
    x = float(
        jnp.linalg.norm(field["moment_body"]) * jnp.linalg.norm(field["field"]) / jnp.max(scene.fluid.kT)
    )
    return {
        "<cos θ>": float(langevin_function(x)),
        **({"<I ω²>/kT": 1.0} if scene.inertia is not None else {}),
    }


def _runner(name, scene, dt, n_steps, samples, key):
    """``run(q, omega) -> (n, k)`` per-body averages over the sampling times of the second half."""
    direction = scene.args["field"]["field"] / jnp.linalg.norm(scene.args["field"]["field"])
    moment = scene.args["field"]["moment_body"] / jnp.linalg.norm(scene.args["field"]["moment_body"])
    kwargs = dict(
        torque=scene.torque, args=scene.args, fluid=scene.fluid, key=key, save_every=n_steps // samples
    )

    def run(q, omega):
        if scene.inertia is None:
            traj = overdamped_rollout(q, dt=dt, n_steps=n_steps, scheme=name, **kwargs)
        else:
            traj = rollout(name, jax.tree_util.tree_map(jnp.asarray, scene.state._replace(q=q, omega=omega)),
                           scene.inertia, dt, n_steps, **kwargs)  # fmt: skip
        later = slice(samples // 2 + 1, None)
        axis = quat.rotate(traj.q[later], jnp.broadcast_to(moment, traj.q[later].shape[:-1] + (3,)))
        seen = [jnp.sum(axis * direction, axis=-1)]
        if scene.inertia is not None:
            spin = quat.rotate(quat.conjugate(traj.q[later]), traj.omega[later])
            seen.append(jnp.sum(spin**2 * scene.inertia, axis=-1) / (3 * jnp.max(scene.fluid.kT)))
        return jnp.mean(jnp.stack(seen, axis=-1), axis=0)

    return run


def compare_thermal(scene="magnetic_nanoparticles", *, t_end=None, particles=4096, dtype="float64",
                    coarse_steps=4, levels=5, schemes=None, repeats=3, progress=True):  # fmt: skip
    """The rows of the weak-error comparison (see the module) of a scene of `THERMAL_SCENES`."""
    if dtype not in comparison.DTYPES:
        raise ValueError(f"`dtype` must be one of {sorted(comparison.DTYPES)}; got {dtype!r}.")
    run_scene = THERMAL_SCENES[scene](comparison.DTYPES[dtype], n=particles)
    known = THERMAL_SCHEMES if run_scene.inertia is not None else BROWNIAN_SCHEMES
    schemes = list(known) if schemes is None else list(schemes)
    unknown = [s for s in schemes if s not in known]
    if unknown:
        raise ValueError(f"`schemes` has unknown names {unknown} for scene {scene!r}; known: {list(known)}.")
    if coarse_steps < 2 or coarse_steps % 2:
        raise ValueError(f"`coarse_steps` must be even and >= 2 for a thermal scene; got {coarse_steps}.")
    t_end = run_scene.t_end if t_end is None else float(t_end)
    exact = _exact(run_scene)
    rows = []
    jobs = [(name, level) for name in schemes for level in range(levels)]
    for name, level in tqdm(jobs, desc="compare (weak)", disable=not progress, leave=False):
        factor = 2**level
        n_steps = coarse_steps * factor
        dt = t_end / n_steps
        run = _runner(name, run_scene, dt, n_steps, coarse_steps, jax.random.key(level))
        state = (run_scene.state.q, run_scene.state.omega)
        values, compile_s, seconds = comparison.time_compiled(lambda s, run=run: run(*s), state, repeats,
                                                              compiler_options())  # fmt: skip
        values = np.asarray(values, np.float64)
        scheme = known[name]
        evals = getattr(scheme, "torque_evals_per_step", None) or scheme.velocity_evals_per_step
        for k, (observable, target) in enumerate(exact.items()):
            mean = float(values[:, k].mean())
            rows.append(
                {
                    "scene": scene, "method": name, "kind": "fixed", "order": scheme.order, "dt": dt,
                    "n_steps": n_steps, "particles": particles, "dtype": dtype, "observable": observable,
                    "value": mean, "exact": target, "weak_error": abs(mean - target),
                    "stderr": float(values[:, k].std(ddof=1) / math.sqrt(particles)),
                    "torque_evals": evals * n_steps, "us_per_particle_run": seconds / particles * 1e6,
                    "compile_s": compile_s,
                }
            )  # fmt: skip
    return rows


def format_thermal_table(rows) -> str:
    header = (
        f"{'method':<20} {'observable':<11} {'dt':>10} {'steps':>6} {'value':>9} {'exact':>9} "
        f"{'weak error':>10} {'± stat':>8} {'µs/part.':>9} {'compile s':>9}"
    )
    lines = [header, "-" * len(header)]
    for r in rows:
        flag = "" if r["weak_error"] > 2 * r["stderr"] else "  (noise)"
        lines.append(
            f"{r['method']:<20} {r['observable']:<11} {r['dt']:>10.3g} {r['n_steps']:>6d} "
            f"{r['value']:>9.5f} {r['exact']:>9.5f} {r['weak_error']:>10.2e} {r['stderr']:>8.1e} "
            f"{r['us_per_particle_run']:>9.3g} {r['compile_s']:>9.2f}{flag}"
        )
    return "\n".join(lines)


def plot_weak_errors(rows, path):
    """Weak error against wall time per particle, one panel per observable, the statistical floor dashed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    observables = list(dict.fromkeys(r["observable"] for r in rows))
    fig, axes = plt.subplots(1, len(observables), figsize=(5.5 * len(observables), 4.2), squeeze=False)
    for ax, observable in zip(axes[0], observables, strict=True):
        chosen = [r for r in rows if r["observable"] == observable]
        for method in dict.fromkeys(r["method"] for r in chosen):
            ladder = [r for r in chosen if r["method"] == method]
            cost = [r["us_per_particle_run"] for r in ladder]
            ax.loglog(cost, [max(r["weak_error"], 1e-12) for r in ladder], "o-", label=method)
        floor = 2 * max(r["stderr"] for r in chosen)
        ax.axhline(floor, color="grey", ls="--", lw=1, label="2σ statistical floor")
        ax.set_xlabel("wall time per particle [µs]")
        ax.set_ylabel(f"|{observable} − exact|")
        ax.set_title(f"{chosen[0]['scene']}: {observable}")
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return Path(path)


def write_thermal_outputs(rows, out_dir, plot=True) -> list[Path]:
    """``compare.csv``, ``compare.json`` (with the machine) and ``compare.png`` under ``out_dir``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = [write_csv(rows, out / "compare.csv"), out / "compare.json"]
    written[1].write_text(json.dumps({"machine": comparison.machine_info(), "rows": rows}, indent=1) + "\n")
    if plot:
        written.append(plot_weak_errors(rows, out / "compare.png"))
    return written


def main_thermal(ns, parser) -> int:
    """``python -m jaxrot compare --scene NAME`` for a thermal scene (its parsed arguments ``ns``)."""
    import time

    start = time.perf_counter()
    particles = 4096 if ns.particles is None else ns.particles
    schemes = None if ns.schemes is None else ns.schemes.split(",")
    coarse_steps = ns.coarse_steps + ns.coarse_steps % 2  # even: the second half starts on a step
    try:
        rows = compare_thermal(
            ns.scene, t_end=ns.t_end, particles=particles, dtype=ns.dtype, coarse_steps=coarse_steps,
            levels=min(ns.levels, 6), repeats=ns.repeats, schemes=schemes,
        )  # fmt: skip
    except ValueError as err:
        parser.error(str(err))
    print(
        f"jaxrot compare — scene {ns.scene}; {ns.dtype}; {particles} bodies; weak errors of ensemble "
        "averages against their closed forms (second half of the horizon, from the exact equilibrium)"
    )
    written = write_thermal_outputs(rows, ns.out, plot=not ns.no_plot)
    print(format_thermal_table(rows))
    for path in written:
        print(f"wrote {path}")
    print(f"total {time.perf_counter() - start:.1f} s")
    return 0
