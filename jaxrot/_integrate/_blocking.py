"""Cache blocking: independent bodies advanced one block at a time, each block through every step.

A step reads and writes every stage of every body. For N = 10⁶ in float64 those
stages are megabytes each and live in DRAM: the Zhao step ran at 15–17 million
particle-steps per second on 2 cores, against 40 M/s at N = 10⁴. When no torque
couples the bodies, the order of the two loops is free: `rollout` then (on CPU, `on_cpu`) splits the
bodies into blocks of about `BLOCK_BODIES` and runs the whole time loop on one
block before the next (``lax.map`` over blocks), so a block's stages stay in cache:
39 M/s at N = 10⁶ (100 blocks of 10⁴ bodies; no_squish 16 → 29 M/s). Each body
does the same arithmetic as unblocked; the results are bit for bit the same for
every scheme but ``"splitting"`` (a few ulp), and so are gradients, up to the order
of the sum over bodies for a shared parameter (``tests/test_blocking.py``).

Body ``b·n_blocks + i`` goes to block ``i``: a strided split, so that particle
arrays sharded over devices along their body axis stay sharded along the
in-block axis and no device needs another's bodies (`n_blocks_for` picks a
count that divides each device's share).
"""

import equinox as eqx
import jax
import jax.numpy as jnp

from .._particles import PARTICLES


BLOCK_BODIES = 16384
# Blocks of a multiple of this many bodies (8 float64 in an AVX-512 register): at N = 10⁶, 64 blocks of
# 15625 ran the Zhao step at 27 M/s, 100 blocks of 10000 at 39 M/s (blocks of 5000 to 62500: 37-40).
LANES = 8


def on_cpu(x) -> bool:
    """Whether ``x`` lives on (or, traced, will be computed on) CPU devices.

    Blocking pays on CPU, where a block's stages fit in cache; a GPU needs every body at once to
    fill its cores: with blocks of 16384 bodies, 10⁷ bodies ran 611 blocks one after another and
    one throughput row on an H100 did not finish in minutes.
    """
    try:
        return all(device.platform == "cpu" for device in x.devices())
    except jax.errors.ConcretizationTypeError:
        return jax.default_backend() == "cpu"


def n_blocks_for(n: int, block: int | None = None, shards: int = 1) -> int:
    """How many blocks to split ``n`` bodies into: 1 (no blocking) below two blocks' worth.

    Prefers a count within a factor 2 of ``n / block`` that divides ``n`` (no padding)
    into blocks of a multiple of `LANES` bodies, then any divisor, then pads. With the
    bodies sharded over ``shards`` devices, the count must divide each device's share
    (so that every block keeps each device's bodies on it), else 1.
    """
    block = BLOCK_BODIES if block is None else block
    if shards > 1:
        if n % shards:
            return 1
        n = n // shards
    if n < 2 * block:
        return 1
    fewest = -(-n // block)
    counts = range(fewest, 2 * fewest + 1)
    for aligned in (True, False):
        for count in counts:
            if n % count == 0 and (not aligned or (n // count) % LANES == 0):
                return count
    return 1 if shards > 1 else fewest


def to_blocks(x, n_blocks: int):
    """``(N, ...)`` → ``(n_blocks, ceil(N / n_blocks), ...)``, body ``b·n_blocks + i`` in block ``i``.

    Missing bodies are copies of the last one (valid states, discarded by `from_blocks`).
    """
    n = x.shape[0]
    per_block = -(-n // n_blocks)
    pad = per_block * n_blocks - n
    if pad:
        x = jnp.concatenate([x, jnp.broadcast_to(x[-1:], (pad, *x.shape[1:]))])
    return jnp.swapaxes(x.reshape(per_block, n_blocks, *x.shape[1:]), 0, 1)


def from_blocks(y, n: int, body_axis: int):
    """Inverse of `to_blocks` for a result with the block axis in front.

    ``y`` has shape ``(n_blocks, *before, per_block, ...)`` with the in-block body
    axis at ``body_axis`` (counted without the block axis); returns
    ``(*before, n, ...)``.
    """
    n_blocks = y.shape[0]
    y = jnp.moveaxis(y, 0, body_axis + 1)
    shape = y.shape
    merged = y.reshape(*shape[:body_axis], shape[body_axis] * n_blocks, *shape[body_axis + 2 :])
    return jax.lax.slice_in_dim(merged, 0, n, axis=body_axis)


def couples_bodies(torque, n: int, t, flat_state, args, args_axes) -> bool:
    """True when ``torque`` (for one body) communicates over the particle axis.

    Such a torque (`jaxrot.torques.DipoleInteraction`) needs all bodies at the
    same stage of the same step, so its rollout cannot be blocked. Decided by
    tracing ``torque`` once for one body (``(N, ...)`` inputs with axis 0 in
    ``args_axes`` sliced to one row), with the particle axis bound to its ``n``
    bodies, and looking for any collective or ``axis_index`` on it.
    """
    if torque is None:
        return False

    def abstract(x, per_body):
        return jax.ShapeDtypeStruct(x.shape[1:] if per_body else x.shape, x.dtype)

    leaves, treedef = jax.tree_util.tree_flatten(args)
    per_body = leaf_axes(args_axes, args)
    one_args = treedef.unflatten(
        [abstract(x, a == 0) if eqx.is_array(x) else x for x, a in zip(leaves, per_body, strict=True)]
    )
    dynamic, static = eqx.partition(one_args, lambda x: isinstance(x, jax.ShapeDtypeStruct))

    def one_body(t, q, omega, dynamic):
        return torque(t, q, omega, eqx.combine(dynamic, static))

    q, omega = (abstract(x, True) for x in flat_state)
    jaxpr = jax.make_jaxpr(one_body, axis_env=[(PARTICLES, n)])(abstract(t, False), q, omega, dynamic)
    return _mentions_axis(jaxpr.jaxpr)


def leaf_axes(axes, tree) -> list:
    """The ``vmap`` axis (0 or None) of each leaf of ``tree``, from ``axes``, a prefix tree of it."""
    out = []

    def record(axis, subtree):
        out.extend([axis] * len(jax.tree_util.tree_leaves(subtree)))

    jax.tree_util.tree_map(record, axes, tree, is_leaf=lambda x: x is None)
    return out


def map_blocks(fn, n_blocks: int, inputs: tuple, in_axes: tuple):
    """``fn(*inputs)`` block by block (``lax.map``): leaves with axis 0 in ``in_axes`` are split
    by `to_blocks`, the others are shared. Outputs come stacked, the block axis in front."""
    per_body = jax.tree_util.tree_structure(inputs).unflatten([a == 0 for a in leaf_axes(in_axes, inputs)])
    rows, shared = eqx.partition(inputs, per_body)
    blocked = jax.tree_util.tree_map(lambda x: to_blocks(x, n_blocks), rows)
    return jax.lax.map(lambda block: fn(*eqx.combine(block, shared)), blocked)


def _mentions_axis(jaxpr) -> bool:
    for eqn in jaxpr.eqns:
        for key, value in eqn.params.items():
            names = value if isinstance(value, tuple) else (value,)
            if key in ("axis_name", "axes") and PARTICLES in names:
                return True
            for sub in value if isinstance(value, (tuple, list)) else (value,):
                inner = getattr(sub, "jaxpr", sub)
                if hasattr(inner, "eqns") and _mentions_axis(inner):
                    return True
    return False
