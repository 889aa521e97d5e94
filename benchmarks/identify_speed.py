"""`jaxrot.identify` against the same identification written with diffrax and optimistix.

The test satellite (`tests/_telemetry.py`: 3 manoeuvres of 121 star-tracker and gyro samples,
known magnetorquer torques, unknown inertia tensor and residual dipole) is fitted twice from the
same start (a diagonal inertia, zero dipole, each start state from its first samples):

- jaxrot: `jaxrot.identify` with its defaults (its scheme and step rule), covariance included;
- as a diffrax user would write it: the Euclidean quaternion ODE (q̇ = ½ ω ⊗ q, L̇ = τ) with
  Tsit5 or Dopri5 at fixed steps, the finest of spacing/1, /2, /4, … not needed: the coarsest
  whose orientation error against the reference at the true parameters is at most jaxrot's, then
  `optimistix.least_squares` (Gauss–Newton and Levenberg–Marquardt) on the same whitened residuals,
  the same 27 parameters (six inertia elements, dipole, per manoeuvre a rotation-vector offset of
  q₀ and ω₀). The optimistix side gets no covariance: its time is the fit alone.

Both sides are timed with their first call (compile included) and compiled: the median of 7
rounds in which every fit runs once (interleaved, so that a drift of the machine's speed moves
all fits alike);
"same fit quality" is checked as the largest difference of the inertia and dipole between the two
fits in units of jaxrot's standard errors, and the final losses.

Then MuJoCo 4.0's `mujoco.sysid` against `jaxrot.identify` on data MuJoCo made, with ideal sensors
(``--mujoco-seeds`` noise seeds) and with real ones (``--sensor-seeds``: a gyro bias per manoeuvre,
gyro scale and delay, a misaligned and delayed tracker, fitted by both tools), and what each tool can
express: `benchmarks/identify_mujoco.py`. Skipped with a message where ``mujoco[sysid]`` is not
installed (``pip install -e ".[mujoco]"``).

    python benchmarks/identify_speed.py      # ~3 minutes on 2 cores, +5 with MuJoCo (ideal and real sensors)
    python benchmarks/identify_speed.py --quick  # 2 rounds, 1 seed per MuJoCo table, 1 optimistix tolerance
    python benchmarks/identify_speed.py --json docs/identify_speed_cpu.json  # the file the docs render
"""

import argparse
import json
import pathlib
import statistics
import sys
import time

import jax


jax.config.update("jax_enable_x64", True)
sys.path.insert(0, str(pathlib.Path(__file__).parents[1] / "tests"))

import diffrax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import optimistix as optx  # noqa: E402
from _telemetry import SATELLITE_DIPOLE, SATELLITE_INERTIA, dipole_torque, satellite_experiments  # noqa: E402

import jaxrot  # noqa: E402
from jaxrot import quaternion as quat  # noqa: E402
from jaxrot.comparison import machine_info  # noqa: E402


sys.path.insert(0, str(pathlib.Path(__file__).parent))
from identify_mujoco import mujoco_identify_inputs, mujoco_rows  # noqa: E402, F401 (others import the inputs here)


ELEMENTS = ((0, 1, 2, 0, 0, 1), (0, 1, 2, 1, 2, 2))
INERTIA0 = np.diag([0.04, 0.05, 0.06])


def first_call(fn):
    """(seconds of the first call, compile included; its result)."""
    t0 = time.perf_counter()
    out = jax.block_until_ready(fn())
    return time.perf_counter() - t0, out


def interleaved_medians(fns, rounds=7):
    """Median seconds of each compiled ``fn``, timed round-robin (one call of each per round): this
    VM's speed drifts by up to 2× over minutes, so fits timed one after another are not comparable."""
    times = [[] for _ in fns]
    for _ in range(rounds):
        for fn, samples in zip(fns, times, strict=True):
            t0 = time.perf_counter()
            jax.block_until_ready(fn())
            samples.append(time.perf_counter() - t0)
    return [statistics.median(t) for t in times]


def stack(experiments):
    """The experiments as arrays ``(k, n, ...)`` (same sample times here)."""
    return {
        "t": jnp.stack([jnp.asarray(e.t) for e in experiments]),
        "q": jnp.stack([jnp.asarray(e.q) for e in experiments]),
        "omega_body": jnp.stack([jnp.asarray(e.omega_body) for e in experiments]),
        "t_c": jnp.stack([jnp.asarray(e.control[0]) for e in experiments]),
        "tau_c": jnp.stack([jnp.asarray(e.control[1]) for e in experiments]),
    }


def diffrax_model(solver, substeps, data):
    """Orientations and body rates at the samples, for parameters ``p`` (a user's diffrax code)."""
    spacing = float(data["t"][0, 1] - data["t"][0, 0])
    n_steps = (data["t"].shape[1] - 1) * substeps

    def field_torque(t, y, args):
        q, momentum = y
        inertia, dipole, t_c, tau_c = args
        rotation = quat.to_matrix(q / jnp.linalg.norm(q))
        omega = rotation @ jnp.linalg.solve(inertia, rotation.T @ momentum)
        control = jnp.stack([jnp.interp(t, t_c, tau_c[:, i]) for i in range(3)])
        tau = dipole_torque(t, q, omega, {"dipole": dipole}) + control
        q_dot = 0.5 * quat.multiply(jnp.concatenate([jnp.zeros(1), omega]), q)
        return q_dot, tau

    term = diffrax.ODETerm(field_torque)

    def one(q0, omega0, inertia, dipole, t, t_c, tau_c):
        rotation = quat.to_matrix(q0)
        momentum0 = rotation @ inertia @ rotation.T @ omega0
        sol = diffrax.diffeqsolve(
            term,
            solver,
            t[0],
            t[-1],
            spacing / substeps,
            (q0, momentum0),
            args=(inertia, dipole, t_c, tau_c),
            saveat=diffrax.SaveAt(ts=t),
            stepsize_controller=diffrax.ConstantStepSize(),
            max_steps=n_steps + 8,
            adjoint=diffrax.ForwardMode(),  # Gauss–Newton differentiates forwards (jacfwd)
        )
        q, momentum = sol.ys
        q = q / jnp.linalg.norm(q, axis=-1, keepdims=True)
        rotations = jax.vmap(quat.to_matrix)(q)
        omega_body = jnp.linalg.solve(inertia, jnp.einsum("nji,nj->ni", rotations, momentum).T).T
        return q, omega_body

    def model(p, q_start):
        inertia = jnp.zeros((3, 3)).at[ELEMENTS].set(p["inertia"]).at[ELEMENTS[::-1]].set(p["inertia"])
        q0 = quat.multiply(quat.exp(p["dq0"]), q_start)
        return jax.vmap(one, in_axes=(0, 0, None, None, 0, 0, 0))(
            q0, p["omega0"], inertia, p["dipole"], data["t"], data["t_c"], data["tau_c"]
        )

    return model


def residuals(p, args):
    model, data, q_start, sigma_q, sigma_omega = args
    q, omega_body = model(p, q_start)
    relative = quat.multiply(quat.conjugate(data["q"]), q)
    r_q = 2 * relative[..., 1:] * jnp.sign(relative[..., :1]) / sigma_q
    r_w = (omega_body - data["omega_body"]) / sigma_omega
    return jnp.where(jnp.isnan(r_q), 0.0, r_q), r_w


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", default=None, help="also write the rows here")
    parser.add_argument(
        "--mujoco-seeds", type=int, default=4, help="noise seeds of the MuJoCo comparison (0: skip)"
    )
    parser.add_argument(
        "--sensor-seeds",
        type=int,
        default=4,
        help="noise seeds of the real-sensor MuJoCo comparison (0: skip)",
    )
    parser.add_argument("--rounds", type=int, default=7, help="interleaved timing rounds (median)")
    parser.add_argument(
        "--quick", action="store_true", help="2 rounds, 1 MuJoCo seed, optimistix at tolerance 1e-6 only"
    )
    opts = parser.parse_args(argv)
    if opts.quick:
        opts.rounds, opts.mujoco_seeds, opts.sensor_seeds = (
            2,
            min(opts.mujoco_seeds, 1),
            min(opts.sensor_seeds, 1),
        )
    tolerances = (1e-6,) if opts.quick else (1e-4, 1e-6, 1e-10)
    info = machine_info()
    print(info)
    experiments, _ = satellite_experiments(0)
    clean, _ = satellite_experiments(0, noise=False)
    data, clean_data = stack(experiments), stack(clean)
    q_start = data["q"][:, 0]
    omega_start = quat.rotate(q_start, data["omega_body"][:, 0])
    sigma_q, sigma_omega = experiments[0].sigma_q, experiments[0].sigma_omega
    args = {"dipole": jnp.zeros(3)}

    def jaxrot_fit():
        return jaxrot.identify(
            experiments, torque=dipole_torque, args=args, free_args={"dipole": True}, inertia0=INERTIA0,
            q0=np.asarray(q_start), omega0=np.asarray(omega_start),
        )  # fmt: skip

    first, fit = first_call(jaxrot_fit)
    se = np.concatenate([np.asarray(fit.stderr.inertia)[ELEMENTS], np.asarray(fit.stderr.args["dipole"])])
    ours = np.concatenate([np.asarray(fit.inertia)[ELEMENTS], np.asarray(fit.args["dipole"])])
    truth = np.concatenate([SATELLITE_INERTIA[ELEMENTS], SATELLITE_DIPOLE])
    true_p = {
        "inertia": jnp.asarray(SATELLITE_INERTIA[ELEMENTS]),
        "dipole": jnp.asarray(SATELLITE_DIPOLE),
        "dq0": jnp.zeros((3, 3)),
        "omega0": None,
    }
    # jaxrot's model error at the truth, on noise-free data: the accuracy diffrax's step must match.
    true_q0 = clean_data["q"][:, 0]
    true_omega0 = quat.rotate(true_q0, clean_data["omega_body"][:, 0])
    spacing = float(data["t"][0, 1] - data["t"][0, 0])
    substeps = round(spacing / fit.dt)
    ours_error = 0.0
    for k in range(len(experiments)):
        t_c, tau_c = data["t_c"][k], data["tau_c"][k]

        def torque(t, q, omega, args, t_c=t_c, tau_c=tau_c):
            control = jnp.stack([jnp.interp(t, t_c, tau_c[:, i]) for i in range(3)])
            return dipole_torque(t, q, omega, args) + control

        traj = jaxrot.rollout(
            fit.scheme,
            jaxrot.RotState(true_q0[k], true_omega0[k]),
            jnp.asarray(SATELLITE_INERTIA),
            spacing / substeps,
            (data["t"].shape[1] - 1) * substeps,
            torque=torque,
            args={"dipole": jnp.asarray(SATELLITE_DIPOLE)},
            save_every=substeps,
        )
        ours_error = max(ours_error, float(jnp.max(quat.angle_between(traj.q, clean_data["q"][k]))))
    print(f"jaxrot identify: first call {first:.1f} s, loss {fit.loss:.1f}, "
          f"{fit.n_iterations} iterations; model error at the truth {ours_error:.1e} rad")  # fmt: skip
    print(f"jaxrot estimate − truth, in standard errors: max {np.max(np.abs(ours - truth) / se):.2f}")

    label = f"jaxrot.identify ({fit.scheme}, {substeps} step(s) per sample, covariance included)"
    rows = [[label, first, None, fit.loss, 0.0, ours_error]]
    fns = [jaxrot_fit]
    start = {
        "inertia": jnp.asarray(INERTIA0[ELEMENTS]),
        "dipole": jnp.zeros(3),
        "dq0": jnp.zeros((3, 3)),
        "omega0": omega_start,
    }
    for solver_name, solver in (("Tsit5", diffrax.Tsit5()), ("Dopri5", diffrax.Dopri5())):
        for substeps in (1, 2, 4, 8, 16, 32):
            model = diffrax_model(solver, substeps, data)
            q_true, _ = jax.jit(model)(true_p | {"omega0": true_omega0}, true_q0)
            error = float(jnp.max(quat.angle_between(q_true, clean_data["q"])))
            if error <= ours_error:
                break
        step = float(data["t"][0, 1] - data["t"][0, 0]) / substeps
        # Each optimiser at a ladder of tolerances: the loosest that reaches jaxrot's fit is its time.
        for opt_name, optimiser in [
            (f"{kind.__name__} tol {tol:g}", kind(rtol=tol, atol=tol))
            for kind in (optx.GaussNewton, optx.LevenbergMarquardt)
            for tol in tolerances
        ]:

            def solve(p0, optimiser=optimiser, model=model):
                sol = optx.least_squares(
                    residuals,
                    optimiser,
                    p0,
                    args=(model, data, q_start, sigma_q, sigma_omega),
                    max_steps=100,
                    throw=False,
                )
                return sol.value, sol.stats["num_steps"]

            solve = jax.jit(solve)
            first_d, (value, n_opt) = first_call(lambda solve=solve: solve(start))
            fns.append(lambda solve=solve: solve(start))
            r_q, r_w = residuals(value, (model, data, q_start, sigma_q, sigma_omega))
            loss = float(jnp.sum(r_q**2) + jnp.sum(r_w**2))
            theirs = np.concatenate([np.asarray(value["inertia"]), np.asarray(value["dipole"])])
            gap = float(np.max(np.abs(theirs - ours) / se))
            label = f"diffrax {solver_name} dt = {step:g} s + optimistix {opt_name} ({int(n_opt)} steps)"
            rows.append([label, first_d, None, loss, gap, error])
    for row, median in zip(rows, interleaved_medians(fns, opts.rounds), strict=True):
        row[2] = median
    run = rows[0][2]
    print()
    print(
        "| fit | first call [s] | compiled [s] | loss | max Δ vs jaxrot [se] | model error [rad] | × jaxrot |"
    )
    print("|---|---|---|---|---|---|---|")
    for label, first_r, run_r, loss, gap, error in rows:
        cells = [label, f"{first_r:.1f}", f"{run_r:.2f}", f"{loss:.1f}", f"{gap:.2f}", f"{error:.1e}"]
        print("| " + " | ".join(cells + [f"{run_r / run:.1f}"]) + " |")
    same = [r for r in rows[1:] if r[4] < 0.1]
    best = min(same, key=lambda r: r[2])
    print(f"\nFastest diffrax + optimistix fit within 0.1 se of jaxrot's: {best[0]}")
    print(f"  compiled {best[2]:.2f} s against jaxrot's {run:.2f} s: jaxrot {best[2] / run:.1f}× faster")
    print(f"  first call {best[1]:.1f} s against jaxrot's {first:.1f} s: {best[1] / first:.2f}×")
    mujoco = mujoco_rows(opts.mujoco_seeds, opts.sensor_seeds)
    if opts.json:
        keys = ("fit", "first_call_s", "compiled_s", "loss", "max_gap_se", "model_error_rad")
        out = {"machine": info, "rounds": opts.rounds}
        out["rows"] = [dict(zip(keys, r, strict=True)) for r in rows]
        out |= mujoco or {}
        with open(opts.json, "w") as f:
            json.dump(out, f, indent=2)


if __name__ == "__main__":
    main()
