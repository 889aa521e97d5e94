"""ExpRK5: Luan and Ostermann's eight-stage exponential Runge–Kutta method expRK5s8, stiff order 5,
with an embedded method of stiff order 4 on the same stages."""

from fractions import Fraction
from typing import ClassVar

from ._exponential import AbstractExponentialLieRK
from ._exponential_tableau import ExponentialTableau


_C = (
    Fraction(1, 2),
    Fraction(1, 2),
    Fraction(1, 4),
    Fraction(1, 2),
    Fraction(1, 5),
    Fraction(2, 3),
    Fraction(1),
)


def _phi(k, stage=None):
    """``c^k φ_k(c z)`` at the node ``c`` of ``stage`` (counted from 1 as in the paper), or ``φ_k(z)``:
    the paper's ``φ_{k,i}`` and ``φ_k``, as ((coefficient, k, node),)."""
    node = Fraction(1) if stage is None else _C[stage - 2]
    return ((node**k, k, node),)


def _sum(*parts):
    """``Σ factor · terms`` over ``(factor, terms)`` pairs, as one tuple of terms."""
    return tuple((Fraction(factor) * a, k, node) for factor, terms in parts for a, k, node in terms)


def _float(terms):
    return tuple((float(a), k, float(node)) for a, k, node in terms)


# Luan & Ostermann (2014), section 5: the coefficients a_ij (j ≥ 2) and b_i in the φ_{k,i} = c_i^k φ_k(c_i z)
# notation (as in Chebfun's spinscheme/computeCoeffs.m, 'exprk5s8'); the first column follows from the
# row sums Σ_j a_ij = c_i φ_1(c_i z), Σ_j b_j = φ_1(z). tests/test_exp_rk5.py checks the stiff order
# conditions: 1–9 and 13–17 of the paper's table hold for all z, 10–12 in the weakened form (b_i(0)).
_A = {(3, 2): _sum((2, _phi(2, 2)))}
_A[4, 3] = _sum((2, _phi(2, 4)))
_A[5, 3] = _sum((-2, _phi(2, 2)), (16, _phi(3, 2)))
_A[5, 4] = _sum((8, _phi(2, 2)), (-32, _phi(3, 2)))
_A[6, 4] = _sum((8, _phi(2, 6)), (-32, _phi(3, 6)))
_A[6, 5] = _sum((-2, _phi(2, 6)), (16, _phi(3, 6)))
_A[7, 4] = _sum((Fraction(-125, 162), _A[6, 4]))
_A[7, 5] = _sum((Fraction(125, 1944), _A[6, 4]), (Fraction(-4, 3), _phi(2, 7)), (Fraction(40, 3), _phi(3, 7)))
_A[7, 6] = _sum(
    (Fraction(3125, 3888), _A[6, 4]), (Fraction(25, 3), _phi(2, 7)), (Fraction(-100, 3), _phi(3, 7))
)
_PHI = _sum(
    (Fraction(5, 32), _A[6, 4]), (Fraction(-25, 28), _phi(2, 6)), (Fraction(81, 175), _phi(2, 7)),
    (Fraction(-162, 25), _phi(3, 7)), (Fraction(150, 7), _phi(4, 6)), (Fraction(972, 35), _phi(4, 7)),
    (6, _phi(4)),
)  # fmt: skip
_A[8, 5] = _sum((Fraction(-16, 3), _phi(2)), (Fraction(208, 3), _phi(3)), (-40, _PHI))
_A[8, 6] = _sum((Fraction(250, 21), _phi(2)), (Fraction(-250, 3), _phi(3)), (Fraction(250, 7), _PHI))
_A[8, 7] = _sum((Fraction(27, 14), _phi(2)), (-27, _phi(3)), (Fraction(135, 7), _PHI))
_B = {
    6: _sum((Fraction(125, 14), _phi(2)), (Fraction(-625, 14), _phi(3)), (Fraction(1125, 14), _phi(4))),
    7: _sum((Fraction(-27, 14), _phi(2)), (Fraction(162, 7), _phi(3)), (Fraction(-405, 7), _phi(4))),
    8: _sum((Fraction(1, 2), _phi(2)), (Fraction(-13, 2), _phi(3)), (Fraction(45, 2), _phi(4))),
}
# The embedded weights (derived here, not in the paper): stages 5, 6, 7 (c = 1/2, 1/5, 2/3) have
# ψ_{2,i} = ψ_{3,i} = 0 and a_i2 = 0, so any weights on them that satisfy ψ_2 = ψ_3 = ψ_4 = 0 meet
# all nine conditions of stiff order 4; with three distinct nodes those weights are unique (the
# inverse of the Vandermonde system Σ_i b̂_i c_i^{j−1}/(j−1)! = φ_j, j = 2, 3, 4). The method's own
# weights are the same construction on stages 6, 7, 8; the difference of the two is O(h⁵) whatever ζΔt/I.
_B_EMBEDDED = {
    5: _sum((Fraction(-16, 3), _phi(2)), (Fraction(208, 3), _phi(3)), (-240, _phi(4))),
    6: _sum((Fraction(250, 21), _phi(2)), (Fraction(-250, 3), _phi(3)), (Fraction(1500, 7), _phi(4))),
    7: _sum((Fraction(27, 14), _phi(2)), (-27, _phi(3)), (Fraction(810, 7), _phi(4))),
}


def _first_column(node, row):
    """``{0: a_i1, …}``: ``a_i1 = c φ_1(c z) − Σ_{j ≥ 2} a_ij`` completes ``row`` (stages from 0)."""
    first = _sum((1, ((node, 1, node),)), *((-1, terms) for terms in row.values()))
    return {0: _float(first)} | {j - 1: _float(terms) for j, terms in sorted(row.items())}


def _row(i):
    return {j: terms for (r, j), terms in _A.items() if r == i}


LUAN_OSTERMANN = ExponentialTableau(
    c=tuple(float(x) for x in _C),
    a=tuple(_first_column(_C[i - 2], _row(i)) for i in range(2, 9)),
    b=_first_column(Fraction(1), _B),
    b_embedded=_first_column(Fraction(1), _B_EMBEDDED),
)


class ExpRK5(AbstractExponentialLieRK):
    """Luan–Ostermann exponential Runge–Kutta (expRK5s8): order 5 at any ζΔt/I, eight torque calls a step.

    The fifth-order fluid scheme (the ``"fluid"`` model: `jaxrot.rollout` with ``fluid=`` at
    ``kT = 0``; see `jaxrot.schemes.AbstractExponentialLieRK`): eight stages that satisfy the stiff
    order conditions of order 5 (three of them, 10–12 of the paper's table, in the weakened form its
    convergence proof uses), lifted to the rotation group in Runge–Kutta–Munthe-Kaas coordinates. An
    embedded method of stiff order 4 on the same stages (derived here: ``_B_EMBEDDED``) gives an error
    estimate at no extra torque call, so `jaxrot.solver` makes it an adaptive diffrax solver for a
    `jaxrot.RigidBodyTerm` with a ``fluid``. As ``ζΔt/I → ∞`` it becomes an eight-stage RKMK method of
    order 5 of the overdamped model; without a fluid, a classical method of order 5.

    Reference: V. T. Luan and A. Ostermann, "Explicit exponential Runge–Kutta methods of high order
    for parabolic problems", J. Comput. Appl. Math. 262 (2014), section 5 (expRK5s8).

    Example:
        >>> import jaxrot
        >>> s = jaxrot.FLUID_SCHEMES["exp_rk5"]
        >>> s.order, s.torque_evals_per_step, s.has_error_estimate  # `jaxrot.solver` makes it adaptive
        (5, 8, True)

    `jaxrot.rollout("exp_rk5", state, inertia, dt, n_steps, fluid=fluid)` runs it as
    `jaxrot.schemes.ExpRK4` is run; ``diffrax.diffeqsolve(jaxrot.RigidBodyTerm(inertia, torque,
    fluid=fluid), jaxrot.solver("exp_rk5"), …, stepsize_controller=diffrax.PIDController(…))``
    adaptively (tests/test_exp_rk5.py).
    """

    name: ClassVar[str] = "exp_rk5"
    order: ClassVar[int] = 5
    models: ClassVar[frozenset[str]] = frozenset({"fluid"})
    tableau: ClassVar[ExponentialTableau] = LUAN_OSTERMANN
