"""Bodies at a temperature against the peers a user would pick: docs/thermal_peers.json.

One run, one process, the same physics for every method: N bodies with inertia (1, 2, 3), an isotropic
rotational friction ζ = 2 (torque per angular velocity) and kT = 1, float64.

- jaxrot: ``rollout("baoab" | "exp_euler", ..., fluid=Fluid(ζ, kT=1), key=...)``.
- jax_md: ``simulate.nvt_langevin`` on ``rigid_body.RigidBody`` (BAOAB with NO_SQUISH's rotor and
  Davidchack, Ouldridge & Tretyakov's exact O step), the same kT and dt, its friction
  ``gamma.orientation = ζ Σ_k 1/I_k`` (jax_md damps body axis ``l`` at the rate ``G M / (4 I_l)``,
  ``M = 4 / Σ_k 1/I_k``: that is ``ζ / I_l``), centres at zero force (jax_md integrates them too:
  part of its cost). Skipped, with a message, where jax_md is not installed (it excludes jax 0.10.2:
  ``pip install -e ".[peers]"`` under Python 3.12).
- diffrax: the Langevin SDE written as a user would, on the Euclidean state ``(q, ω_b)``:
  ``q̇ = ½ q ⊗ (0, ω_b)``, ``I ω̇_b = τ_b − ω_b × I ω_b − ζ ω_b + √(2 kT ζ) dW/dt``, solved by
  ``EulerHeun`` with a ``VirtualBrownianTree`` per body, ``ConstantStepSize``, vmapped over bodies.

Measured against dt (0.5, 0.25, 0.125, 0.0625), each method with its own noise:

- temperature bias: ``⟨I_k ω_k²⟩/kT − 1`` (mean of the three axes) and the dipole's configurational
  bias ``⟨cos θ⟩ − L(2)`` for a dipole along body z in a field at ``μB/kT = 2``, bodies started from the
  exact Boltzmann law, averaged over the 8 sampling times of the second half of t ∈ [0, 8];
- orientation-correlation bias: ``⟨e_i(1)·e_i(0)⟩`` of free bodies started at the identity (mean
  over the three body axes), against jaxrot's ``baoab`` at dt = 1/128 with 8× the bodies (the
  underdamped correlation has no closed form);
- for diffrax, the largest ``| |q| − 1 |`` seen (nothing keeps its quaternion on the unit sphere);
- for jax_md, torque-free at dt = 1/32: its rotational temperature per axis and how far its conjugate
  momentum leaves the quaternion's tangent space, as shipped and with its O step's noise drawn with
  the exact covariance (`jax_md_diagnosis`);
- with ``--timing``: cost per body-step (median wall time of the compiled run over bodies × steps,
  N = 10⁴, the dipole scene).

Statistical errors are the standard errors over independent bodies. Timings must come from a quiet
machine: on a shared one, run without ``--timing`` (the file then has no timing columns).

    python benchmarks/thermal_peers.py --timing      # the published file (Python 3.12 with jax_md)
    python benchmarks/thermal_peers.py               # biases only
    python benchmarks/thermal_peers.py --quick       # tiny sizes, to stdout, nothing written
"""

import argparse
import importlib.metadata
import json
import math
import sys
import time
from pathlib import Path

import jax


jax.config.update("jax_enable_x64", True)

import diffrax
import jax.numpy as jnp
import numpy as np

import jaxrot
from jaxrot import quaternion as quat
from jaxrot._fluid._equilibrium import dipole_orientations, langevin_function, maxwell_spins
from jaxrot.comparison import machine_info, time_compiled


ROOT = Path(__file__).resolve().parents[1]
INERTIA = jnp.array([1.0, 2.0, 3.0])
FRICTION = 2.0
KT = 1.0
X = 2.0  # μB/kT of the dipole
EZ = jnp.array([0.0, 0.0, 1.0])
T_DIPOLE, T_FREE = 8.0, 1.0
SAMPLES = 16  # sampling times over a run; the second half is averaged
DTS = (0.5, 0.25, 0.125, 0.0625)


def have_jax_md():
    try:
        import jax_md  # noqa: F401
    except ImportError:
        return False
    return True


def start(n, dipole):
    """``(q, ω_b)`` ``(n, 4)``, ``(n, 3)``: the dipole's Boltzmann law, or the identity, and Maxwell spins."""
    k1, k2 = jax.random.split(jax.random.key(1))
    q = dipole_orientations(k1, n, X) if dipole else jnp.tile(jnp.array([1.0, 0.0, 0.0, 0.0]), (n, 1))
    omega = maxwell_spins(k2, q, INERTIA, KT)
    return q, quat.rotate(quat.conjugate(q), omega)


def observables(q, omega_body):
    """``(n, 7)``: cos θ, I_k ω_k²/kT (3), e_i·e_i(0) for i = 1..3 (from the identity)."""
    cos_theta = quat.rotate(q, EZ)[..., 2:3]
    energy = omega_body**2 * INERTIA.reshape((1,) * (omega_body.ndim - 1) + (3,)) / KT
    axes = jnp.diagonal(quat.to_matrix(q), axis1=-2, axis2=-1)
    return jnp.concatenate([cos_theta, energy, axes], axis=-1)


def field_args(dipole):
    strength = X * KT if dipole else 0.0
    return {"field": {"moment_body": EZ, "field": jnp.array([0.0, 0.0, strength])}}


# --- the three methods: run(q, omega_body, key) -> observables (SAMPLES, n, 7) at the sampling times ---


def _samples(dipole):
    """Sampling times of a run: ``SAMPLES`` for the dipole's averages, the final state for free bodies."""
    return SAMPLES if dipole else 1


def jaxrot_method(name, dt, t_end, dipole):
    n_steps = round(t_end / dt)
    fluid = jaxrot.Fluid(jnp.full(3, FRICTION), kT=KT)

    def run(q, omega_body, key):
        state = jaxrot.RotState(q, quat.rotate(q, omega_body))
        traj = jaxrot.rollout(
            name, state, INERTIA, dt, n_steps, torque=jaxrot.torques.UniformField(), args=field_args(dipole),
            fluid=fluid, key=key, save_every=n_steps // _samples(dipole),
        )  # fmt: skip
        return observables(traj.q[1:], quat.rotate(quat.conjugate(traj.q[1:]), traj.omega[1:]))

    return run


def jax_md_method(dt, t_end, dipole):
    from jax_md import rigid_body, simulate, space

    n_steps = round(t_end / dt)
    field = field_args(dipole)["field"]

    def energy(body, **kwargs):
        moment = rigid_body.quaternion_rotate(body.orientation, jnp.broadcast_to(EZ, body.center.shape))
        return -jnp.sum(moment @ field["field"])

    _, shift = space.free()
    gamma = rigid_body.RigidBody(jnp.asarray(0.1), jnp.asarray(FRICTION * float(jnp.sum(1 / INERTIA))))
    init_fn, step_fn = simulate.nvt_langevin(energy, shift, dt, KT, gamma=gamma)

    def run(q, omega_body, key):
        n, dtype = q.shape[0], q.dtype
        position = rigid_body.RigidBody(jnp.zeros((n, 3), dtype), rigid_body.Quaternion(q))
        mass = rigid_body.RigidBody(jnp.ones((n,), dtype), jnp.broadcast_to(INERTIA, (n, 3)))
        momenta = rigid_body.RigidBody(
            jnp.zeros((n, 3), dtype),
            rigid_body.angular_momentum_to_conjugate_momentum(position.orientation, INERTIA * omega_body),
        )
        md = init_fn(jax.random.key_data(key), position, mass=mass, momenta=momenta)

        def sample(md, _):
            md = jax.lax.fori_loop(0, n_steps // _samples(dipole), lambda i, s: step_fn(s), md)
            q = md.position.orientation.vec
            angular = rigid_body.conjugate_momentum_to_angular_momentum(
                md.position.orientation, md.momentum.orientation
            )
            return md, observables(q, angular / INERTIA)

        _, seen = jax.lax.scan(sample, md, None, length=_samples(dipole))
        return seen

    return run


def diffrax_method(dt, t_end, dipole):
    n_steps = round(t_end / dt)
    field = field_args(dipole)["field"]["field"]
    ts = jnp.arange(1, _samples(dipole) + 1) * (t_end / _samples(dipole))

    def drift(t, y, args):
        q, w = y[:4], y[4:]
        q_dot = 0.5 * quat.multiply(q, jnp.concatenate([jnp.zeros(1), w]))
        torque_body = jnp.cross(EZ, quat.rotate(quat.conjugate(q), field))  # μ_b × R⁻¹B (μ = 1)
        w_dot = (torque_body - jnp.cross(w, INERTIA * w) - FRICTION * w) / INERTIA
        return jnp.concatenate([q_dot, w_dot])

    noise = jnp.concatenate([jnp.zeros((4, 3)), jnp.diag(jnp.sqrt(2 * KT * FRICTION) / INERTIA)])

    def one(y0, key):
        brownian = diffrax.VirtualBrownianTree(0.0, t_end, tol=dt / 2, shape=(3,), key=key)
        terms = diffrax.MultiTerm(
            diffrax.ODETerm(drift), diffrax.ControlTerm(lambda t, y, a: noise, brownian)
        )
        solution = diffrax.diffeqsolve(
            terms, diffrax.EulerHeun(), 0.0, t_end, dt, y0, saveat=diffrax.SaveAt(ts=ts),
            stepsize_controller=diffrax.ConstantStepSize(), max_steps=n_steps + 1,
        )  # fmt: skip
        return solution.ys

    def run(q, omega_body, key):
        ys = jax.vmap(one)(jnp.concatenate([q, omega_body], axis=-1), jax.random.split(key, q.shape[0]))
        ys = jnp.swapaxes(ys, 0, 1)
        norm_drift = jnp.max(jnp.abs(jnp.linalg.norm(ys[..., :4], axis=-1) - 1))
        return observables(ys[..., :4], ys[..., 4:]), norm_drift

    return run


def methods(peer):
    found = {"jaxrot baoab": lambda dt, t, d: jaxrot_method("baoab", dt, t, d),
             "jaxrot exp_euler": lambda dt, t, d: jaxrot_method("exp_euler", dt, t, d)}  # fmt: skip
    if peer:
        found["jax_md nvt_langevin"] = jax_md_method
    found["diffrax EulerHeun"] = diffrax_method
    return found


def _stats(values):
    """Mean and standard error over bodies of a per-body average ``(n,)``."""
    values = np.asarray(values, np.float64)
    return float(values.mean()), float(values.std(ddof=1) / math.sqrt(len(values)))


def measure_biases(n, peer, dts=DTS):
    rows = []
    q_free, w_free = start(8 * n, dipole=False)
    reference = jaxrot_method("baoab", 1 / 128, T_FREE, False)(q_free, w_free, jax.random.key(99))[-1, :, 4:]
    ref_mean, ref_err = _stats(jnp.mean(reference, axis=-1))
    q_dip, w_dip = start(n, dipole=True)
    q_free, w_free = q_free[:n], w_free[:n]
    for name, make in methods(peer).items():
        for dt in dts:
            t0 = time.perf_counter()
            out = make(dt, T_DIPOLE, True)(q_dip, w_dip, jax.random.key(3))
            drift = None
            if isinstance(out, tuple):
                out, drift = out
            later = out[SAMPLES // 2 :].mean(axis=0)  # per body, second half
            cos_mean, cos_err = _stats(later[:, 0])
            temp_mean, temp_err = _stats(jnp.mean(later[:, 1:4], axis=-1))
            free = make(dt, T_FREE, False)(q_free, w_free, jax.random.key(4))
            if isinstance(free, tuple):
                free, free_drift = free
                drift = max(float(drift), float(free_drift))
            corr_mean, corr_err = _stats(jnp.mean(free[-1, :, 4:], axis=-1))
            row = {
                "method": name,
                "dt": dt,
                "bodies": n,
                "temperature_bias": temp_mean - 1.0,
                "temperature_bias_stderr": temp_err,
                "cos_theta_bias": cos_mean - float(langevin_function(X)),
                "cos_theta_bias_stderr": cos_err,
                "correlation_bias": corr_mean - ref_mean,
                "correlation_bias_stderr": math.hypot(corr_err, ref_err),
                "max_norm_drift": None if drift is None else float(drift),
            }
            rows.append(row)
            text = (
                f"{name:<20} dt={dt:<7} T-bias {row['temperature_bias']:+.2e}±{temp_err:.0e}  "
                f"cos-bias {row['cos_theta_bias']:+.2e}±{cos_err:.0e}  "
                f"corr-bias {row['correlation_bias']:+.2e}±{row['correlation_bias_stderr']:.0e}  "
                f"|q|-1 {row['max_norm_drift']}  {time.perf_counter() - t0:.0f} s"
            )
            print(text, file=sys.stderr, flush=True)
    return rows, {"correlation_reference": ref_mean, "correlation_reference_stderr": ref_err}


def jax_md_diagnosis(n=4096, dt=1 / 32, steps=512):
    """jax_md's rotational temperature per axis, torque-free, at a small dt, and ``⟨(P·q)²⟩`` of its
    conjugate momentum (0 on the tangent space), as shipped and with its O step's noise drawn with the
    exact covariance ``Σ_l s_l² P_l(q) P_l(q)ᵀ`` (``Σ_l s_l P_l(q) ξ_l``) instead of component by
    component with the variances ``Σ_l s_l² P_l(q)²``; everything else as jax_md's."""
    from jax_md import rigid_body, simulate, space
    from jax_md.rigid_body import MOMENTUM_PERMUTATION as perm

    shipped = simulate.stochastic_step._registry[rigid_body.RigidBody]

    def corrected(state, dt, kT, gamma):
        key, center_key, orientation_key = jax.random.split(state.rng, 3)
        rest, center, orientation = rigid_body.split_center_and_orientation(state)
        center = simulate.stochastic_step(center.set(rng=center_key), dt, kT, gamma.center)
        momentum, inertia, g = orientation.momentum.vec, orientation.mass, gamma.orientation
        m = 4 / jnp.sum(1 / inertia, axis=-1)
        q = orientation.position.vec
        xi = jax.random.normal(orientation_key, (q.shape[0], 3), q.dtype)
        new = 0
        for axis in range(3):
            p = perm[axis](q)
            decay = jnp.exp(-g * m * dt / (4 * inertia[:, axis]))
            scale = jnp.sqrt(4 * kT * inertia[:, axis] * (1 - jnp.exp(-m * g * dt / (2 * inertia[:, axis]))))
            new = new + (decay * jnp.sum(p * momentum, axis=-1) + scale * xi[:, axis])[:, None] * p
        orientation = orientation.set(momentum=rigid_body.Quaternion(new))
        return rigid_body.merge_center_and_orientation(rest.set(rng=key), center, orientation)

    result = {"dt": dt, "steps": steps, "bodies": n}
    for label, step in (("shipped", shipped), ("exact_covariance", corrected)):
        simulate.stochastic_step.register(rigid_body.RigidBody)(step)
        _, shift = space.free()
        gamma = rigid_body.RigidBody(jnp.asarray(0.1), jnp.asarray(FRICTION * float(jnp.sum(1 / INERTIA))))
        init_fn, step_fn = simulate.nvt_langevin(lambda body, **kw: 0.0 * jnp.sum(body.center), shift, dt, KT,
                                                 gamma=gamma)  # fmt: skip
        q0 = jnp.tile(jnp.array([1.0, 0.0, 0.0, 0.0]), (n, 1))
        position = rigid_body.RigidBody(jnp.zeros((n, 3)), rigid_body.Quaternion(q0))
        mass = rigid_body.RigidBody(jnp.ones((n,)), jnp.broadcast_to(INERTIA, (n, 3)))
        md = init_fn(jax.random.key_data(jax.random.key(7)), position, mass=mass)
        advance = jax.jit(lambda s, step_fn=step_fn: jax.lax.fori_loop(0, steps, lambda i, x: step_fn(x), s))
        md = advance(md)
        orientation, momentum = md.position.orientation, md.momentum.orientation
        angular = rigid_body.conjugate_momentum_to_angular_momentum(orientation, momentum)
        result[label] = {
            "kinetic_per_axis_over_kT": (jnp.mean(angular**2, axis=0) / INERTIA / KT).tolist(),
            "p_dot_q_squared": float(jnp.mean(jnp.sum(momentum.vec * orientation.vec, axis=-1) ** 2)),
        }
    simulate.stochastic_step.register(rigid_body.RigidBody)(shipped)
    print(f"jax_md diagnosis: {result}", file=sys.stderr, flush=True)
    return result


def measure_cost(n, peer, n_steps=256, repeats=3):
    """Seconds per body-step of each method on the dipole scene, dt = 0.0625 (compiled, median)."""
    rows = []
    q, w = start(n, dipole=True)
    for name, make in methods(peer).items():
        run = make(0.0625, n_steps * 0.0625, True)
        options = jaxrot.compiler_options() if name.startswith("jaxrot") else None
        _, compile_s, seconds = time_compiled(
            lambda args, run=run: run(*args), (q, w, jax.random.key(5)), repeats, options
        )
        per_step = seconds / (n * n_steps)
        rows.append(
            {
                "method": name,
                "bodies": n,
                "steps": n_steps,
                "seconds_per_body_step": per_step,
                "compile_s": compile_s,
            }
        )
        print(
            f"{name:<20} {seconds / (n * n_steps) * 1e9:8.1f} ns per body-step", file=sys.stderr, flush=True
        )
    return rows


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--bodies", type=int, default=16384, help="bodies for the biases")
    parser.add_argument("--timing", action="store_true", help="also time the methods (a quiet machine only)")
    parser.add_argument("--quick", action="store_true", help="tiny sizes, nothing written")
    parser.add_argument("--out", default=str(ROOT / "docs" / "thermal_peers.json"))
    args = parser.parse_args(argv)
    peer = have_jax_md()
    if not peer:
        print("jax_md is not installed: its rows are skipped (pip install -e '.[peers]' under Python 3.12)",
              file=sys.stderr)  # fmt: skip
    n = 256 if args.quick else args.bodies
    rows, reference = measure_biases(n, peer, DTS[:2] if args.quick else DTS)
    diagnosis = jax_md_diagnosis(256 if args.quick else 4096) if peer else None
    cost = (
        measure_cost(256 if args.quick else 10_000, peer, 16 if args.quick else 256)
        if args.timing or args.quick
        else None
    )
    if args.quick:
        return
    info = machine_info()
    if peer:
        info["jax_md"] = importlib.metadata.version("jax-md")
    result = {
        "machine": info,
        "command": "python benchmarks/thermal_peers.py "
        + " ".join(argv if argv is not None else sys.argv[1:]),
        "setting": {
            "inertia": INERTIA.tolist(),
            "friction": FRICTION,
            "kT": KT,
            "x": X,
            "t_dipole": T_DIPOLE,
            "t_free": T_FREE,
            "samples": SAMPLES,
        },  # fmt: skip
        **reference,
        "rows": rows,
        "jax_md_diagnosis": diagnosis,
        "cost": cost,
    }
    Path(args.out).write_text(json.dumps(result, indent=1) + "\n")
    print(f"wrote {args.out}", file=sys.stderr)


if __name__ == "__main__":
    main()
