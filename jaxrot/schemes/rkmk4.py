"""RKMK4: the classical fourth-order Runge–Kutta tableau on SO(3) × R³."""

from typing import ClassVar

import diffrax
import equinox as eqx
import numpy as np

from ._lie_runge_kutta import AbstractLieRungeKutta
from ._overdamped import OverdampedRKMK4


# diffrax ships no classical RK4; its ButcherTableau validates the coefficients (Σa = c, Σb = 1).
_RK4 = diffrax.ButcherTableau(
    c=np.array([0.5, 0.5, 1.0]),
    b_sol=np.array([1 / 6, 1 / 3, 1 / 3, 1 / 6]),
    b_error=np.zeros(4),
    a_lower=(np.array([0.5]), np.array([0.0, 0.5]), np.array([0.0, 0.0, 1.0])),
)


class RKMK4(AbstractLieRungeKutta):
    """Runge–Kutta–Munthe-Kaas with the classical RK4 tableau: order 4, four torque calls per step.

    The tableau advances the **body** angular momentum ``m = I ω_b`` (Euler's equations) beside the
    rotation (``momentum_frame="body"``; `jaxrot.schemes.AbstractLieRungeKutta`), the form of
    MuJoCo 4.0's ``RK4`` integrator on a free joint, which it reproduces to round-off. A free
    body's ``m`` then evolves independently of the stage orientations; measured
    (``benchmarks/order4.py``, errors at equal steps), 2.6× (intermediate-axis flip), 8.4×
    (tumbling body) and 11× (heavy top) smaller errors than with the world momentum ``L``, whose
    stage velocities ``R_i I⁻¹ R_iᵀ L`` inherit the stage orientations' errors. World ``L`` is then
    kept to the method's order rather than exactly; ``RKMK4(momentum_frame="world")`` keeps it
    exactly (the scheme before).

    The same name integrates the overdamped model (`jaxrot.overdamped_rollout`, its default at
    kT = 0): the tableau then advances the orientation alone (`overdamped`).

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
    models: ClassVar[frozenset[str]] = frozenset({"vacuum", "overdamped"})
    tableau: ClassVar[diffrax.ButcherTableau] = _RK4
    momentum_frame: str = eqx.field(default="body", static=True)

    def overdamped(self) -> OverdampedRKMK4:
        """The same tableau on the orientation alone, for `jaxrot.overdamped_rollout` (the overdamped
        model, no inertia), in this scheme's ``chart``."""
        return OverdampedRKMK4(chart=self.chart)
