"""ExpMidpoint: the exponential midpoint rule on SO(3) × R³, order 2 at any ζΔt/I."""

from typing import ClassVar

from ._exponential import AbstractExponentialLieRK
from ._exponential_tableau import ExponentialTableau


# The second-order method with c_2 = 1/2 (Hochbruck & Ostermann 2005, section 5.1): the weights
# integrate the line through the forcings at 0 and h/2 exactly; at z = 0 the midpoint rule.
_MIDPOINT = ExponentialTableau(
    c=(0.5,),
    a=({0: ((0.5, 1, 0.5),)},),
    b={0: ((1.0, 1, 1.0), (-2.0, 2, 1.0)), 1: ((2.0, 2, 1.0),)},
)


class ExpMidpoint(AbstractExponentialLieRK):
    """Exponential midpoint rule: order 2 at any ζΔt/I, two torque calls per step.

    The cheap fluid scheme (the ``"fluid"`` model: `jaxrot.rollout` with ``fluid=`` at ``kT = 0``;
    see `jaxrot.schemes.AbstractExponentialLieRK` and the module `jaxrot.schemes._exponential`):
    the friction's relaxation ``e^{−ζΔt/I}`` is exact, so no step is limited by ``I/ζ``; as
    ``ζΔt/I → ∞`` it becomes the Lie midpoint rule of the overdamped model.

    Reference: M. Hochbruck and A. Ostermann, "Explicit exponential Runge–Kutta methods for
    semilinear parabolic problems", SIAM J. Numer. Anal. 43, 1069–1090 (2005), section 5.1.

    Example:
        >>> import jax.numpy as jnp, jaxrot
        >>> fluid = jaxrot.Fluid(jnp.array([1e6, 1e6, 1e6]))  # ζ Δt / I = 1e4
        >>> s = jaxrot.RotState(jnp.array([1.0, 0, 0, 0]), jnp.array([0.0, 0, 5.0]))
        >>> traj = jaxrot.rollout("exp_midpoint", s, jnp.ones(3), 0.01, 3, fluid=fluid)
        >>> float(traj.omega[-1, 2])  # the spin is gone after one step
        0.0
    """

    name: ClassVar[str] = "exp_midpoint"
    order: ClassVar[int] = 2
    models: ClassVar[frozenset[str]] = frozenset({"fluid"})
    tableau: ClassVar[ExponentialTableau] = _MIDPOINT
