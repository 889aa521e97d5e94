"""NaN-safe scalar helpers shared by the quaternion algebra and the schemes."""

import jax.numpy as jnp


def taylor_threshold(dtype) -> float:
    """Squared-angle threshold below which the Taylor branches are used.

    ``sqrt(eps)`` keeps the truncation error of a two-term series (~ x**3) below
    round-off while keeping the closed form away from its 0/0 point.
    """
    return float(jnp.finfo(dtype).eps) ** 0.5


def safe_norm(v, axis=-1, keepdims=False):
    """Euclidean norm whose gradient at ``v = 0`` is 0 instead of NaN.

    The double ``where`` keeps the NaN cotangent of ``sqrt`` at 0 out of the
    backward pass (JAX FAQ, "Gradients contain NaN where using where").
    """
    sq = jnp.sum(v * v, axis=axis, keepdims=keepdims)
    nonzero = sq > 0
    return jnp.where(nonzero, jnp.sqrt(jnp.where(nonzero, sq, 1)), 0)
