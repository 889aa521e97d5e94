"""Body-frame inertia: principal moments ``(3,)`` or a full symmetric tensor ``(3, 3)``.

Both forms are first class. The form is a static property of the array's rank,
so the diagonal fast path compiles to elementwise products and the full form
to 3×3 matrix products with an inverse computed once, outside the time loop.

The inertia's checks live here too: `check_inertia` (shapes, and for concrete values
`check_inertia_values` and `check_conditioning`: symmetric, positive definite, the triangle
inequality of a mass distribution within `triangle_tolerance`, resolvable in the dtype).
"""

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._core._checks import declared_dtype, is_concrete


class BodyInertia(NamedTuple):
    """An inertia and its inverse, both ``(3,)`` (principal moments) or ``(3, 3)``.

    Build it with `body_inertia`; schemes accept either this or a raw array.
    Units: mass × length². Frame: body, about the centre of mass (or the fixed
    point of a top).
    """

    tensor: jax.Array
    inverse: jax.Array

    @property
    def is_diagonal(self) -> bool:
        return self.tensor.ndim == 1

    def apply(self, v_body):
        """``I @ v`` for a body-frame vector ``(3,)``."""
        return self.tensor * v_body if self.is_diagonal else self.tensor @ v_body

    def solve(self, v_body):
        """``I⁻¹ @ v`` for a body-frame vector ``(3,)``."""
        return self.inverse * v_body if self.is_diagonal else self.inverse @ v_body

    def angular_acceleration(self, omega_body, torque_body=None):
        """Euler's equations in the body frame: ``I⁻¹ (τ_b − ω_b × I ω_b)``."""
        rate = -jnp.cross(omega_body, self.apply(omega_body))
        if torque_body is not None:
            rate = rate + torque_body
        return self.solve(rate)


def body_inertia(inertia) -> BodyInertia:
    """Wrap one body's inertia ``(3,)`` or ``(3, 3)`` with its inverse.

    Passing a `BodyInertia` returns it unchanged.
    """
    if isinstance(inertia, BodyInertia):
        return inertia
    inertia = jnp.asarray(inertia)
    if inertia.ndim == 1:
        return BodyInertia(inertia, 1 / inertia)
    return BodyInertia(inertia, jnp.linalg.inv(inertia))


def is_diagonal_form(inertia) -> bool:
    """True for principal moments ``(..., 3)``, False for tensors ``(..., 3, 3)``.

    A batch of three ``(3, 3)`` tensors has shape ``(3, 3, 3)``; the trailing
    two axes decide, so ``(..., 3, 3)`` is always read as tensors.
    """
    return not (inertia.ndim >= 2 and inertia.shape[-2:] == (3, 3))


class MathematicalBody(eqx.Module):
    """Opt-in for an inertia that no mass distribution has: integrate it anyway.

    Every real body satisfies the triangle inequality ``I₁ + I₂ ≥ I₃`` (for every permutation of its
    principal moments), and jaxrot rejects an inertia that violates it by more than the rounding of
    three significant digits. Mathematical test bodies may violate it on purpose (ACM TOMS Algorithm
    903 uses the moments (1, 1.0127, 3.3062)); wrap them in this class wherever an inertia is taken.
    Positive definiteness is still required. A pytree: it passes through ``jit`` as it is.

    Attributes:
        inertia: principal moments ``(..., 3)`` or tensors ``(..., 3, 3)``, as the unwrapped argument.

    Example:
        >>> import jax.numpy as jnp, jaxrot
        >>> body = jaxrot.MathematicalBody(jnp.array([1.0, 1.0127, 3.3062]))  # ACM TOMS 903
        >>> s = jaxrot.RotState(jnp.array([1.0, 0, 0, 0]), jnp.array([0.3, 1.0, 0.2]))
        >>> jaxrot.rollout("zhao", s, body, 0.01, 10).q.shape
        (11, 4)
    """

    inertia: jax.Array


def check_inertia(inertia, batch_shape, dtype, name="inertia", *, runtime=True):
    """Validate an inertia for particles with leading shape ``batch_shape``.

    Returns ``(inertia, per_particle)``; the accepted shapes, in the order they
    are matched, are ``batch + (3, 3)``, ``(3, 3)``, ``batch + (3,)``, ``(3,)``.
    A `jaxrot.MathematicalBody` is unwrapped and exempt from the triangle inequality.
    Concrete values are checked now (``ValueError``); a traced shared inertia, with ``runtime``,
    for the triangle inequality by the compiled program (the same tolerance, raised when it runs),
    so that a body is accepted or refused alike under ``jit`` and eagerly (a NumPy or Python
    constant is checked now, even inside ``jit``). A traced per-particle inertia is not: the check
    would be a reduction over all bodies, which a sharded rollout would communicate.
    """
    physical = not isinstance(inertia, MathematicalBody)
    if not physical:
        inertia = inertia.inertia
    declared_dtype(inertia, name)
    # A NumPy or Python constant is checked now even inside `jit` (where jnp.asarray traces it).
    concrete = is_concrete(inertia)
    raw = np.asarray(inertia, dtype=np.float64) if concrete else None
    inertia = jnp.asarray(inertia)
    batch_shape = tuple(batch_shape)
    shape = inertia.shape
    if shape == (*batch_shape, 3, 3) and batch_shape:
        per_particle = True
    elif shape == (3, 3) or shape == (3,):
        per_particle = False
    elif shape == (*batch_shape, 3):
        per_particle = True
    else:
        raise ValueError(
            f"`{name}` must be principal moments (3,) or a full body-frame tensor (3, 3), shared, "
            f"or one per particle with the particle axes {batch_shape} in front; got shape {shape}."
        )
    inertia = inertia.astype(dtype)
    if concrete:
        moments = check_inertia_values(raw, name, physical=physical)
        check_conditioning(moments, dtype, name)
    elif runtime and not per_particle:
        inertia = _checked_in_graph(inertia, name, physical)
    return inertia, per_particle


def triangle_tolerance(moments):
    """How far ``I₁ + I₂ − I₃`` may fall below zero for moments given to three significant digits.

    Inertias are quoted to at least three significant digits; each rounded moment is off by up to
    half a unit in its third digit, ``0.005 · 10^⌊log₁₀ I⌋``, so a planar body (``I₁ + I₂ = I₃``)
    can show a violation up to the sum of the three (Hairer & Vilmart's water molecule, (0.345, 0.653,
    1.0): 0.002 against 0.006). Works on NumPy and JAX arrays ``(..., 3)``; returns ``(...,)``.
    """
    xp = jnp if isinstance(moments, jax.Array) else np
    positive = xp.where(moments > 0, moments, 1)
    return xp.sum(0.005 * 10.0 ** xp.floor(xp.log10(positive)), axis=-1)


def _moments_of(inertia, xp):
    if inertia.shape[-2:] == (3, 3):
        return xp.linalg.eigvalsh(0.5 * (inertia + xp.swapaxes(inertia, -1, -2)))
    return inertia


def _not_physical_message(name, slack=None):
    by = "" if slack is None else f" by {slack:.3g},"
    return (
        f"`{name}` is not a physical body: it violates the triangle inequality I1 + I2 >= I3 (for "
        f"every permutation) that every mass distribution satisfies,{by} more than the "
        "rounding of three significant digits allows. Check the moments; to integrate a "
        "mathematical test body anyway, pass jaxrot.MathematicalBody(inertia)."
    )


def _checked_in_graph(inertia, name, physical):
    """``inertia`` with an `eqx.error_if` check of the triangle inequality within
    `triangle_tolerance` (if ``physical``), raised when the compiled program runs.

    Positive definiteness is not checked here: central differences of a needle's tiny moment step
    across zero, and the integrators themselves do not need it (they need 1/I)."""
    if not physical:
        return inertia
    moments = _moments_of(inertia, jnp)
    slack = jnp.sum(moments, axis=-1) - 2 * jnp.max(moments, axis=-1)
    return eqx.error_if(inertia, jnp.any(slack < -triangle_tolerance(moments)), _not_physical_message(name))


def check_inertia_values(inertia: np.ndarray, name="inertia", *, physical=True):
    if not np.all(np.isfinite(inertia)):
        raise ValueError(f"`{name}` contains NaN or infinite values.")
    if inertia.shape[-2:] == (3, 3):
        scale = np.max(np.abs(inertia), axis=(-2, -1), keepdims=True)
        asym = np.max(np.abs(inertia - np.swapaxes(inertia, -1, -2)) / np.where(scale > 0, scale, 1))
        if asym > 1e-6:
            raise ValueError(
                f"`{name}` must be a symmetric tensor; the largest relative asymmetry is {asym:.3g}. "
                "Pass (I + I.T) / 2 if the asymmetry is round-off."
            )
    moments = _moments_of(inertia, np)
    if np.any(moments <= 0):
        raise ValueError(
            f"`{name}` must be positive definite (every principal moment > 0); "
            f"the smallest principal moment is {float(np.min(moments)):.3g}."
        )
    if physical:
        # A real mass distribution has I_i + I_j >= I_k for every permutation (within rounding).
        slack = np.sum(moments, axis=-1) - 2 * np.max(moments, axis=-1)
        excess = slack + triangle_tolerance(moments)
        if np.any(excess < 0):
            raise ValueError(_not_physical_message(name, -float(np.min(slack))))
    return moments


def check_conditioning(moments: np.ndarray, dtype, name="inertia"):
    """Reject principal moments that ``dtype`` cannot resolve: smallest < eps × largest, or subnormal.

    Below that ratio the round-off of ``ω × Iω`` (≈ eps · largest moment) divided by the
    smallest moment swamps the motion about that axis: measured, zhao and euler return NaN
    within 10 steps for a needle (r, 1, 1) with r ≤ 1e-20 (float64) or r ≤ 1e-12 (float32),
    and a subnormal moment is flushed to zero on CPU and GPU.
    """
    info = np.finfo(dtype)
    smallest = float(np.min(moments))
    if smallest < float(info.tiny):
        raise ValueError(
            f"`{name}` has a principal moment of {smallest:.3g}, below the smallest normal "
            f"{np.dtype(dtype).name} ({float(info.tiny):.3g}); it would be flushed to zero. "
            "Rescale the units."
        )
    ratio = np.min(moments, axis=-1) / np.max(moments, axis=-1)
    if np.any(ratio < float(info.eps)):
        raise ValueError(
            f"`{name}` is too ill-conditioned for {np.dtype(dtype).name}: the smallest principal moment is "
            f"{float(np.min(ratio)):.3g} times the largest, below the resolution "
            f"eps = {float(info.eps):.3g}, so round-off would swamp the rotation about that axis. "
            + ("Check the moments." if info.bits == 64 else "Use float64, or check the moments.")
        )
