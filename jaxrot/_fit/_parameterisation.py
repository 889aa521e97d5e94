"""The fit's parameters: a Cholesky-parameterised inertia tensor and the segment start states.

Every parameter vector gives a physical tensor (`inertia_from_cholesky`), so the
optimiser needs no constraints; `_flat`/`_unflat` turn the parameters into the
float64 vector the optimiser works on, and back.
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np


def inertia_from_cholesky(params, *, unit_trace: bool = False):
    r"""Inertia tensor ``(..., 3, 3)`` of the mass distribution with second moments ``S = L Lᵀ``.

    ``params`` ``(..., 6)`` = ``[L₀₀, L₁₁, L₂₂, L₁₀, L₂₀, L₂₁]`` fill a lower-triangular
    ``L``, so ``S = L Lᵀ`` (the body-frame second-moment matrix ``∫ρ r rᵀ dV``) is
    symmetric positive semidefinite, and

        ``I = tr(S) 𝟙 − S``.

    If ``S`` has eigenvalues ``s₁, s₂, s₃ ≥ 0`` along some axes, ``I`` has the same
    axes and moments ``s₂ + s₃, s₁ + s₃, s₁ + s₂``: every moment is ≥ 0 (> 0 unless
    ``S`` has rank one: a rod) and ``I₁ + I₂ − I₃ = 2 s₃ ≥ 0``, so the triangle
    inequality holds for every permutation. Conversely every physical tensor is
    reached (``S = ½ tr(I) 𝟙 − I``, then Cholesky; `cholesky_from_inertia`),
    including planar bodies on the boundary ``I₁ + I₂ = I₃`` (``s₃ = 0``, a finite
    parameter value; a log-diagonal would push them to infinity, which we
    measured to stall the fit). Nothing non-physical can come out of an
    optimiser step, and the map is a smooth polynomial, so gradients are finite
    everywhere.

    With ``unit_trace=True`` the tensor is divided by ``tr I = 2 tr S``: the
    scale-free form used for torque-free fits, where only ratios are determined.

    Example:
        >>> import jax.numpy as jnp
        >>> from jaxrot._fit import inertia_from_cholesky
        >>> inertia_from_cholesky(jnp.array([1.0, 1.0, 1.0, 0.0, 0.0, 0.0])).tolist()  # a sphere
        [[2.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 2.0]]
    """
    params = jnp.asarray(params)
    d = params[..., :3]
    zero = jnp.zeros_like(d[..., 0])
    lower = jnp.stack(
        [
            jnp.stack([d[..., 0], zero, zero], axis=-1),
            jnp.stack([params[..., 3], d[..., 1], zero], axis=-1),
            jnp.stack([params[..., 4], params[..., 5], d[..., 2]], axis=-1),
        ],
        axis=-2,
    )
    second = lower @ jnp.swapaxes(lower, -1, -2)
    trace = jnp.trace(second, axis1=-2, axis2=-1)[..., None, None]
    inertia = trace * jnp.broadcast_to(jnp.eye(3, dtype=second.dtype), second.shape) - second
    return inertia / (2 * trace) if unit_trace else inertia


def cholesky_from_inertia(inertia, *, floor: float = 1e-6):
    """Parameters ``(6,)`` of `inertia_from_cholesky` for a symmetric ``(3, 3)`` tensor (NumPy, eager).

    A tensor outside the physical set is projected onto it first: the
    eigenvalues of ``S = ½ tr(I) 𝟙 − I`` are raised to at least ``floor ×`` their
    largest (a tensor with a non-positive trace becomes a sphere).
    """
    inertia = np.asarray(inertia, dtype=np.float64)
    inertia = 0.5 * (inertia + inertia.T)
    second = 0.5 * np.trace(inertia) * np.eye(3) - inertia
    values, vectors = np.linalg.eigh(second)
    if not np.all(np.isfinite(values)) or np.trace(inertia) <= 0:
        values, vectors = np.ones(3), np.eye(3)
    values = np.maximum(values, floor * max(float(values.max()), np.finfo(np.float64).tiny))
    lower = np.linalg.cholesky(vectors @ np.diag(values) @ vectors.T)
    return np.array([*np.diag(lower), lower[1, 0], lower[2, 0], lower[2, 1]])


class _Params(NamedTuple):
    chol: jax.Array  # (6,)
    dq: jax.Array  # (K, 3) rotation-vector offsets of the segment starts from the observed q
    omega: jax.Array  # (K, 3) world-frame angular velocity at the segment starts


def _flat(params) -> np.ndarray:
    return np.concatenate([np.asarray(x, dtype=np.float64).reshape(-1) for x in params])


def _unflat(vector, like, dtype) -> _Params:
    out, i = [], 0
    for x in like:
        out.append(jnp.asarray(vector[i : i + x.size].reshape(x.shape), dtype))
        i += x.size
    return _Params(*out)
