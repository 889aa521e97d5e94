"""The fast free rotor (`jaxrot._free_body._rotor.free_rotor`) against the exact one and a Zhao step.

1. Cost per particle-step (ns) at N bodies (default 10⁴, I = (1, 2, 3), random orientations,
   |ω| t = 0.3 per call), float64 and float32: `free_rotor`, `jaxrot.analytic.free_motion`, and
   one `"zhao"` step without torque, each iterated in one compiled `fori_loop` over the vmapped
   bodies, median of repeats (`jaxrot.comparison.time_compiled`), and the ratios to Zhao.
2. What the rotor's per-body step count costs against a fixed two where both take two (the
   common range, |ω| t = 0.3): the rotor and the "splitting" step, same-run interleaved ratios.
3. Error against `free_motion` (largest orientation angle and ω component, random states with
   |ω| = 1, several bodies) over |ω| t up to 10, for the default count, a fixed two, one, float32.
4. Drift of |L| and of the energy over 10⁴ calls (64 bodies, |ω| t = 0.05, float32 and float64)
   with the principal-frame round trip a splitting makes between calls, rotor against free_motion.

5. With ``--against REV``: the rotor of git revision REV imported beside this one, forward calls and
   gradients (in the moments) at |ω| t = 0.3, 0.9, 2.9, interleaved in one process.

    python benchmarks/rotor.py                 # a few minutes on 2 cores
    python benchmarks/rotor.py --n 1000 --no-drift
    python benchmarks/rotor.py --against 95050c5 --no-drift
    python benchmarks/rotor.py --choice-only --rounds 61 --json docs/rotor_choice_cpu.json  # 2. alone
"""

import argparse
import importlib.util
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time

import jax


jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np

import jaxrot
from jaxrot import analytic, quaternion as quat
from jaxrot._free_body._rotor import free_rotor
from jaxrot.comparison import machine_info, time_compiled


DTYPES = {"float64": jnp.float64, "float32": jnp.float32}
MOMENTS = (1.0, 2.0, 3.0)
BODIES = ((1.0, 2.0, 3.0), (1.0, 1.0, 1.9), (0.1, 1.0, 1.05), (1.0, 1.0, 1.0), (1e-3, 1.0, 1.0))
ANGLES = (0.05, 0.1, 0.2, 0.3, 0.5, 0.6, 0.8, 1.0, 1.5, 1.9, 2.5, 5.0, 10.0)


def header():
    device = jax.devices()[0]
    return (
        f"machine: {platform.platform()}, {platform.processor() or platform.machine()}, "
        f"{os.cpu_count()} CPU(s); device {device.platform} ({device.device_kind}); "
        f"python {platform.python_version()}, jax {jax.__version__}, jaxrot {jaxrot.__version__}"
    )


def random_states(n, dtype, seed=0):
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(n, 4))
    w = rng.normal(size=(n, 3))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    w /= np.linalg.norm(w, axis=1, keepdims=True)
    return jnp.asarray(q, dtype), jnp.asarray(w, dtype)


def cost_table(n, repeats):
    zhao = jaxrot.SCHEMES["zhao"]
    lines = [
        "| dtype | free_rotor [ns] | free_motion [ns] | zhao step [ns] | free_rotor / zhao "
        "| free_motion / zhao |",
        "|---|---|---|---|---|---|",
    ]
    for name, dtype in DTYPES.items():
        q, w = random_states(n, dtype)
        moments = jnp.asarray(MOMENTS, dtype)
        dt = jnp.asarray(0.3, dtype)
        methods = {
            "free_rotor": (lambda q, w, m=moments, dt=dt: free_rotor(q, w, m, dt), 100),
            "free_motion": (lambda q, w, m=moments, dt=dt: analytic.free_motion(q, w, m, dt), 4),
            "zhao": (
                lambda q, w, m=moments, dt=dt: tuple(
                    zhao.step(jaxrot.RotState(q, w), 0.0, dt, m, None, None)
                ),
                100,
            ),
        }
        ns = {}
        for label, (one, steps) in methods.items():

            def run(state, one=one, steps=steps):
                return jax.lax.fori_loop(0, steps, lambda i, s: jax.vmap(one)(*s), state)

            _, _, seconds = time_compiled(run, (q, w), repeats)
            ns[label] = seconds / (n * steps) * 1e9
        cells = [f"{ns[k]:.1f}" for k in methods] + [
            f"{ns['free_rotor'] / ns['zhao']:.2f}",
            f"{ns['free_motion'] / ns['zhao']:.1f}",
        ]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def error_table(n_states=200):
    q, w = random_states(n_states, jnp.float64, seed=1)
    exact = jax.jit(jax.vmap(analytic.free_motion, in_axes=(0, 0, None, None)))

    def steps(n):  # None: the rotor's default
        return jax.vmap(lambda *a: free_rotor(*a, substeps=n), in_axes=(0, 0, None, None))

    variants = {
        "default (⌈|ω|t / 0.2⌉ steps, at least 2), float64": (steps(None), jnp.float64),
        "2 steps (fixed), float64": (steps(2), jnp.float64),
        "1 step, float64": (steps(1), jnp.float64),
        "default (⌈|ω|t / 0.5⌉ steps, at least 2), float32": (steps(None), jnp.float32),
    }
    lines = []
    for label, (fn, dtype) in variants.items():
        fn = jax.jit(fn)
        lines.append(f"\n{label}: largest error against free_motion (float64), rad / rad per unit time")
        lines.append("| body | " + " | ".join(f"{a:g}" for a in ANGLES) + " |")
        lines.append("|---|" + "---|" * len(ANGLES))
        for body in BODIES:
            moments = jnp.asarray(body)
            cells = []
            for angle in ANGLES:
                ref = exact(q, w, moments, angle)
                out = fn(q.astype(dtype), w.astype(dtype), moments.astype(dtype), jnp.asarray(angle, dtype))
                out = tuple(np.asarray(a, np.float64) for a in out)
                if np.any(np.isnan(out[0])):
                    cells.append("NaN")
                    continue
                err = max(
                    float(jnp.max(quat.angle_between(jnp.asarray(out[0]), ref[0]))),
                    float(np.max(np.abs(out[1] - np.asarray(ref[1])))),
                )
                cells.append(f"{err:.0e}")
            lines.append(f"| {body} | " + " | ".join(cells) + " |")
    lines.append("(|ω| = 1, so the columns are |ω| t; NaN: outside the valid range, see _free_body/_rotor)")
    return "\n".join(lines)


def drift(fn, dtype, n_calls=10_000, n_bodies=64):
    moments = jnp.asarray(MOMENTS, dtype)
    r = quat.exp(jnp.array([0.4, -0.7, 0.25], dtype))
    q, w = random_states(n_bodies, dtype, seed=3)
    step = jax.vmap(lambda q, w: fn(q, w, moments, jnp.asarray(0.05, dtype)))

    @jax.jit
    def run(q, w):
        def body(carry, _):
            q, w = step(*carry)
            return (quat.multiply(quat.multiply(q, quat.conjugate(r)), r), w), None

        return jax.lax.scan(body, (q, w), None, length=n_calls)[0]

    def invariants(q, w):
        q, w, m = (np.asarray(a, np.float64) for a in (q, w, moments))
        q = q / np.linalg.norm(q, axis=-1, keepdims=True)
        u = np.asarray(quat.rotate(quat.conjugate(jnp.asarray(q)), jnp.asarray(w)))
        return np.linalg.norm(m * u, axis=-1), np.sum(m * u * u, axis=-1)

    (l0, e0), (l1, e1) = invariants(q, w), invariants(*run(q, w))
    dl, de = l1 / l0 - 1, e1 / e0 - 1
    return np.max(np.abs(dl)), np.mean(dl), np.max(np.abs(de)), np.mean(de)


def drift_table():
    lines = [
        "| dtype | method | max abs |L| drift | mean |L| drift | max abs E drift | mean E drift |",
        "|---|---|---|---|---|---|",
    ]
    for name, dtype in DTYPES.items():
        for label, fn in (("free_rotor", free_rotor), ("free_motion", analytic.free_motion)):
            cells = " | ".join(f"{x:.1e}" for x in drift(fn, dtype))
            lines.append(f"| {name} | {label} | {cells} |")
    return "\n".join(lines)


def interleaved(programs, args, rounds):
    """ns per body-call of each compiled program, timed round-robin: ``{key: [per round]}``.

    ``programs`` maps a key to ``(compiled, calls per run, bodies)``; every program runs once before
    the rounds (this VM's timings move ±5-10% between runs: only ratios within one run count).
    """
    samples = {key: [] for key in programs}
    for compiled, _, _ in programs.values():
        jax.block_until_ready(compiled(args))
    for _ in range(rounds):
        for key, (compiled, calls, bodies) in programs.items():
            start = time.perf_counter()
            jax.block_until_ready(compiled(args))
            samples[key].append((time.perf_counter() - start) / (calls * bodies) * 1e9)
    return samples


def choice_cost_table(n, rounds):
    """The per-body step count against a fixed two (the rotor before), at |ω| t = 0.3 where both take
    two steps: the rotor alone and the `"splitting"` step (torque-free and a heavy top), every
    variant compiled first, then timed round-robin over ``rounds`` rounds (this VM's timings move
    ±5-10% between runs: only same-run interleaved ratios count, so the ratio is taken per round
    and its median and quartiles reported)."""
    from jaxrot.schemes.splitting import Splitting

    lines = [
        "| dtype | program | fixed 2 [ns] | per body [ns] | per body / fixed 2, per round: median (IQR) |",
        "|---|---|---|---|---|",
    ]
    rows = []
    for name, dtype in DTYPES.items():
        q, w = random_states(n, dtype)
        moments = jnp.asarray(MOMENTS, dtype)
        dt = jnp.asarray(0.3, dtype)
        arm, down = jnp.asarray([0.0, 0.0, 0.5], dtype), jnp.asarray([0.0, 0.0, -1.0], dtype)

        def gravity(t, q, w, a, arm=arm, down=down):
            return jnp.cross(quat.rotate(q, arm), down)

        programs = {}
        for label, sub in (("fixed 2", 2), ("per body", None)):
            scheme = Splitting(rotor_substeps=sub)

            def rotor(s, sub=sub, moments=moments, dt=dt):
                one = jax.vmap(lambda a, b: free_rotor(a, b, moments, dt, substeps=sub))
                return jax.lax.fori_loop(0, 100, lambda i, s: one(*s), s)

            def free(s, scheme=scheme, moments=moments, dt=dt):
                return jaxrot.rollout(scheme, jaxrot.RotState(*s), moments, dt, 100, save_every=100).q[-1]

            def top(s, scheme=scheme, moments=moments, dt=dt, gravity=gravity):
                state = jaxrot.RotState(*s)
                return jaxrot.rollout(scheme, state, moments, dt, 100, torque=gravity, save_every=100).q[-1]

            for program, fn in (
                ("rotor", rotor),
                ("splitting, torque-free", free),
                ("splitting, heavy top", top),
            ):
                programs[program, label] = (jax.jit(fn).lower((q, w)).compile(), 100, n)
        samples = interleaved(programs, (q, w), rounds)
        for program in ("rotor", "splitting, torque-free", "splitting, heavy top"):
            fixed, chosen = (statistics.median(samples[program, label]) for label in ("fixed 2", "per body"))
            ratios = np.asarray(samples[program, "per body"]) / np.asarray(samples[program, "fixed 2"])
            q1, q2, q3 = np.percentile(ratios, (25, 50, 75))
            lines.append(
                f"| {name} | {program} | {fixed:.1f} | {chosen:.1f} | {q2:.3f} ({q1:.3f}-{q3:.3f}) |"
            )
            rows.append(
                {
                    "dtype": name,
                    "program": program,
                    "fixed_2_ns": fixed,
                    "per_body_ns": chosen,
                    "ratio_quartiles": [float(q1), float(q2), float(q3)],
                }
            )
    return "\n".join(lines), rows


def rotor_at(rev):
    """`free_rotor` of git revision ``rev``, imported as a module of the package (its relative imports
    resolve against this checkout's `jaxrot`)."""
    source = subprocess.run(
        ["git", "show", f"{rev}:jaxrot/_free_body/_rotor.py"], capture_output=True, text=True, check=True
    ).stdout
    path = os.path.join(tempfile.mkdtemp(), "_rotor_rev.py")
    with open(path, "w") as f:
        f.write(source)
    spec = importlib.util.spec_from_file_location("jaxrot._free_body._rotor_rev", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.free_rotor


def against_table(rev, n, rounds=9, calls=20):
    """This checkout's rotor against revision ``rev``'s: ns per body-call, forward (``calls`` vmapped
    calls in a `fori_loop`) and the gradient of a sum of outputs in the moments, interleaved."""
    rotors = {"this": free_rotor, rev: rotor_at(rev)}
    medians = {}
    for name, dtype in DTYPES.items():
        programs = {}
        q, w = random_states(n, dtype)
        moments = jnp.asarray(MOMENTS, dtype)
        for turn in (0.3, 0.9, 2.9):  # |ω| = 1; away from the count rule's steps (0.2 and 0.5 rad)
            dt = jnp.asarray(turn, dtype)
            for label, rotor in rotors.items():

                def forward(s, rotor=rotor, moments=moments, dt=dt):
                    one = jax.vmap(lambda a, b: rotor(a, b, moments, dt))
                    return jax.lax.fori_loop(0, calls, lambda i, s: one(*s), s)

                def gradient(s, rotor=rotor, moments=moments, dt=dt):
                    def loss(m):
                        out = jax.vmap(lambda a, b: rotor(a, b, m, dt))(*s)
                        return jnp.sum(out[0][:, 1]) + jnp.sum(out[1])

                    return jax.grad(loss)(moments)

                programs[turn, "forward", label] = (jax.jit(forward).lower((q, w)).compile(), calls, n)
                programs[turn, "gradient", label] = (jax.jit(gradient).lower((q, w)).compile(), 1, n)
        for key, values in interleaved(programs, (q, w), rounds).items():
            medians[(name, *key)] = statistics.median(values)
    lines = [
        f"| dtype | |ω| t | program | {rev} [ns] | this [ns] | this / {rev} |",
        "|---|---|---|---|---|---|",
    ]
    for name in DTYPES:
        for turn in (0.3, 0.9, 2.9):
            for program in ("forward", "gradient"):
                old, new = medians[name, turn, program, rev], medians[name, turn, program, "this"]
                lines.append(f"| {name} | {turn} | {program} | {old:.1f} | {new:.1f} | {new / old:.3f} |")
    return "\n".join(lines)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--n", type=int, default=10_000, help="bodies for the cost table")
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--no-drift", action="store_true", help="skip the 10^4-call drift table")
    parser.add_argument("--rounds", type=int, default=31, help="interleaved rounds of the choice-cost table")
    parser.add_argument(
        "--against", metavar="REV", help="also time the rotor of git revision REV beside this one"
    )
    parser.add_argument("--choice-only", action="store_true", help="only the choice-cost table (2.)")
    parser.add_argument("--json", default=None, help="write the choice-cost table's rows here")
    ns = parser.parse_args(argv)
    print(header())
    if not ns.choice_only:
        print(f"\nCost per particle-step, N = {ns.n}, I = {MOMENTS}, |ω| t = 0.3, median of {ns.repeats}")
        print(cost_table(ns.n, ns.repeats))
    print(
        f"\nWhat the per-body step count costs at |ω| t = 0.3 (both take two steps), N = {ns.n}, "
        f"median of {ns.rounds} interleaved rounds"
    )
    text, rows = choice_cost_table(ns.n, ns.rounds)
    print(text)
    if ns.json:
        info = machine_info()
        with open(ns.json, "w") as f:
            json.dump({"machine": info, "n": ns.n, "rounds": ns.rounds, "rows": rows}, f, indent=1)
    if ns.choice_only:
        return 0
    if ns.against:
        print(f"\nThis rotor against {ns.against}'s, N = {ns.n}, median of 9 interleaved rounds")
        print(against_table(ns.against, ns.n))
    print(error_table())
    if not ns.no_drift:
        print("\nRelative drift over 10^4 calls (|ω| t = 0.05, 64 bodies, principal-frame round trip)")
        print(drift_table())
    return 0


if __name__ == "__main__":
    sys.exit(main())
