"""RKMK4: the classical fourth-order Runge–Kutta tableau on SO(3) × R³."""

from typing import ClassVar

import diffrax
import numpy as np

from ._lie_runge_kutta import AbstractLieRungeKutta


# diffrax ships no classical RK4; its ButcherTableau validates the coefficients (Σa = c, Σb = 1).
_RK4 = diffrax.ButcherTableau(
    c=np.array([0.5, 0.5, 1.0]),
    b_sol=np.array([1 / 6, 1 / 3, 1 / 3, 1 / 6]),
    b_error=np.zeros(4),
    a_lower=(np.array([0.5]), np.array([0.0, 0.5]), np.array([0.0, 0.0, 1.0])),
)


class RKMK4(AbstractLieRungeKutta):
    """Runge–Kutta–Munthe-Kaas with the classical RK4 tableau: order 4, four torque calls per step.

    Reference: H. Munthe-Kaas, BIT 38, 92–111 (1998); Kutta (1901).

    Example:
        >>> import jax.numpy as jnp, jaxrot
        >>> s = jaxrot.RotState(jnp.array([1.0, 0, 0, 0]), jnp.array([0.3, 1.0, 0.2]))
        >>> traj = jaxrot.rollout("rkmk4", s, jnp.array([1.0, 2.0, 3.0]), 0.05, 100)
        >>> print(traj.q.shape, jaxrot.SCHEMES["rkmk4"].torque_evals_per_step)
        (101, 4) 4
    """

    name: ClassVar[str] = "rkmk4"
    order: ClassVar[int] = 4
    tableau: ClassVar[diffrax.ButcherTableau] = _RK4
