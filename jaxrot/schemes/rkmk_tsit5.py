"""RKMK-Tsit5: diffrax's `Tsit5` tableau on SO(3) × R³, order 5 with an embedded error estimate."""

from typing import ClassVar

import diffrax

from ._lie_runge_kutta import AbstractLieRungeKutta


class RKMKTsit5(AbstractLieRungeKutta):
    """Runge–Kutta–Munthe-Kaas with diffrax's `Tsit5` tableau: order 5, embedded error estimate.

    The tableau is read from `diffrax.Tsit5.tableau`, not retyped. For a fixed step the
    stages after the last nonzero solution weight are skipped, so a step calls the
    torque ``torque_evals_per_step`` times; `step_with_error` evaluates them all.

    Reference: C. Tsitouras, Comput. Math. Appl. 62, 770–775 (2011);
    H. Munthe-Kaas, BIT 38, 92–111 (1998).

    Example:
        >>> import jax.numpy as jnp, jaxrot
        >>> s = jaxrot.RotState(jnp.array([1.0, 0, 0, 0]), jnp.array([0.3, 1.0, 0.2]))
        >>> traj = jaxrot.rollout("rkmk_tsit5", s, jnp.array([1.0, 2.0, 3.0]), 0.05, 100)
        >>> print(traj.q.shape, jaxrot.SCHEMES["rkmk_tsit5"].torque_evals_per_step)
        (101, 4) 6
    """

    name: ClassVar[str] = "rkmk_tsit5"
    order: ClassVar[int] = 5
    tableau: ClassVar[diffrax.ButcherTableau] = diffrax.Tsit5.tableau
    has_error_estimate: ClassVar[bool] = True
