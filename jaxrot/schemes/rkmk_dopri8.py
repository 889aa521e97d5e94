"""RKMK-Dopri8: diffrax's `Dopri8` tableau on SO(3) × R³, order 8 with an embedded error estimate."""

from typing import Any, ClassVar

import diffrax

from ._lie_runge_kutta import AbstractLieRungeKutta


class RKMKDopri8(AbstractLieRungeKutta):
    """Runge–Kutta–Munthe-Kaas with diffrax's `Dopri8` tableau: order 8, embedded error estimate.

    The tableau is read from `diffrax.Dopri8.tableau`, not retyped. For a fixed step the
    stages after the last nonzero solution weight are skipped, so a step calls the
    torque ``torque_evals_per_step`` times; `step_with_error` evaluates them all.

    Reference: P. J. Prince and J. R. Dormand, J. Comput. Appl. Math. 7, 67–75 (1981);
    H. Munthe-Kaas, BIT 38, 92–111 (1998).

    Example:
        >>> import jax.numpy as jnp, jaxrot
        >>> s = jaxrot.RotState(jnp.array([1.0, 0, 0, 0]), jnp.array([0.3, 1.0, 0.2]))
        >>> traj = jaxrot.rollout("rkmk_dopri8", s, jnp.array([1.0, 2.0, 3.0]), 0.05, 100)
        >>> print(traj.q.shape, jaxrot.SCHEMES["rkmk_dopri8"].torque_evals_per_step)
        (101, 4) 13
    """

    name: ClassVar[str] = "rkmk_dopri8"
    order: ClassVar[int] = 8
    models: ClassVar[frozenset[str]] = frozenset({"vacuum"})
    tableau: ClassVar[diffrax.ButcherTableau] = diffrax.Dopri8.tableau
    has_error_estimate: ClassVar[bool] = True
    dense_output: ClassVar[Any] = diffrax.Dopri8.interpolation_cls
