"""Whether an input's values can be read now: the gate of every eager check (a leaf module, so that
the quaternion algebra can check its own inputs without importing the rest of the validation)."""

import jax


def is_concrete(*xs) -> bool:
    """Whether every leaf can be read here: not a tracer, nor an array spread over several processes
    (a multi-process run's global array; its values live on other hosts, so its checks are skipped
    as under ``jit``)."""
    return not any(
        isinstance(leaf, jax.core.Tracer) or not getattr(leaf, "is_fully_addressable", True)
        for leaf in jax.tree_util.tree_leaves(xs)
    )
