"""Body-frame inertia: principal moments ``(3,)`` or a full symmetric tensor ``(3, 3)``.

Both forms are first class. The form is a static property of the array's rank,
so the diagonal fast path compiles to elementwise products and the full form
to 3×3 matrix products with an inverse computed once, outside the time loop.
"""

from typing import NamedTuple

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
