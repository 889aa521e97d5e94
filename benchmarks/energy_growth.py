"""Energy and angular-momentum drift against the rotation per step |ω|Δt over long float64 runs, for
every vacuum scheme of jaxrot and every integrator of MuJoCo XLA (MJX), on the same bodies.

Accuracy only (no timing: any machine gives the same numbers to round-off). Issue 75: `zhao` gains
energy without bound at moderate steps, where the docs had measured it only at |ω|Δt = 0.023. Each
method runs each body for ``--steps`` steps (default 10⁵) at every rung of a log grid of |ω|Δt (|ω| the
initial rate), 10 rungs per decade from 10^-2.3 = 0.005 to 1 rad per step (24 rungs, each 1.26× the
last), all rungs of a body in one vmapped call (dt a traced value: one compilation per method and
torque, shared by the two free bodies). The bodies:

- ``tumbling``: I = (1, 2, 3) kg m² about the centre, q₀ = exp((0.1, 0.2, 0.3)), ω_b = (1, 2, 0.5)
  rad/s (|ω| = 2.29 rad/s); invariants: the energy and the world angular momentum L (a vector);
- ``dzhanibekov``: the ``free_top`` scene, the same body spun about its intermediate axis
  (ω_b = (0.01, 2, 0.01) rad/s): it flips every ~6 s; the same invariants;
- ``heavy_top``: the ``heavy_top`` scene, (1.25, 2, 3) kg m² about the pivot, 1 kg at (0.1, 0.05, 0.3) m,
  weight (0, 0, −9.81) N (|ω| = 6.09 rad/s); invariants: the energy (kinetic plus potential) and the
  angular momentum about the vertical L_z (the weight's direction), its change relative to |L₀|.

Every step's state is saved (``--save-every 1``), so a maximum is over every step of the run. Per
method, body and rung: the largest |ΔE/E₀| over the first 10⁴ steps and over the run, the signed
ΔE/E₀ at the end (+ a gain), the largest relative change of the conserved momentum, and the first
non-finite step where the run turns inf or NaN (then its figures are null). Per method and body, for
the energy and for the momentum, the **1 % step**: the largest rung at which that rung and every
smaller one stay within 1 % over the whole run and are finite (the true limit lies between it and
the next rung, 1.26× larger); null where the smallest rung already fails. A rung above it that passes
again (a lucky step: a resonance, a blow-up that happens to miss) is listed, not counted.

MJX (``pip install -e ".[mjx]"``; without it the MJX rows are left out and the file says so): Euler,
RK4 and implicitfast on MuJoCo models of the same bodies, built as `benchmarks/mjx_peer.py` builds them
(one body on a ball joint; the heavy top's central inertia at its centre of mass, the joint at the
pivot, gravity (0, 0, −9.81)); qpos is the orientation, qvel the body-frame rates, so the state is
``RotState.from_body(qpos / |qpos|, qvel)`` and the invariants are jaxrot's, computed the same way.

    python benchmarks/energy_growth.py --json docs/energy_growth.json      # the results file (~5 min)
    PYTHONPATH=. python benchmarks/energy_growth.py --json out.json        # from a git worktree
    python benchmarks/energy_growth.py --steps 10000 --methods zhao,mjx_rk4  # a check
"""

import argparse
import importlib.metadata
import importlib.util
import json
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

import jaxrot
from jaxrot import quaternion as quat
from jaxrot.comparison import machine_info
from jaxrot.diagnostics import angular_momentum


# |ω|Δt rungs (rad per step): 10 per decade, 10^-2.3 = 0.005 to 10^0 = 1.
GRID_EXPONENTS = tuple(k / 10 for k in range(-23, 1))
GRID = tuple(10.0**e for e in GRID_EXPONENTS)
# The rungs whose signed end drift the docs tabulate: 10^-1.5, 10^-1, 10^-0.5.
FIXED_RUNGS = (-1.5, -1.0, -0.5)
TOLERANCE = 0.01  # the "1 %": the largest |ΔE/E₀| (and momentum change) allowed over the run
EARLY_STEPS = 10_000
MJX_INTEGRATORS = ("euler", "rk4", "implicitfast")


def bodies():
    """``name -> scene`` (float64); the free bodies are torque-free, the top has its weight."""
    q0 = quat.exp(jnp.array([0.1, 0.2, 0.3]))
    free = jaxrot.SCENES["free_top"]()
    tumbling = free._replace(
        name="tumbling", state=jaxrot.RotState(q0, quat.rotate(q0, jnp.array([1.0, 2.0, 0.5])))
    )
    return {"tumbling": tumbling, "dzhanibekov": free, "heavy_top": jaxrot.SCENES["heavy_top"]()}


def summary(scene, t, q, omega, save_every):
    """The invariants' figures of one run from its saved states ``q`` ``(n, 4)``, ``omega`` ``(n, 3)``
    (world frame), index 0 the initial state: a dict of scalars (jnp; NaN where the run turned
    non-finite before its end, ``first_nonfinite`` the first such step, −1 if none)."""
    energy = scene.energy(t, q, omega)  # J, per saved state (the scene's energy of one body)
    change = (energy - energy[0]) / jnp.abs(energy[0])
    momentum = angular_momentum(q, omega, scene.inertia)  # (n, 3), world frame
    if scene.torque is not None:  # a top under its weight (world z) keeps only L_z
        drift = jnp.abs(momentum[:, 2] - momentum[0, 2])
    else:
        drift = jnp.linalg.norm(momentum - momentum[0], axis=-1)
    drift = drift / jnp.linalg.norm(momentum[0])
    finite = jnp.all(jnp.isfinite(q), axis=-1) & jnp.all(jnp.isfinite(omega), axis=-1)
    finite = finite & jnp.isfinite(change) & jnp.isfinite(drift)
    ok = jnp.all(finite)
    early = EARLY_STEPS // save_every + 1

    def largest(x):  # NaN unless every sample is finite (XLA's max may skip NaNs: not trusted here)
        return jnp.where(ok, jnp.max(jnp.where(finite[: len(x)], jnp.abs(x), 0.0)), jnp.nan)

    return {
        "energy_max": largest(change),
        "energy_max_1e4": largest(change[:early]),
        "energy_end": jnp.where(ok, change[-1], jnp.nan),
        "momentum_max": largest(drift),
        "first_nonfinite_step": jnp.where(ok, -1, jnp.argmin(finite) * save_every),
    }


def jaxrot_program(scheme, scene, n_steps, save_every):
    """A compiled ``(states (k,), dts (k,)) -> summary`` of ``scheme`` on ``scene``'s torque and inertia
    (the state and dt are arguments: one program serves every rung and both free bodies)."""

    def one(state, dt):
        traj = jaxrot.rollout(
            scheme, state, scene.inertia, dt, n_steps, torque=scene.torque, args=scene.args,
            save_every=save_every, check_finite=False,
        )  # fmt: skip
        return summary(scene, traj.t, traj.q, traj.omega, save_every)

    return jax.jit(jax.vmap(one))


def mjx_program(n_steps, save_every):
    """A compiled ``(mjx.Model, dts (k,), qpos (k, 4), qvel (k, 3), scene) -> saved (qpos, qvel)`` of
    MJX: each rung's model is the given one at its own timestep."""
    from mujoco import mjx

    def one(m, dt, qpos, qvel):
        m = m.replace(opt=m.opt.replace(timestep=dt))
        d = mjx.make_data(m).replace(qpos=qpos, qvel=qvel)

        def save(d, _):
            d = jax.lax.fori_loop(0, save_every, lambda i, d: mjx.step(m, d), d)
            return d, (d.qpos, d.qvel)

        _, (qs, ws) = jax.lax.scan(save, d, None, length=n_steps // save_every)
        return jnp.concatenate([qpos[None], qs]), jnp.concatenate([qvel[None], ws])

    return jax.jit(jax.vmap(one, in_axes=(None, 0, 0, 0)))


def mjx_models():
    """``(body -> xml builder (integrator, dt), mjx_peer.mjx_model)``: `mjx_peer`'s free body (I = (1, 2, 3)
    about the centre, the tumbling and Dzhanibekov bodies' inertia) and heavy top."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import mjx_peer

    built = mjx_peer.problems(1.0, 1.0)
    free, top = built["free_body"][0], built["heavy_top"][0]
    return {"tumbling": free, "dzhanibekov": free, "heavy_top": top}, mjx_peer.mjx_model


def state_of(qpos, qvel):
    """MuJoCo's ball-joint state as jaxrot's (q, world ω): qpos normalised, qvel the body-frame rates."""
    state = jaxrot.RotState.from_body(quat.normalize(qpos), qvel)
    return state.q, state.omega


def limit(passing):
    """The index of the largest rung at which it and every smaller rung pass, or None."""
    below = None
    for i, ok in enumerate(passing):
        if not ok:
            break
        below = i
    return below


def row(method, peer, name, scene, out):
    """One method on one body: its figures per rung and its 1 % steps."""
    omega = float(jnp.linalg.norm(scene.state.omega))
    out = {k: np.asarray(v) for k, v in out.items()}
    r = {
        "method": method,
        "peer": peer,
        "body": name,
        "omega0": omega,
        "dt": [g / omega for g in GRID],
        **{
            k: [None if not np.isfinite(x) else float(x) for x in out[k]]
            for k in out
            if k != "first_nonfinite_step"
        },
        "first_nonfinite_step": [None if s < 0 else int(s) for s in out["first_nonfinite_step"]],
    }
    for key in ("energy", "momentum"):
        passing = [x is not None and x <= TOLERANCE for x in r[f"{key}_max"]]
        i = limit(passing)
        r[f"{key}_limit"] = None if i is None else GRID[i]
        start = -1 if i is None else i
        r[f"{key}_lucky"] = [GRID[j] for j in range(start + 2, len(GRID)) if passing[j]]
    return r


def log_row(r):
    def rung(x):
        return "< 0.005" if x is None else f"{x:.3g}"

    nonfinite = [g for g, s in zip(GRID, r["first_nonfinite_step"], strict=True) if s is not None]
    print(
        f"{r['body']:12s} {r['method']:18s} 1 % step: energy {rung(r['energy_limit'])}, momentum "
        f"{rung(r['momentum_limit'])}"
        + (f"; lucky rungs {r['energy_lucky']}" if r["energy_lucky"] else "")
        + (f"; non-finite from |ω|Δt {nonfinite[0]:.3g}" if nonfinite else ""),
        flush=True,
    )


def measure_jaxrot(schemes, scenes, n_steps, save_every):
    rows = []
    for scheme in schemes:
        start = time.perf_counter()
        programs = {}
        for name, scene in scenes.items():
            kind = "free" if scene.torque is None else name
            program = programs.setdefault(kind, jaxrot_program(scheme, scene, n_steps, save_every))
            omega = float(jnp.linalg.norm(scene.state.omega))
            states = jax.tree.map(lambda x: jnp.broadcast_to(x, (len(GRID), *x.shape)), scene.state)
            rows.append(row(scheme, "jaxrot", name, scene, program(states, jnp.asarray(GRID) / omega)))
            log_row(rows[-1])
        print(f"  {scheme}: {time.perf_counter() - start:.0f} s", flush=True)
    return rows


def measure_mjx(integrators, scenes, n_steps, save_every):
    xmls, mjx_model = mjx_models()
    program = mjx_program(n_steps, save_every)
    times = jnp.zeros(n_steps // save_every + 1)  # the invariants here do not depend on time

    def summarize(scene):
        return jax.jit(jax.vmap(lambda q, w: summary(scene, times, *state_of(q, w), save_every)))

    summaries = {name: summarize(scene) for name, scene in scenes.items()}
    rows = []
    for integrator in integrators:
        start = time.perf_counter()
        for name, scene in scenes.items():
            m = mjx_model(xmls[name](integrator, 0.01))
            omega = float(jnp.linalg.norm(scene.state.omega))
            omega_body = quat.rotate(quat.conjugate(scene.state.q), scene.state.omega)
            qpos = jnp.broadcast_to(scene.state.q, (len(GRID), 4))
            qvel = jnp.broadcast_to(omega_body, (len(GRID), 3))
            qs, ws = program(m, jnp.asarray(GRID) / omega, qpos, qvel)
            rows.append(row(f"mjx_{integrator}", "mjx", name, scene, summaries[name](qs, ws)))
            log_row(rows[-1])
        print(f"  mjx_{integrator}: {time.perf_counter() - start:.0f} s", flush=True)
    return rows


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=100_000)
    parser.add_argument("--save-every", type=int, default=1)
    parser.add_argument(
        "--methods", default=None, help="jaxrot schemes and mjx_<integrator> (default: all of them)"
    )
    parser.add_argument("--json", help="write the results file here")
    opts = parser.parse_args(argv)
    jax.config.update("jax_enable_x64", True)  # here, not at import: the tests import this module
    methods = (
        opts.methods.split(",") if opts.methods else [*jaxrot.SCHEMES, *(f"mjx_{i}" for i in MJX_INTEGRATORS)]
    )
    schemes = [m for m in methods if not m.startswith("mjx_")]
    integrators = [m.removeprefix("mjx_") for m in methods if m.startswith("mjx_")]
    has_mjx = (
        importlib.util.find_spec("mujoco") is not None and importlib.util.find_spec("mujoco.mjx") is not None
    )
    info = machine_info()
    if has_mjx:
        import mujoco

        info |= {"mujoco": mujoco.__version__, "mujoco_mjx": importlib.metadata.version("mujoco-mjx")}
    elif integrators:
        print(
            'energy_growth: MJX is not installed (pip install -e ".[mjx]"): its rows are left out', flush=True
        )
    print(", ".join(f"{k} {v}" for k, v in info.items()), flush=True)
    scenes = bodies()
    start = time.perf_counter()
    rows = measure_jaxrot(schemes, scenes, opts.steps, opts.save_every)
    if has_mjx and integrators:
        rows += measure_mjx(integrators, scenes, opts.steps, opts.save_every)
    print(f"energy_growth: {time.perf_counter() - start:.0f} s", flush=True)
    settings = {
        "steps": opts.steps,
        "save_every": opts.save_every,
        "grid": list(GRID),
        "grid_exponents": list(GRID_EXPONENTS),
        "fixed_rungs": [10.0**e for e in FIXED_RUNGS],
        "tolerance": TOLERANCE,
        "early_steps": EARLY_STEPS,
        "mjx": "measured" if has_mjx and integrators else ("not installed" if integrators else "not asked"),
        "bodies": {
            name: {"omega0": float(jnp.linalg.norm(s.state.omega)), "inertia": [float(x) for x in s.inertia]}
            for name, s in scenes.items()
        },
    }
    if opts.json:
        out = {"machine": info, "settings": settings, "rows": rows}
        Path(opts.json).write_text(json.dumps(out, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
