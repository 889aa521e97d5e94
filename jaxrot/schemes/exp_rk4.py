"""ExpRK4: Hochbruck and Ostermann's five-stage exponential Runge–Kutta method, stiff order 4."""

from typing import ClassVar

from ._exponential import AbstractExponentialLieRK
from ._exponential_tableau import ExponentialTableau


def _scaled(terms, factor):
    return tuple((factor * c, k, node) for c, k, node in terms)


# Hochbruck & Ostermann (2005), eq. (5.19), in the φ_{j,k} = φ_j(c_k z) notation of the Expint
# package's hochost4.m; c = (0, 1/2, 1/2, 1, 1/2).
_A52 = ((0.5, 2, 0.5), (-1.0, 3, 1.0), (0.25, 2, 1.0), (-0.5, 3, 0.5))
_A54 = ((0.25, 2, 0.5), *_scaled(_A52, -1.0))
_A51 = ((0.5, 1, 0.5), *_scaled(_A52, -2.0), *_scaled(_A54, -1.0))
_HOCHBRUCK_OSTERMANN = ExponentialTableau(
    c=(0.5, 0.5, 1.0, 0.5),
    a=(
        {0: ((0.5, 1, 0.5),)},
        {0: ((0.5, 1, 0.5), (-1.0, 2, 0.5)), 1: ((1.0, 2, 0.5),)},
        {0: ((1.0, 1, 1.0), (-2.0, 2, 1.0)), 1: ((1.0, 2, 1.0),), 2: ((1.0, 2, 1.0),)},
        {0: _A51, 1: _A52, 2: _A52, 3: _A54},
    ),
    b={
        0: ((1.0, 1, 1.0), (-3.0, 2, 1.0), (4.0, 3, 1.0)),
        3: ((-1.0, 2, 1.0), (4.0, 3, 1.0)),
        4: ((4.0, 2, 1.0), (-8.0, 3, 1.0)),
    },
)


class ExpRK4(AbstractExponentialLieRK):
    """Hochbruck–Ostermann exponential Runge–Kutta: order 4 at any ζΔt/I, five torque calls per step.

    The high-order fluid scheme (the ``"fluid"`` model: `jaxrot.rollout` with ``fluid=`` at
    ``kT = 0``; see `jaxrot.schemes.AbstractExponentialLieRK`): five stages that
    satisfy the stiff order conditions of order 4, lifted to the rotation group in
    Runge–Kutta–Munthe-Kaas coordinates. As ``ζΔt/I → ∞`` it becomes a fourth-order RKMK method of
    the overdamped model; without a fluid, a five-stage classical method of order 4.

    Reference: M. Hochbruck and A. Ostermann, "Explicit exponential Runge–Kutta methods for
    semilinear parabolic problems", SIAM J. Numer. Anal. 43, 1069–1090 (2005), eq. (5.19).

    Example:
        >>> import jax.numpy as jnp, jaxrot
        >>> shear = jnp.zeros((3, 3)).at[0, 1].set(1.0)
        >>> fluid = jaxrot.Fluid.spheroid(1.0, 1.0, viscosity=1.0, velocity_gradient=shear)
        >>> s = jaxrot.RotState(jnp.array([1.0, 0, 0, 0]), jnp.zeros(3))
        >>> traj = jaxrot.rollout("exp_rk4", s, 1e-3 * jnp.ones(3), 0.1, 50, fluid=fluid)
        >>> traj.omega[-1].round(6).tolist()  # a sphere turns with the fluid: half the vorticity
        [0.0, 0.0, -0.5]
    """

    name: ClassVar[str] = "exp_rk4"
    order: ClassVar[int] = 4
    models: ClassVar[frozenset[str]] = frozenset({"fluid"})
    tableau: ClassVar[ExponentialTableau] = _HOCHBRUCK_OSTERMANN
