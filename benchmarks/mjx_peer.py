"""MuJoCo XLA (MJX) against jaxrot: the same bodies on both sides, orders, cost at equal error, gradients.

Two problems, each a MuJoCo model built by `mujoco_free_body.model_xml` (one body on a ball joint,
contacts and constraints off) and the same physics in jaxrot:

- ``free_body``: inertia diag(1, 2, 3) about the centre (the ball joint at the centre of mass),
  torque-free, ``q0 = exp((0.1, 0.2, 0.3))``, body rates ``(0.3, 1, 0.2)`` rad/s, t = ``--t-free``;
- ``heavy_top``: `jaxrot.scenes.heavy_top` (1.25, 2, 3) kg m² about the pivot, 1 kg at (0.1, 0.05, 0.3)
  m: in MuJoCo the ball joint sits at the pivot and the body's inertial element carries the central
  tensor `jaxrot.central_inertia(pivot, mass, offset)` at the offset, gravity (0, 0, −9.81).

MJX's state is MuJoCo's: ``qpos`` the orientation (scalar first, body → world), ``qvel`` the
**body-frame** angular velocity, so jaxrot's state is ``RotState.from_body(qpos, qvel)``. The
reference is `jaxrot.reference_rollout` (diffrax Dopri8, rtol = atol = 1e-12); an error is the
geodesic angle at t_end. Measured, float64 (``jax_enable_x64``):

1. each MJX integrator's (Euler, RK4, implicitfast) error against dt and its order (the slope of a
   log-log fit over the rungs between 1e-10 and 0.1 rad), beside jaxrot's rkmk4, zhao, splitting
   and rkmk_dopri8; and that MJX's finest RK4 rung and the reference agree (same physics);
2. cost per body-step for ``--n`` bodies of the heavy top (MJX: `jax.vmap` over `mjx.Data`; jaxrot:
   its particle axis), and per error budget each side's cheapest method on it: the steps its ladder
   needs × its cost per body-step (an MJX step costs the same at any dt; jaxrot's is timed at that
   dt). Not the free body: `splitting`'s exact rotor solves it at any step;
3. the gradient of a final-orientation loss ``1 − (q(T)·q_target)²`` after ``--grad-steps`` steps
   w.r.t. the initial body rates, for ``--grad-n`` bodies: compile and run time, MJX RK4 and rkmk4;
4. that gradient AT REST (ω = 0, one free body): MJX's (every integrator), central finite differences
   of MJX's own map (h = 1e-5) and jaxrot's (rkmk4 and zhao). MJX's is 0: ``math.norm`` returns 0 with
   a zero gradient when every component is within 1e-8 (``jp.allclose(x, 0)``).

    python benchmarks/mjx_peer.py --json docs/mjx_cpu.json        # full: ~6 min on 2 quiet cores (estimated)
    python benchmarks/mjx_peer.py --quick --json /tmp/mjx.json    # ~4 min (9.9 min at 1.6 cores of load)

Needs ``pip install -e ".[mjx]"``; without it, it says so and exits 0.
"""

import argparse
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
from jaxrot.comparison import fit_order, machine_info, time_compiled
from jaxrot.comparison._timing import time_runs


sys.path.insert(0, str(Path(__file__).resolve().parent))
from mujoco_free_body import model_xml  # noqa: E402  (the MuJoCo model builder, shared)


MJX_INTEGRATORS = ("euler", "rk4", "implicitfast")
JAXROT_SCHEMES = ("rkmk4", "zhao", "splitting", "rkmk_dopri8")
FIT_RANGE = (1e-10, 0.1)  # rad: rungs used for an order
BUDGETS = (1e-2, 1e-4, 1e-6, 1e-8)
Q_TARGET = (0.3, -0.2, 0.5)  # rotation vector of the loss's target orientation
FREE_INERTIAL = '<inertial pos="0 0 0" mass="1" diaginertia="1.0 2.0 3.0"/>'


def problems(t_free, t_top):
    """``name -> (xml builder (integrator, dt), RotState, inertia, torque, args, t_end)``."""
    q0 = quat.exp(jnp.array([0.1, 0.2, 0.3]))
    top = jaxrot.scenes.heavy_top()
    offset = top.args["gravity"]["offset_body"]
    central = np.asarray(top.central_inertia())
    full = " ".join(repr(float(central[i, j])) for i, j in ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)))
    pos = " ".join(repr(float(x)) for x in offset)
    top_inertial = f'<inertial pos="{pos}" mass="{top.mass!r}" fullinertia="{full}"/>'

    def free_xml(integrator, dt):
        return model_xml(1, integrator, dt, joint="ball")

    def top_xml(integrator, dt):
        xml = model_xml(1, integrator, dt, joint="ball")
        return xml.replace(FREE_INERTIAL, top_inertial).replace('gravity="0 0 0"', 'gravity="0 0 -9.81"')

    assert FREE_INERTIAL in free_xml("rk4", 0.1)  # the builder's body, replaced for the top
    omega_b = quat.rotate(quat.conjugate(top.state.q), top.state.omega)
    return {
        "free_body": (
            free_xml,
            jaxrot.RotState.from_body(q0, jnp.array([0.3, 1.0, 0.2])),
            jnp.array([1.0, 2.0, 3.0]),
            None,
            None,
            t_free,
        ),
        "heavy_top": (
            top_xml,
            jaxrot.RotState.from_body(top.state.q, omega_b),
            top.inertia,
            top.torque,
            top.args,
            t_top,
        ),
    }


def mjx_model(xml):
    import mujoco
    from mujoco import mjx

    return mjx.put_model(mujoco.MjModel.from_xml_string(xml))


def mjx_data(m, q, omega_body):
    from mujoco import mjx

    return mjx.make_data(m).replace(qpos=jnp.asarray(q), qvel=jnp.asarray(omega_body))


def _mjx_run(m, d, n):
    from mujoco import mjx

    return jax.lax.fori_loop(0, n, lambda i, d: mjx.step(m, d), d).qpos


_MJX_RUN = jax.jit(_mjx_run)


def mjx_runner(m):
    """A compiled ``(m, d, n) -> qpos`` after ``n`` steps: dt (``m.opt.timestep``), ``n`` and the model's
    numbers are arguments, so one program serves every rung and both problems of an integrator."""
    return _MJX_RUN


def with_dt(m, dt):
    return m.replace(opt=m.opt.replace(timestep=jnp.asarray(dt)))


def angle(q, q_ref):
    e = float(jnp.max(quat.angle_between(jnp.asarray(q), jnp.asarray(q_ref))))
    return e if np.isfinite(e) else None


def ladders(name, problem, max_steps, log):
    xml, state, inertia, torque, args, t_end = problem
    q_ref = jaxrot.reference_rollout(state, inertia, jnp.array([0.0, t_end]), torque=torque, args=args).q[-1]
    omega_b = quat.rotate(quat.conjugate(state.q), state.omega)
    rows = []
    for integrator in MJX_INTEGRATORS:
        m = mjx_model(xml(integrator, 0.1))
        d = mjx_data(m, state.q, omega_b)
        run = mjx_runner(m)
        n = 16
        while n <= max_steps:
            error = angle(run(with_dt(m, t_end / n), d, n), q_ref)
            rows.append(
                {
                    "problem": name,
                    "method": f"mjx_{integrator}",
                    "n_steps": n,
                    "dt": t_end / n,
                    "error_rad": error,
                }
            )
            log(f"{name} mjx_{integrator:12s} {n:6d} steps  {error}")
            if error is not None and error < FIT_RANGE[0]:
                break
            n *= 2
    chunk = 16  # every rung runs this compiled chunk of steps n / chunk times: one program per scheme
    for scheme in JAXROT_SCHEMES:

        @jax.jit
        def steps(s, dt, scheme=scheme):
            traj = jaxrot.rollout(scheme, s, inertia, dt, chunk, torque=torque, args=args, save_every=chunk)
            return jaxrot.RotState(traj.q[-1], traj.omega[-1])

        n = chunk
        while n <= max_steps:
            s = state
            for _ in range(n // chunk):
                s = steps(s, t_end / n)  # t0 does not matter: the torques do not depend on time
            error = angle(s.q, q_ref)
            rows.append(
                {"problem": name, "method": scheme, "n_steps": n, "dt": t_end / n, "error_rad": error}
            )
            log(f"{name} {scheme:16s} {n:6d} steps  {error}")
            if error is not None and error < FIT_RANGE[0]:
                break
            n *= 2
    return rows


def orders(rows):
    out = {}
    for key in dict.fromkeys((r["problem"], r["method"]) for r in rows):
        mine = [
            r
            for r in rows
            if (r["problem"], r["method"]) == key
            and r["error_rad"] is not None
            and FIT_RANGE[0] < r["error_rad"] < FIT_RANGE[1]
        ]
        out.setdefault(key[0], {})[key[1]] = (
            fit_order([r["dt"] for r in mine], [r["error_rad"] for r in mine]) if len(mine) >= 2 else None
        )
    return out


def bodies(n, seed=0):
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(n, 4))
    return jnp.asarray(q / np.linalg.norm(q, axis=1, keepdims=True)), jnp.asarray(rng.normal(size=(n, 3)))


def mjx_costs(problem, n, steps, repeats, log):
    """ns per body-step of each MJX integrator, ``n`` bodies vmapped over `mjx.Data`."""
    from mujoco import mjx

    xml, *_ = problem
    q, w = bodies(n)
    out = {}
    for integrator in MJX_INTEGRATORS:
        m = mjx_model(xml(integrator, 1e-3))
        d = jax.vmap(lambda q, w, m=m: mjx_data(m, q, w))(q, w)

        def run(d, m=m):
            step = jax.vmap(lambda d: mjx.step(m, d))
            return jax.lax.fori_loop(0, steps, lambda i, d: step(d), d).qpos

        _, compile_s, seconds = time_compiled(run, d, repeats)
        out[f"mjx_{integrator}"] = {"ns_per_body_step": 1e9 * seconds / (n * steps), "compile_s": compile_s}
        log(f"cost mjx_{integrator}: {out[f'mjx_{integrator}']}")
    return out


_JAXROT_RUNS = {}


def jaxrot_cost(scheme, problem, n, dt, steps, repeats):
    """ns per body-step of ``scheme`` at ``dt`` on ``n`` bodies (dt an argument: one program per scheme)."""
    _, _, inertia, torque, args, _ = problem
    q, w = bodies(n)
    state = jaxrot.RotState.from_body(q, w)
    if scheme not in _JAXROT_RUNS:

        def run(s, dt):
            traj = jaxrot.rollout(scheme, s, inertia, dt, steps, torque=torque, args=args, save_every=steps)
            return traj.q[-1]

        _JAXROT_RUNS[scheme] = jax.jit(run, compiler_options=jaxrot.compiler_options())
    _, seconds = time_runs(_JAXROT_RUNS[scheme], (state, jnp.asarray(dt)), repeats)
    return 1e9 * seconds / (n * steps)


def equal_error(rows, costs, problem, n, steps, repeats, log):
    """Per budget and side, the cheapest method meeting it on the heavy top: µs per body over t_end."""
    out = []
    for budget in BUDGETS:
        entry = {"budget_rad": budget}
        for side, methods in (("mjx", [f"mjx_{i}" for i in MJX_INTEGRATORS]), ("jaxrot", JAXROT_SCHEMES)):
            best = None
            for method in methods:
                meeting = [
                    r
                    for r in rows
                    if r["problem"] == "heavy_top"
                    and r["method"] == method
                    and r["error_rad"] is not None
                    and r["error_rad"] <= budget
                ]
                if not meeting:
                    continue
                r = min(meeting, key=lambda r: r["n_steps"])
                ns = (
                    costs[method]["ns_per_body_step"]
                    if side == "mjx"
                    else jaxrot_cost(method, problem, n, r["dt"], steps, repeats)
                )
                cand = {
                    "method": method,
                    "n_steps": r["n_steps"],
                    "error_rad": r["error_rad"],
                    "ns_per_body_step": ns,
                    "us_per_body": 1e-3 * ns * r["n_steps"],
                }
                if best is None or cand["us_per_body"] < best["us_per_body"]:
                    best = cand
            entry[side] = best
        m, j = entry["mjx"], entry["jaxrot"]
        entry["ratio"] = m["us_per_body"] / j["us_per_body"] if m and j else None
        log(f"budget {budget:g}: {entry}")
        out.append(entry)
    return out


def loss_of_q(q_end):
    target = quat.exp(jnp.asarray(Q_TARGET))
    return 1.0 - jnp.sum(q_end * target, axis=-1) ** 2


def mjx_final(m, q0, n_steps):
    from mujoco import mjx

    def final(w):
        d = mjx_data(m, q0, w)
        return jax.lax.scan(lambda d, _: (mjx.step(m, d), None), d, None, length=n_steps)[0].qpos

    return final


def jaxrot_final(scheme, inertia, q0, dt, n_steps):
    def final(w):
        state = jaxrot.RotState.from_body(q0, w)
        return jaxrot.rollout(scheme, state, inertia, dt, n_steps, save_every=n_steps).q[-1]

    return final


def gradient_cost(problem, n, n_steps, dt, repeats, log):
    """Compile and run seconds of the loss's gradient over ``n`` bodies, MJX RK4 and rkmk4."""
    xml, _, inertia, *_ = problem
    q, w = bodies(n)
    out = {}
    m = mjx_model(xml("rk4", dt))
    for side in ("mjx_rk4", "rkmk4"):
        if side == "mjx_rk4":

            def total(w):
                qs = jax.vmap(lambda qi, wi: mjx_final(m, qi, n_steps)(wi))(q, w)
                return jnp.sum(loss_of_q(qs))
        else:

            def total(w):
                return jnp.sum(loss_of_q(jaxrot_final("rkmk4", inertia, q, dt, n_steps)(w)))

        opts = jaxrot.compiler_options() if side == "rkmk4" else None
        g, compile_s, seconds = time_compiled(jax.grad(total), w, repeats, opts)
        out[side] = {"compile_s": compile_s, "run_s": seconds, "finite": bool(jnp.all(jnp.isfinite(g)))}
        log(f"gradient {side}: {out[side]}")
    return out


def gradient_at_rest(problem, n_steps, dt, h=1e-5):
    xml, state, inertia, *_ = problem
    q0, w0 = state.q, jnp.zeros(3)
    out = {}
    for integrator in MJX_INTEGRATORS:
        final = mjx_final(mjx_model(xml(integrator, dt)), q0, n_steps)
        f = jax.jit(lambda w, final=final: loss_of_q(final(w)))
        g = jax.grad(f)(w0)
        fd = [(float(f(w0.at[i].set(h))) - float(f(w0.at[i].set(-h)))) / (2 * h) for i in range(3)]
        out[f"mjx_{integrator}"] = {"gradient": [float(x) for x in g], "finite_difference": fd}
    for scheme in ("rkmk4", "zhao"):
        f = jax.jit(lambda w, scheme=scheme: loss_of_q(jaxrot_final(scheme, inertia, q0, dt, n_steps)(w)))
        g = jax.grad(f)(w0)
        fd = [(float(f(w0.at[i].set(h))) - float(f(w0.at[i].set(-h)))) / (2 * h) for i in range(3)]
        out[scheme] = {"gradient": [float(x) for x in g], "finite_difference": fd}
    return out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small sizes (a check, a few minutes)")
    parser.add_argument("--json", default=None)
    opts = parser.parse_args(argv)
    jax.config.update("jax_enable_x64", True)  # here, not at import: tests/test_mjx.py imports this module
    if importlib.util.find_spec("mujoco") is None or importlib.util.find_spec("mujoco.mjx") is None:
        print('mjx_peer: MJX is not installed (pip install -e ".[mjx]"); nothing measured')
        return 0
    import mujoco

    s = dict(
        t_free=10.0,
        t_top=2.0,
        max_steps=2**13 if opts.quick else 2**15,
        n=200 if opts.quick else 1000,
        cost_steps=20 if opts.quick else 50,
        repeats=2 if opts.quick else 5,
        grad_n=100,
        grad_steps=200 if opts.quick else 1000,
        grad_dt=0.01,
        rest_steps=100,
        rest_dt=0.01,
        fit_range_rad=FIT_RANGE,
        budgets_rad=BUDGETS,
        q_target=Q_TARGET,
        quick=opts.quick,
    )
    info = machine_info() | {
        "mujoco": mujoco.__version__,
        "mujoco_mjx": importlib.metadata.version("mujoco-mjx"),
    }
    print(", ".join(f"{k} {v}" for k, v in info.items()), flush=True)
    log = lambda text: print(text, flush=True)
    probs = problems(s["t_free"], s["t_top"])
    start = time.perf_counter()
    rows = [r for name, p in probs.items() for r in ladders(name, p, s["max_steps"], log)]
    fitted = orders(rows)
    log(f"orders {fitted}  ({time.perf_counter() - start:.0f} s)")
    agreement = {}
    for name in probs:
        finest = [r for r in rows if r["problem"] == name and r["method"] == "mjx_rk4" and r["error_rad"]]
        agreement[name] = {"mjx_rk4_finest_dt": finest[-1]["dt"], "error_rad": finest[-1]["error_rad"]}
    # Cost and equal error on the heavy top: on the torque-free body `splitting`'s exact rotor is exact at
    # any step, which would compare integrators with a closed form.
    costs = mjx_costs(probs["heavy_top"], s["n"], s["cost_steps"], s["repeats"], log)
    for scheme in JAXROT_SCHEMES:
        costs[scheme] = {
            "ns_per_body_step": jaxrot_cost(
                scheme, probs["heavy_top"], s["n"], 0.01, s["cost_steps"] * 4, s["repeats"]
            ),
            "dt": 0.01,
        }
        log(f"cost {scheme}: {costs[scheme]}")
    budgets = equal_error(rows, costs, probs["heavy_top"], s["n"], s["cost_steps"] * 4, s["repeats"], log)
    gradient = gradient_cost(
        probs["free_body"], s["grad_n"], s["grad_steps"], s["grad_dt"], min(s["repeats"], 3), log
    )
    rest = gradient_at_rest(probs["free_body"], s["rest_steps"], s["rest_dt"])
    log(f"gradient at rest {json.dumps(rest)}  ({time.perf_counter() - start:.0f} s)")
    out = {
        "machine": info,
        "settings": s,
        "rows": rows,
        "orders": fitted,
        "agreement": agreement,
        "costs": costs,
        "budgets": budgets,
        "gradient": gradient,
        "gradient_at_rest": rest,
    }
    if opts.json:
        Path(opts.json).write_text(json.dumps(out, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
