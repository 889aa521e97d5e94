"""How many kernels a throughput step launches on a GPU, and how far it is from one pass.

For each program of `benchmarks/throughput.py` (a `jaxrot.rollout` of N heavy tops, or jax_md's
NVE), writes the optimised HLO of the compiled program to ``--out`` and prints the kernels in its
loop body (fusions and other launches), the run time per particle-step, and what the card would
move per particle-step at ``--bandwidth`` in that time. Five floors are timed beside them in the same
process: ``copy``, a step that only rescales the state (one read and one write of q and ω),
``elementwise_exp``, one quaternion exponential per step (a full rotation's arithmetic), and
``soa_exp``, the same step on q and ω split into their components (structure of arrays),
``tuple_exp``, the same with the (N, 4) carry split into components and stacked again in every step, and
``cm_exp``, the same step with the particle axis last (carry ``(4, N)``, the per-body code vmapped
over the last axis). The ``cm_<scheme>`` programs run each scheme so (`component_major_run`), with the
largest difference of their final orientations from the original's in the row.

    python benchmarks/gpu_passes.py --n 10000000 --out /tmp/hlo
"""

import argparse
import json
import re
import sys
from pathlib import Path

import jax


jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
from throughput import DT, bodies, have_jax_md, jax_md_run, jaxrot_run

import jaxrot
from jaxrot import quaternion as quat
from jaxrot._core._math import taylor_threshold
from jaxrot._core._trig import sincos
from jaxrot._inertia import body_inertia
from jaxrot.comparison import machine_info, time_runs
from jaxrot.schemes import resolve_scheme


class _PaddedConcat:
    """``jax.numpy`` with `stack` and `concatenate` along the last axis written as sums of padded
    pieces (elementwise work XLA can fuse), everything else passed through: an experiment on how
    XLA:GPU fuses a step whose quaternion arithmetic assembles its results component by component."""

    def __getattr__(self, name):
        return getattr(jnp, name)

    def stack(self, arrays, axis=0):
        arrays = [jnp.asarray(a) for a in arrays]
        if axis in (-1, arrays[0].ndim):
            return self.concatenate([a[..., None] for a in arrays], axis=-1)
        return jnp.stack(arrays, axis=axis)

    def concatenate(self, arrays, axis=0):
        arrays = [jnp.asarray(a) for a in arrays]
        if axis not in (-1, arrays[0].ndim - 1):
            return jnp.concatenate(arrays, axis=axis)
        total = sum(a.shape[-1] for a in arrays)
        out, offset = 0, 0
        for a in arrays:
            width = a.shape[-1]
            out = out + jnp.pad(a, [(0, 0)] * (a.ndim - 1) + [(offset, total - offset - width)])
            offset += width
        return out


def pad_concatenations():
    """Route every jaxrot module's `jnp.stack`/`jnp.concatenate` through `_PaddedConcat`."""
    proxy = _PaddedConcat()
    for name, module in list(sys.modules.items()):
        if name.startswith("jaxrot") and getattr(module, "jnp", None) is jnp:
            module.jnp = proxy


def _soa_multiply(a, b):
    a0, a1, a2, a3 = a
    b0, b1, b2, b3 = b
    return (
        a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3,
        a0 * b1 + a1 * b0 + a2 * b3 - a3 * b2,
        a0 * b2 - a1 * b3 + a2 * b0 + a3 * b1,
        a0 * b3 + a1 * b2 - a2 * b1 + a3 * b0,
    )


def _soa_exp(v):
    """`quat.exp` on components: the same branches and kernels, no (N, 4) array."""
    x, y, z = v
    theta_sq = x * x + y * y + z * z
    use_taylor = theta_sq < taylor_threshold(x.dtype)
    theta = jnp.sqrt(jnp.where(use_taylor, 1, theta_sq))
    sin_half, cos_half = sincos(0.5 * theta)
    real = jnp.where(use_taylor, 1 - theta_sq / 8 + theta_sq**2 / 384, cos_half)
    factor = jnp.where(use_taylor, 0.5 - theta_sq / 48 + theta_sq**2 / 3840, sin_half / theta)
    return real, factor * x, factor * y, factor * z


def _soa_step(q, w):
    """`floor_run`'s exponential step with q and ω as tuples of (N,) components (structure of arrays)."""
    conj = (q[0], -q[1], -q[2], -q[3])
    w_body = _soa_multiply(_soa_multiply(conj, (jnp.zeros_like(q[0]), *w)), q)[1:]
    return _soa_multiply(q, _soa_exp(tuple(0.5e-3 * c for c in w_body)))


def floor_run(kind, n_steps):
    """A floor step: ``copy`` rescales q and ω; ``elementwise_exp`` turns q by ``exp(½ Δt ω_body)``
    with jaxrot's quaternion functions; ``soa_exp`` the same on components (q, ω split into (N,)
    arrays before the loop and stacked after it), to see whether that layout fuses into fewer kernels."""

    def step(_, s):
        q, w = s
        if kind == "copy":
            return q * 1.0000001, w * 0.9999999
        if kind == "soa_exp":
            return _soa_step(q, w), w
        if kind == "tuple_exp":  # (N, 4) carry, split into components and stacked again every step
            split = (tuple(q[:, i] for i in range(4)), tuple(w[:, i] for i in range(3)))
            return jnp.stack(_soa_step(*split), axis=-1), w
        one = lambda q, w: quat.multiply(q, quat.exp(0.5e-3 * quat.rotate(quat.conjugate(q), w)))  # noqa: E731
        if kind == "cm_exp":
            return jax.vmap(one, in_axes=-1, out_axes=-1)(q, w), w
        return one(q, w), w

    def run(state):
        if kind == "cm_exp":
            return jax.lax.fori_loop(0, n_steps, step, (state.q.T, state.omega.T))[0].T
        if kind == "soa_exp":
            split = (tuple(state.q[:, i] for i in range(4)), tuple(state.omega[:, i] for i in range(3)))
            return jnp.stack(jax.lax.fori_loop(0, n_steps, step, split)[0], axis=-1)
        return jax.lax.fori_loop(0, n_steps, step, (state.q, state.omega))[0]

    return run


def component_major_run(name, scene, n_steps):
    """A scheme's loop with the particle axis last: the carry ``(4, N)``, ``(3, N)``, … and the
    per-body step vmapped over that axis (``in_axes=-1``), so that a quaternion's components are
    rows, not ``(N, 1)`` columns; the same arithmetic per body as `jaxrot.rollout`."""
    scheme = resolve_scheme(name)
    inertia = body_inertia(scene.inertia)

    def run(state):
        carry = jax.vmap(lambda s: scheme.init(s, 0.0, inertia, scene.torque, scene.args))(state)
        carry = jax.tree_util.tree_map(lambda x: jnp.moveaxis(x, 0, -1), carry)

        def step_one(c, t):
            return scheme.step(c, t, DT, inertia, scene.torque, scene.args)

        step = jax.vmap(step_one, in_axes=(-1, None), out_axes=-1)
        carry = jax.lax.fori_loop(0, n_steps, lambda i, c: step(c, i * DT), carry)
        carry = jax.tree_util.tree_map(lambda x: jnp.moveaxis(x, -1, 0), carry)
        return jax.vmap(scheme.state)(carry).q

    return run


def kernels(hlo):
    """Kernel launches of the largest computation called by a while loop (the step), by kind."""
    bodies_ = re.findall(r"while\(.*?body=%?([\w.\-]+)", hlo)
    blocks = dict(re.findall(r"\n(?:ENTRY )?%?([\w.\-]+) [^\n]*\{\n(.*?)\n\}", hlo, flags=re.S))
    counts = {}
    for name in bodies_:
        text = blocks.get(name, "")
        c = {
            "fusion": len(re.findall(r"= [^\n]* fusion\(", text)),
            "custom-call": len(re.findall(r"custom-call\(", text)),
            "copy/transpose": len(re.findall(r"= [^\n]* (?:copy|transpose)\(", text)),
            "while": len(re.findall(r"while\(", text)),
            "instructions": text.count("\n") + 1,
        }
        if c["instructions"] > counts.get("instructions", 0):
            counts = c | {"body": name}
    return counts


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--n", type=int, default=10_000_000)
    p.add_argument("--steps", type=int, default=30)
    p.add_argument("--schemes", default="euler,zhao,no_squish,splitting")
    p.add_argument("--bandwidth", type=float, default=3.35e12, help="bytes/s of the card (H100 SXM: 3.35e12)")
    p.add_argument("--out", required=True)
    p.add_argument("--pad-concat", action="store_true", help="assemble vectors by padded sums (experiment)")
    ns = p.parse_args()
    if ns.pad_concat:
        pad_concatenations()
    out = Path(ns.out)
    out.mkdir(parents=True, exist_ok=True)
    state, scene = bodies(ns.n, jnp.float32)
    runs = {
        f"floor_{k}": floor_run(k, ns.steps)
        for k in ("copy", "elementwise_exp", "soa_exp", "tuple_exp", "cm_exp")
    }
    # cm_…: the same step with the particle axis last (component_major_run), checked against the original
    runs |= {s: jaxrot_run(s, scene, ns.steps) for s in ns.schemes.split(",")}
    runs |= {f"cm_{s}": component_major_run(s, scene, ns.steps) for s in ns.schemes.split(",")}
    if have_jax_md():
        runs["jax_md"] = jax_md_run(scene, ns.steps)
    rows, finals = [], {}
    print(machine_info())
    for name, run in runs.items():
        options = None if name == "jax_md" else jaxrot.compiler_options()
        compiled = jax.jit(run, compiler_options=options).lower(state).compile()
        hlo = compiled.as_text()
        (out / f"{name}.hlo.txt").write_text(hlo)
        final, seconds = time_runs(compiled, (state,), 5)
        finals[name] = final
        ns_per = seconds / (ns.n * ns.steps) * 1e9
        row = {
            "program": name,
            "ns_per_particle_step": ns_per,
            "bytes_at_bandwidth": ns_per * 1e-9 * ns.bandwidth,
        }
        row |= kernels(hlo)
        plain = name[3:] if name.startswith("cm_") else None
        twin = "floor_elementwise_exp" if name in ("floor_cm_exp", "floor_tuple_exp") else plain
        if twin in finals:
            row["max_abs_diff_vs_" + twin] = float(jnp.max(jnp.abs(final - finals[twin])))
        rows.append(row)
        print(json.dumps(row), flush=True)
    (out / "passes.json").write_text(
        json.dumps({"machine": machine_info(), "n": ns.n, "rows": rows}, indent=1)
    )


if __name__ == "__main__":
    main()
