"""A top's inertia about its pivot and about its centre of mass: the parallel-axis theorem, checked.

A heavy top is integrated with its inertia about the fixed pivot (Euler's equations about a fixed
point), but a body is specified, and can exist or not, by its inertia about the centre of mass. The
two differ by ``m(|r|²𝟙 − r rᵀ)`` (mass ``m``, offset ``r`` from the pivot to the centre of mass, body
frame), so a pivot inertia, a mass and an offset chosen apart may describe no body at all.
`pivot_inertia` builds the pivot tensor from a central inertia; `central_inertia` goes back and
refuses (``ValueError``, before anything compiles) a central inertia that is not positive definite or
breaks the triangle inequality. Kept apart from `jaxrot._inertia`, which the integrators run.
"""

import jax.numpy as jnp
import numpy as np

from ._core._checks import is_concrete
from ._inertia import check_inertia_values, triangle_tolerance


def _tensor(inertia, xp):
    """Principal moments ``(..., 3)`` as diagonal tensors ``(..., 3, 3)``; tensors unchanged."""
    if inertia.shape[-2:] == (3, 3):
        return inertia
    return inertia[..., :, None] * xp.eye(3, dtype=inertia.dtype)


def _parallel_axis(mass, offset, xp):
    """``m (|r|² 𝟙 − r rᵀ)`` ``(..., 3, 3)``: what moving the axes from the centre of mass to a pivot at
    ``−r`` from it adds to the inertia (parallel-axis theorem)."""
    mass = xp.asarray(mass)[..., None, None]
    square = xp.sum(offset * offset, axis=-1)[..., None, None]
    return mass * (square * xp.eye(3, dtype=offset.dtype) - offset[..., :, None] * offset[..., None, :])


def _check_mass_offset(mass, offset, names):
    mass_name, offset_name = names
    mass_np, offset_np = np.asarray(mass, np.float64), np.asarray(offset, np.float64)
    if not (np.all(np.isfinite(mass_np)) and np.all(mass_np > 0)):
        raise ValueError(f"`{mass_name}` must be a finite mass > 0 (kg); got {mass_np}.")
    if offset_np.shape[-1:] != (3,) or not np.all(np.isfinite(offset_np)):
        raise ValueError(
            f"`{offset_name}` must be a finite body-frame vector (3,) (m), pivot -> centre of mass; "
            f"got shape {offset_np.shape}."
        )
    return mass_np, offset_np


def pivot_inertia(central, mass, offset):
    """The inertia about a pivot, from the inertia about the centre of mass (parallel-axis theorem).

    ``I_pivot = I_c + m (|r|² 𝟙 − r rᵀ)``, all in the body frame: ``central`` principal moments ``(3,)``
    (body axes = its principal axes) or a tensor ``(3, 3)`` about the centre of mass (kg m²), ``mass``
    ``m`` (kg), ``offset`` ``r`` ``(3,)`` (m) from the pivot to the centre of mass (the ``offset_body``
    of `jaxrot.torques.Gravity`). Returns the ``(3, 3)`` tensor about the pivot, the ``inertia`` of a
    rollout of a top on that pivot (Euler's equations about a fixed point use the inertia about it).
    It is diagonal only when ``r`` lies along a principal axis of ``central``; otherwise pass the tensor
    as it is, or turn the body frame to its principal axes (``jnp.linalg.eigh``) and the offset with it.
    Leading axes broadcast. Concrete inputs are checked first (``ValueError``): ``central`` must be a
    body that can exist (positive, the triangle inequality), ``mass`` > 0, ``offset`` finite.

    Example:
        >>> import jax.numpy as jnp, jaxrot
        >>> pivot = jaxrot.pivot_inertia(jnp.array([1.0, 2.0, 2.5]), 1.0, jnp.array([0.0, 0.0, 0.5]))
        >>> pivot.diagonal().tolist()
        [1.25, 2.25, 2.5]
    """
    xp = jnp
    if is_concrete(central, mass, offset):
        check_inertia_values(np.asarray(central, np.float64), "central")
        _check_mass_offset(mass, offset, ("mass", "offset"))
    central, offset = jnp.asarray(central), jnp.asarray(offset)
    dtype = jnp.result_type(central, offset, mass)
    central, offset = central.astype(dtype), offset.astype(dtype)
    return _tensor(central, xp) + _parallel_axis(jnp.asarray(mass, dtype), offset, xp)


def central_inertia(pivot, mass, offset, *, names=("pivot", "mass", "offset")):
    """The inertia about the centre of mass of a top given about its pivot; refuses a body that cannot exist.

    ``I_c = I_pivot − m (|r|² 𝟙 − r rᵀ)`` ``(3, 3)``, the inverse of `pivot_inertia` (same arguments,
    frames and units: body frame, kg m², kg, m). Moments about a pivot are not free: they exceed
    the central ones by the parallel-axis term, so a pivot inertia, a mass and an offset chosen apart
    can imply a central inertia that no mass distribution has (``(1, 2, 3)`` about a pivot with 1 kg at
    ``(0.1, 0.05, 0.3)`` m: central moments ``(0.907, 1.90, 2.99)``, ``I₁ + I₂ < I₃``). For concrete inputs
    a ``ValueError`` names the arguments and the fix when the central inertia is not positive definite
    or violates the triangle inequality beyond `triangle_tolerance`; ``names`` label the three arguments
    in that message. Under ``jit`` (traced inputs) it only computes.
    """
    pivot_name = names[0]
    if is_concrete(pivot, mass, offset):
        pivot_np = np.asarray(pivot, np.float64)
        check_inertia_values(pivot_np, pivot_name)
        mass_np, offset_np = _check_mass_offset(mass, offset, names[1:])
        central = _tensor(pivot_np, np) - _parallel_axis(mass_np, offset_np, np)
        moments = np.linalg.eigvalsh(central)
        slack = np.sum(moments, axis=-1) - 2 * np.max(moments, axis=-1)
        if np.any(moments <= 0) or np.any(slack + triangle_tolerance(moments) < 0):
            worst = np.unravel_index(np.argmin(np.minimum(slack, moments.min(-1))), slack.shape)
            shown = ", ".join(f"{m:.4g}" for m in moments[worst])
            problem = (
                "are not all positive"
                if np.any(moments[worst] <= 0)
                else (f"violate the triangle inequality I1 + I2 >= I3 by {-slack[worst]:.3g}")
            )
            raise ValueError(
                f"`{pivot_name}` about the pivot, `{names[1]}` and `{names[2]}` are not a body that can "
                f"exist: the central inertia they imply (`{pivot_name}` less the parallel-axis term "
                f"m(|r|^2 1 - r r^T)) has principal moments ({shown}), which {problem}. The moments "
                "about a pivot exceed those about the centre of mass by that term: build the pivot "
                "tensor from a physical central inertia with jaxrot.pivot_inertia(central, mass, "
                f"offset), or raise the pivot's smallest moments, or bring the centre of mass closer to "
                "the pivot."
            )
    pivot, offset = jnp.asarray(pivot), jnp.asarray(offset)
    dtype = jnp.result_type(pivot, offset, mass)
    pivot, offset = pivot.astype(dtype), offset.astype(dtype)
    return _tensor(pivot, jnp) - _parallel_axis(jnp.asarray(mass, dtype), offset, jnp)
