"""Body-frame inertia: principal moments ``(3,)`` or a full symmetric tensor ``(3, 3)``.

Both forms are first class. The form is a static property of the array's rank,
so the diagonal fast path compiles to elementwise products and the full form
to 3×3 matrix products with an inverse computed once, outside the time loop.
"""

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp


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
