"""The DMV steps of one body repeated: a while loop (on a GPU a static loop first) with our own batching rule
and a derivative rule that carries the steps' Jacobian (JAX cannot reverse-differentiate a while
loop). `jaxrot._free_body._rotor` chooses the counts; `LOOP_BATCH` sets the steps per iteration.
"""

import math

import jax
import jax.numpy as jnp
from jax import lax

from .._core._fusion import tracing_for_cpu
from ._dmv import _dmv_step


# The least DMV10 steps per call (`jaxrot._free_body._rotor`'s rule). The primal runs them in the while
# loop with the rest (traced for a GPU, with `LOOP_BATCH` > 1, a static loop before it); the derivative
# rule differentiates them as a static loop and carries the Jacobian of the rest.
_MIN_SUBSTEPS = 2
LOOP_BATCH = None
"""DMV steps per iteration of the rotor's while loop: ``None`` (default) is 1 when tracing for CPU
and `_GPU_LOOP_BATCH` otherwise; an int sets it. Private: benchmarks set it before anything is
traced, in a process of their own. On a GPU each while iteration is a few kernel launches and a
host read of the loop predicate, so with long flows (a race's few long steps) the rotor's cost is
that latency times the iterations, whatever the batch size; taking k steps per iteration divides
it by k. Each body's count beyond the first two steps is then rounded up to a multiple of k
(more, shorter DMV steps: never less accurate). On the CPU a body's extra steps cost compute, so
there it stays 1. Measured on an H200 (N = 1000, float64, dipole scene, `benchmarks/rotor_loop.py`,
docs/performance.md): 4 per iteration ran splitting, srkn6b and srkn14a 2.5×, 2.35×, 1.9× faster at
8 steps per run and cost at most 9% where a body needs one extra step and now takes four; 8 cost
20% there, 2 gained less (1.5-1.8× at 8 steps). On the CPU (N = 1000, 2 cores) 4 and 8 ranged
0.68-1.13×."""
_GPU_LOOP_BATCH = 4
# The primal's first steps inside the while loop (`_repeat`), not a static loop before it: one traced
# DMV step instead of two. Measured (jax 0.12, 2 cores at load ~8): the rotor's program 3,384 -> 2,522
# HLO ops (vmapped, float32), jax_md's 1000-step BAOAB loop 7,981 -> 7,041 and its XLA compile
# 11.3 -> 9.3 s (median of 3 interleaved); forward speed at N = 10⁴ 0.97-1.03x (wall), 0.98-1.04x
# (CPU), 11 interleaved rounds, |ω| t = 0.3 and 0.9, float64 and float32. False: the static loop.
_MERGED = True


def _loop_batch() -> int:
    if LOOP_BATCH is not None:
        return LOOP_BATCH
    return 1 if tracing_for_cpu() else _GPU_LOOP_BATCH


def _split(a):
    return tuple(a[..., k] for k in range(a.shape[-1]))


def _gather(group):
    """A state group of one body as an array: a tuple of scalar components stacked, an array as is."""
    return jnp.stack(group) if isinstance(group, tuple) else group


def _scatter(array, like):
    """`_gather` undone on the leading axis: back to components where ``like`` is a tuple."""
    return tuple(array[k] for k in range(len(like))) if isinstance(like, tuple) else array


def _repeat(step, n, state, params, *, first=0, batch=1, custom=True):
    """``step(params, state)`` applied ``first + n`` times to one body (``n`` a multiple of ``batch``).

    ``state`` is a tuple of groups, each a tuple of scalar components or an array; ``step`` sees
    each group as an array (components stacked). The ``first`` steps run in the while loop with the
    ``n`` more (its counter from ``-first``; with ``batch > 1`` a static loop before it). One body:
    a loop on its own count. Under `jax.vmap` (a custom rule, not
    JAX's): one loop over the batch with a scalar counter up to the largest count, each body's state
    kept once its own count is done, and every group component-major (the batch axis last, so the
    components of a tuple group are contiguous rows). JAX's rule counted per body, reduced the
    batched predicate in every iteration and carried ``(N, 4)`` rows that XLA:CPU transposed on the
    way in and out: the loop cost ~8% of a rotor call where no body entered it (|ω| t = 0.3,
    N = 10⁴). ``custom=False`` keeps JAX's rule (the derivative rule's Jacobian loop, where ours
    made gradients 9-18% slower). Each iteration of the while loop applies ``step`` ``batch``
    times (`LOOP_BATCH`).
    """

    def iterate(step_once, s):
        if batch == 1:
            return step_once(s)
        for _ in range(batch):
            # Unbarriered, XLA fused the chain of steps and recomputed each step in every consumer
            # (measured on the CPU: 30x slower at 8 per iteration).
            s = lax.optimization_barrier(step_once(s))
        return s

    def loops(step_once, n, s, top, mask):
        start = 0
        if first and batch == 1 and _MERGED:
            # The first steps in the while loop too (its counter from -first; n >= 0, so the mask
            # keeps them): one traced step instead of two, and a body in the common range runs
            # the loop's first two iterations instead of a static loop of two.
            start = -first
        elif first:
            s = lax.fori_loop(0, first, lambda _, s: step_once(s), s)

        def body(c):
            i, s = c
            new = iterate(step_once, s)
            if mask:  # bodies past their own count keep their state (n broadcasts on the last axis)
                new = jax.tree_util.tree_map(lambda a, b: jnp.where(i < n, a, b), new, s)
            return i + batch, new

        return lax.while_loop(lambda c: c[0] < top, body, (jnp.full((), start, n.dtype), s))[1]

    def run(n, state, params):
        s = loops(lambda s: step(params, s), n, tuple(map(_gather, state)), n, mask=False)
        return tuple(map(_scatter, s, state))

    if not custom:
        return run(n, state, params)
    run = jax.custom_batching.custom_vmap(run)

    @run.def_vmap
    def run_batched(axis_size, in_batched, n, state, params):
        n_batched, state_batched, params_batched = in_batched
        state = jax.tree_util.tree_map(
            lambda x, b: x if b else jnp.broadcast_to(x, (axis_size, *jnp.shape(x))), state, state_batched
        )
        # Tuple groups stack their (N,) components to (k, N); arrays move the batch axis last.
        s = tuple(_gather(g) if isinstance(g, tuple) else jnp.moveaxis(g, 0, -1) for g in state)
        params_axes = jax.tree_util.tree_map(lambda b: 0 if b else None, params_batched)
        step_all = jax.vmap(step, in_axes=(params_axes, -1), out_axes=-1)
        top = jnp.max(n) if n_batched else n
        s = loops(lambda s: step_all(params, s), n, s, top, mask=n_batched)
        out = tuple(
            _scatter(x, g) if isinstance(g, tuple) else jnp.moveaxis(x, -1, 0)
            for x, g in zip(s, state, strict=True)
        )
        return out, jax.tree_util.tree_map(lambda _: True, out)

    return run(n, state, params)


def _per_body(fn, batch, *args):
    """``fn`` of one body, mapped over the leading axes ``batch`` of ``args`` (leaves broadcast to them)."""
    if not batch:
        return fn(*args)
    size = math.prod(batch)

    def flatten(x):
        x = jnp.asarray(x)
        core = x.shape[len(batch) :] if x.ndim >= len(batch) and x.shape[: len(batch)] == batch else x.shape
        return jnp.broadcast_to(x, batch + core).reshape((size, *core))

    out = jax.vmap(fn)(*jax.tree_util.tree_map(flatten, args))
    return jax.tree_util.tree_map(lambda y: y.reshape(batch + y.shape[1:]), out)


def _step_with(p, fad, h):
    """One DMV step ``(q, m) → (q, m)`` on 4- and 3-tuples of components, parameters ``p``, ``fad``, ``h``."""
    g = 0.5 * h
    f = tuple(g * fi * pi for fi, pi in zip(fad, p, strict=True))
    return lambda s: _dmv_step(s[0], s[1], p, fad, f, g, g * g, h)


def _stacked_step(p, fad, h):
    """`_step_with` on the arrays ``q`` ``(…, 4)`` and ``m`` ``(…, 3)``: the form loops carry."""
    step = _step_with(p, fad, h)

    def stacked(carry):
        q, m = step((_split(carry[0]), _split(carry[1])))
        return jnp.stack(q, axis=-1), jnp.stack(m, axis=-1)

    return stacked


def _first_steps(q, m, p, fad, h):
    """The first `_MIN_SUBSTEPS` DMV steps of one body (``q`` ``(4,)``, ``m`` ``(3,)``), a static loop."""
    step = _stacked_step(p, fad, h)
    return lax.fori_loop(0, _MIN_SUBSTEPS, lambda _, carry: step(carry), (q, m))


def _primal_step(params, s):
    return _stacked_step(*params)(s)


@jax.custom_jvp
def _dmv_steps(q, m, p, fad, h, n):
    """``n >= _MIN_SUBSTEPS`` DMV steps of one body: component tuples ``q`` (4) and ``m`` (3) → the same.

    All in one while loop, which a body in the common range leaves after `_MIN_SUBSTEPS` iterations
    (`_repeat`; with `LOOP_BATCH` > 1 the first in a static loop before it). JAX cannot
    reverse-differentiate a while loop, so the derivative rule differentiates the first steps as a
    static loop and carries the extra steps' Jacobian as a value: the tangent is the static steps'
    derivative followed by a product with that Jacobian, which reverse mode can transpose (carrying
    the Jacobian through all the steps instead cut the rotor's gradient program from 10.8k to 6.5k
    HLO ops and its compile by a third, but ran its gradient 3x slower at |ω| t = 0.3).
    """
    return _repeat(
        _primal_step, n - _MIN_SUBSTEPS, (q, m), (p, fad, h), first=_MIN_SUBSTEPS, batch=_loop_batch()
    )


@_dmv_steps.defjvp
def _dmv_steps_jvp(primals, tangents):
    q, m, p, fad, h, n = primals
    dq, dm, dp, dfad, dh, _ = tangents
    s, ds = jax.jvp(
        _first_steps,
        (jnp.stack(q), jnp.stack(m), p, fad, h),
        (jnp.stack(dq), jnp.stack(dm), dp, dfad, dh),
    )
    state = jnp.concatenate(s)
    theta = jnp.stack((*p, *fad, h))
    z_tangent = jnp.concatenate([*ds, jnp.stack((*dp, *dfad, dh))])
    n_s, size = state.shape[0], state.shape[0] + theta.shape[0]

    def flat(z):
        step = _step_with(_split(z[n_s : n_s + 3]), _split(z[n_s + 3 : n_s + 6]), z[n_s + 6])
        q, m = step((_split(z[:4]), _split(z[4:n_s])))
        return jnp.stack(q + m)

    def with_value(z):
        value = flat(z)
        return value, value

    def step(theta, carry):
        state, jac = carry  # (7,) and its Jacobian in (state, θ) after the first steps, (7, 14)
        # ∂ step / ∂ (state, θ): (7, 14), and the step's value from the same trace (jacfwd's primal).
        d, state = jax.jacfwd(with_value, has_aux=True)(jnp.concatenate([state, theta]))
        jac = d[:, :n_s] @ jac + jnp.concatenate([jnp.zeros_like(d[:, :n_s]), d[:, n_s:]], axis=1)
        return state, jac

    state, jac = _repeat(
        step,
        n - _MIN_SUBSTEPS,
        (state, jnp.eye(n_s, size, dtype=state.dtype)),
        theta,
        batch=_loop_batch(),
        custom=False,
    )
    d_state = jac @ z_tangent
    return (_split(state[:4]), _split(state[4:])), (_split(d_state[:4]), _split(d_state[4:]))
