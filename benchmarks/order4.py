"""Fourth-order Lie-group methods on the rigid body: orders and error constants at equal torque calls.

Accuracy only (no timing: it can run on a busy machine). Every method advances the orientation on
the group and an angular-momentum variable in R³ with four (CG4: five) evaluations of the dynamics
per step; they differ in how the stage rotations are composed and in the variable the tableau
advances beside them:

- **RKMK4** (Munthe-Kaas, BIT 38 (1998) 92): one exponential of a combination of ``dexp⁻¹``-corrected
  slopes per stage. Its stage rotations can act on the left (world algebra, ``exp(Θ) ⊗ q_n``,
  jaxrot) or on the right (body algebra, ``q_n ⊗ exp(Θ)``, MuJoCo's ``mj_integratePos``): the two
  are conjugate by the constant ``q_n``, the same method (rows 3-4 against 1-2).
- **CF4**, commutator-free (Celledoni, Marthinsen and Owren, FGCS 19 (2003) 341): products of
  exponentials of plain combinations of the slopes, two at the fourth stage and at the end.
- **CG4**, Crouch–Grossman (Owren and Marthinsen's five-stage order-4 coefficients as printed by
  Jackiewicz, Marthinsen and Owren, Adv. Comput. Math. 13 (2000) 405): one exponential per slope,
  composed; its ``a₅₄`` is taken from the row sum ``c₅`` (one public copy prints ``…13565``, which
  breaks the row sum in the 14th digit).
- **MuJoCo 3.x's RK4**: RK4 on ``(q, ω_b)`` with the stage rotations ``q_n ⊗ exp(h Σ a_ij ω_j)``
  and no ``dexp⁻¹``: order 2 (its changelog for 4.0 says so and adds the RKMK correction).
- **MuJoCo 4.0's RK4** itself (free bodies; skipped with a message where ``mujoco`` is absent).

The momentum variable: the world angular momentum ``L`` (``L̇ = τ``; ``ω = R I⁻¹ Rᵀ L`` depends on
the stage orientation) or the body angular velocity ``ω_b`` (Euler's equations
``I ω̇_b = I ω_b × ω_b + Rᵀ τ``, the variable MuJoCo's free joint carries; RK is invariant under the
linear map to the body momentum ``I ω_b`` that jaxrot's ``rkmk4`` carries). Problems:

- ``dzhanibekov``: jaxrot.SCENES["free_top"]: torque-free, I = (1, 2, 3), q = 1,
  ω_b = (0.01, 2, 0.01), 10 s (the intermediate-axis flip); exact solution `jaxrot.analytic`.
- ``generic``: torque-free, I = (1, 2, 3), q = exp((0.1, 0.2, 0.3)), ω_b = (1, 2, 0.5), 10 s (the
  tests' tumbling body).
- ``heavy_top``: jaxrot.SCENES["heavy_top"], 5 s; reference `jaxrot.reference_rollout` at
  rtol = atol = 1e-14.

The error of a run is the largest orientation error (rad) over 51 equally spaced times. The order
is the slope of a log-log fit over four halvings of the step (2.5× and 5× coarser for the orders 5
and 8; rungs below 1e-11 rad, near the
reference's round-off, left out; 1e-12 for the exact free-body solutions); the error at equal
torque calls is that fit evaluated at the step
that spends as many calls as four per reference step (``dt_ref · s / 4``, ``s`` calls per step).

    python benchmarks/order4.py --json docs/order4.json   # the results file the docs render (~6 min)
    python benchmarks/order4.py --quick                     # two rungs, one problem: a check
"""

import argparse
import json
import sys

import jax


jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np

import jaxrot
from jaxrot import analytic, quaternion as quat
from jaxrot.comparison import machine_info
from jaxrot.schemes import RKMK4, RKMKDopri5, RKMKDopri8
from jaxrot.schemes._lie_runge_kutta import exp_and_dexpinv


SAMPLES = 50
MOMENTS = (1.0, 2.0, 3.0)


def problems():
    """``name -> (state, inertia, torque, args, t_end, reference dt, dt ladder)``."""
    free_top, heavy = jaxrot.SCENES["free_top"](), jaxrot.SCENES["heavy_top"]()
    q0 = quat.exp(jnp.array([0.1, 0.2, 0.3]))
    generic = jaxrot.RotState(q0, quat.rotate(q0, jnp.array([1.0, 2.0, 0.5])))
    free_ladder = (0.04, 0.02, 0.01, 0.005)
    return {
        "dzhanibekov": (free_top.state, free_top.inertia, None, None, 10.0, 0.01, free_ladder),
        "generic": (generic, jnp.array(MOMENTS), None, None, 10.0, 0.01, free_ladder),
        "heavy_top": (
            heavy.state,
            heavy.inertia,
            heavy.torque,
            heavy.args,
            5.0,
            0.005,
            (0.02, 0.01, 0.005, 0.0025),
        ),
    }


# --- the methods ---------------------------------------------------------------------------------

RK4 = {
    "a": ((), (0.5,), (0.0, 0.5), (0.0, 0.0, 1.0)),
    "b": (1 / 6, 1 / 3, 1 / 3, 1 / 6),
    "c": (0, 0.5, 0.5, 1),
}
CG4 = {
    "a": (
        (),
        (0.8177227988124852,),
        (0.3199876375476427, 0.0659864263556022),
        (0.9214417194464946, 0.4997857776773573, -1.0969984448371582),
        (0.3552358559023322, 0.2390958372307326, 1.3918565724203246, -1.1092979392113465),
    ),
    "b": (
        0.1370831520630755, -0.0183698531564020, 0.7397813985370780, -0.1907142565505889, 0.3322195591068374
    ),
    "c": (0.0, 0.8177227988124852, 0.3859740639032449, 0.3242290522866937, 0.8768903263420429),
}  # fmt: skip
# CF4: each stage (and the output) a product of exponentials, applied first to last, each a row of
# weights on the slopes (Celledoni, Marthinsen and Owren 2003, the method of order 4 with 4 stages).
CF4 = {
    "a": ((), ((0.5,),), ((0.0, 0.5),), ((0.5, 0.0, 0.0), (-0.5, 0.0, 1.0))),
    "b": ((0.25, 1 / 6, 1 / 6, -1 / 12), (-1 / 12, 1 / 6, 1 / 6, 0.25)),
    "c": (0, 0.5, 0.5, 1),
}


def _weighted(h, weights, vectors):
    total = jnp.zeros(3)
    for w, v in zip(weights, vectors, strict=False):
        total = total + (w * h) * v
    return total


def lie_step(method, side, variable, inertia, torque, args):
    """One step ``(t, q, v, h) -> (q, v)`` of ``method`` (``rkmk4``, ``cf4``, ``cg4``, ``mujoco3``).

    ``side``: ``"left"`` (world algebra, ``exp(Θ) ⊗ q``) or ``"right"`` (body algebra, ``q ⊗ exp(Θ)``);
    ``variable``: ``"L"`` (world angular momentum) or ``"omega_body"`` (body angular velocity)."""
    moments = jnp.asarray(inertia)
    right = side == "right"

    def flow(q, theta):
        e = quat.exp(theta)
        return quat.multiply(q, e) if right else quat.multiply(e, q)

    def slopes(t, q, v):
        """The algebra slope (body ω for ``right``, world ω for ``left``) and the rate of ``v``."""
        omega_body = quat.rotate(quat.conjugate(q), v) / moments if variable == "L" else v
        omega = quat.rotate(q, omega_body)
        tau = jnp.zeros(3) if torque is None else torque(t, q, omega, args)
        if variable == "L":
            rate = tau
        else:
            rate = (
                jnp.cross(moments * omega_body, omega_body) + quat.rotate(quat.conjugate(q), tau)
            ) / moments
        return (omega_body if right else omega), rate

    def dexpinv(theta, w):
        # Right-trivialised: Θ' = dexp⁻¹_{−Θ}(ω_b) for q = q_n ⊗ exp(Θ).
        return exp_and_dexpinv(-theta if right else theta, w)[1]

    def step(t, q, v, h):
        ks, rates = [], []
        if method == "cf4":
            for i in range(4):
                q_i, v_i = q, v
                for row in CF4["a"][i]:
                    q_i, v_i = flow(q_i, _weighted(h, row, ks)), v_i + _weighted(h, row, rates)
                k, r = slopes(t + CF4["c"][i] * h, q_i, v_i)
                ks.append(k)
                rates.append(r)
            for row in CF4["b"]:
                q, v = flow(q, _weighted(h, row, ks)), v + _weighted(h, row, rates)
            return quat.normalize(q), v
        tableau = CG4 if method == "cg4" else RK4
        for i, row in enumerate(tableau["a"]):
            v_i = v + _weighted(h, row, rates)
            if method == "cg4":  # one frozen flow per earlier slope, the first slope's first
                q_i = q
                for w, k in zip(row, ks, strict=False):
                    q_i = flow(q_i, (w * h) * k)
                k, r = slopes(t + tableau["c"][i] * h, q_i, v_i)
            else:
                theta = _weighted(h, row, ks)
                k, r = slopes(t + tableau["c"][i] * h, flow(q, theta), v_i)
                if method == "rkmk4":
                    k = dexpinv(theta, k)
            ks.append(k)
            rates.append(r)
        if method == "cg4":
            for w, k in zip(tableau["b"], ks, strict=True):
                q = flow(q, (w * h) * k)
        else:
            q = flow(q, _weighted(h, tableau["b"], ks))
        return quat.normalize(q), v + _weighted(h, tableau["b"], rates)

    def initial(state):
        omega_body = quat.rotate(quat.conjugate(state.q), state.omega)
        return quat.rotate(state.q, moments * omega_body) if variable == "L" else omega_body

    return step, initial


def scripted_run(method, side, variable):
    """``run(state, inertia, torque, args, dt, n_per_sample) -> q`` at the 51 sample times."""
    compiled = {}  # one program per problem: dt and the steps per sample are runtime values

    def run(state, inertia, torque, args, dt, per_sample):
        key = (id(torque), tuple(np.asarray(inertia).ravel()))
        if key not in compiled:
            step, initial = lie_step(method, side, variable, inertia, torque, args)

            @jax.jit
            def go(q, v, dt, per_sample):
                def sample(carry, i):
                    def one(j, c):
                        return step((i * per_sample + j) * dt, *c, dt)

                    carry = jax.lax.fori_loop(0, per_sample, one, carry)
                    return carry, carry[0]

                _, qs = jax.lax.scan(sample, (q, v), jnp.arange(SAMPLES))
                return jnp.concatenate([q[None], qs])

            compiled[key] = go, initial
        go, initial = compiled[key]
        return go(state.q, initial(state), jnp.asarray(dt), jnp.asarray(per_sample))

    return run


def library_run(scheme):
    def run(state, inertia, torque, args, dt, per_sample):
        traj = jaxrot.rollout(
            scheme, state, inertia, dt, SAMPLES * per_sample, torque=torque, args=args, save_every=per_sample
        )
        return traj.q

    return run


MUJOCO_XML = """<mujoco><option gravity="0 0 0" integrator="RK4" timestep="{dt}"/><worldbody><body>
<freejoint/><inertial pos="0 0 0" mass="1" diaginertia="{i1} {i2} {i3}"/></body></worldbody></mujoco>"""


def mujoco_run(state, inertia, torque, args, dt, per_sample):
    """MuJoCo's own RK4 on a free body (no gravity): ``qpos[3:]`` is q, ``qvel[3:]`` the body ω."""
    import mujoco

    if torque is not None:
        return None
    i1, i2, i3 = (float(x) for x in inertia)
    model = mujoco.MjModel.from_xml_string(MUJOCO_XML.format(dt=dt, i1=i1, i2=i2, i3=i3))
    data = mujoco.MjData(model)
    data.qpos[3:] = np.asarray(state.q)
    data.qvel[3:] = np.asarray(quat.rotate(quat.conjugate(state.q), state.omega))
    qs = [data.qpos[3:].copy()]
    for _ in range(SAMPLES):
        for _ in range(per_sample):
            mujoco.mj_step(model, data)
        qs.append(data.qpos[3:].copy())
    return jnp.asarray(np.array(qs))


# (label, order, torque calls per step, exponentials per step, run); the first is jaxrot's rkmk4.
def methods():
    rows = [
        ("rkmk4: RKMK4, body momentum (jaxrot)", 4, 4, "4 + 3 dexp⁻¹", library_run("rkmk4")),
        ("RKMK4, world momentum L (jaxrot's rkmk4 before)", 4, 4, "4 + 3 dexp⁻¹",
         library_run(RKMK4(momentum_frame="world"))),
        ("RKMK4, right-trivialised (body algebra), body ω", 4, 4, "4 + 3 dexp⁻¹",
         scripted_run("rkmk4", "right", "omega_body")),
        ("RKMK4, right-trivialised (body algebra), world L", 4, 4, "4 + 3 dexp⁻¹",
         scripted_run("rkmk4", "right", "L")),
        ("CF4, world algebra, world L", 4, 4, "6", scripted_run("cf4", "left", "L")),
        ("CF4, world algebra, body ω", 4, 4, "6", scripted_run("cf4", "left", "omega_body")),
        ("CF4, body algebra, world L", 4, 4, "6", scripted_run("cf4", "right", "L")),
        ("CF4, body algebra, body ω", 4, 4, "6", scripted_run("cf4", "right", "omega_body")),
        ("CG4, world algebra, world L", 4, 5, "15", scripted_run("cg4", "left", "L")),
        ("CG4, world algebra, body ω", 4, 5, "15", scripted_run("cg4", "left", "omega_body")),
        ("CG4, body algebra, world L", 4, 5, "15", scripted_run("cg4", "right", "L")),
        ("CG4, body algebra, body ω", 4, 5, "15", scripted_run("cg4", "right", "omega_body")),
        ("MuJoCo 3.x RK4 form (no dexp⁻¹), in jax", 2, 4, "4",
         scripted_run("mujoco3", "right", "omega_body")),
        ("MuJoCo 4.0 RK4 (free body)", 4, 4, "4 + 3 dexp⁻¹", mujoco_run),
        ("rkmk_dopri5, world momentum L (jaxrot)", 5, 6, "6 + 5 dexp⁻¹", library_run("rkmk_dopri5")),
        ("rkmk_dopri5, body momentum", 5, 6, "6 + 5 dexp⁻¹",
         library_run(RKMKDopri5(momentum_frame="body"))),
        ("rkmk_dopri8, world momentum L (jaxrot)", 8, 13, "13 + 12 dexp⁻¹", library_run("rkmk_dopri8")),
        ("rkmk_dopri8, body momentum", 8, 13, "13 + 12 dexp⁻¹",
         library_run(RKMKDopri8(momentum_frame="body"))),
    ]  # fmt: skip
    return rows


def mujoco_available():
    try:
        import mujoco
    except ImportError:
        return None
    return mujoco.__version__


def measure(quick=False):
    probs = problems()
    if quick:
        probs = {"generic": probs["generic"][:6] + (probs["generic"][6][:2],)}
    has_mujoco = mujoco_available()
    if has_mujoco is None:
        print("mujoco is not installed: its row is skipped (pip install mujoco)", file=sys.stderr)
    elif int(has_mujoco.split(".")[0]) < 4:
        print(
            f"mujoco {has_mujoco} is older than 4.0 (its RK4 has order 2): its row is skipped",
            file=sys.stderr,
        )
        has_mujoco = None
    rows = []
    for label, order, calls, exponentials, run in methods():
        if run is mujoco_run and has_mujoco is None:
            continue
        row = {
            "method": label,
            "nominal_order": order,
            "torque_calls_per_step": calls,
            "exponentials": exponentials,
        }
        row["problems"] = {}
        for name, (state, inertia, torque, args, t_end, dt_ref, ladder) in probs.items():
            if run is mujoco_run and torque is not None:
                continue
            # The higher orders reach round-off at the fourth-order steps: coarser rungs.
            ladder = tuple({5: 2.5, 8: 5.0}.get(order, 1.0) * dt for dt in ladder)
            reference = _reference(name, state, inertia, torque, args, t_end)
            errors = []
            for dt in ladder:
                per_sample = round(t_end / SAMPLES / dt)
                q = run(state, inertia, torque, args, dt, per_sample)
                errors.append(float(jnp.max(quat.angle_between(q, reference))))
            floor = 1e-12 if torque is None else 1e-11
            fit = [(dt, e) for dt, e in zip(ladder, errors, strict=True) if e > floor]
            slope, equal = None, None
            if len(fit) >= 2:  # else the method is at round-off on all but the coarsest rung
                slope, intercept = np.polyfit(np.log([d for d, _ in fit]), np.log([e for _, e in fit]), 1)
                dt_equal = dt_ref * calls / 4
                # Only within the fitted rungs or above them: below, the fit would run into round-off.
                if dt_equal >= fit[-1][0]:
                    equal = float(np.exp(intercept + slope * np.log(dt_equal)))
            row["problems"][name] = {
                "dts": list(ladder),
                "errors": errors,
                "fitted_order": None if slope is None else float(slope),
                "rungs_fitted": len(fit),
                "dt_ref": dt_ref,
                "error_at_equal_calls": equal,
            }
            print(f"{name:12s} {label:52s} order {slope or 0:5.2f}  equal calls {equal or 0:.2e}  "
                  + " ".join(f"{e:.2e}" for e in errors), flush=True)  # fmt: skip
        rows.append(row)
    return rows


_REFERENCES = {}


def _reference(name, state, inertia, torque, args, t_end):
    if name not in _REFERENCES:
        ts = jnp.linspace(0.0, t_end, SAMPLES + 1)
        if torque is None:
            _REFERENCES[name] = analytic.free_top(state, inertia, ts).q
        else:
            _REFERENCES[name] = jaxrot.reference_rollout(
                state, inertia, ts, torque=torque, args=args, rtol=1e-14, atol=1e-14
            ).q
    return _REFERENCES[name]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", default=None, help="write the results file here")
    parser.add_argument("--quick", action="store_true", help="one problem, two rungs: a check that it runs")
    opts = parser.parse_args(argv)
    machine = machine_info()  # the commit as the run starts
    machine["mujoco"] = mujoco_available()
    rows = measure(opts.quick)
    if opts.json:
        with open(opts.json, "w") as f:
            json.dump({"machine": machine, "samples": SAMPLES + 1, "rows": rows}, f, indent=2)
            f.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
