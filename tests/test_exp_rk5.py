"""ExpRK5 (Luan & Ostermann's expRK5s8): its stiff order conditions as identities in the φ-functions,
its embedded method, and the pair as an adaptive diffrax solver in a fluid.

The stiff order conditions (Luan & Ostermann, J. Comput. Appl. Math. 262 (2014), table 1; Hochbruck &
Ostermann, SIAM J. Numer. Anal. 43 (2005) up to order 4) are operator identities such as
``Σ_i b_i(Z) J ψ_{2,i}(Z) = 0`` for every bounded ``J``, with ``Z = hA``,
``ψ_j(z) = Σ_i b_i(z) c_i^{j−1}/(j−1)! − φ_j(z)`` and
``ψ_{j,i}(z) = Σ_k a_ik(z) c_k^{j−1}/(j−1)! − c_i^j φ_j(c_i z)``. For a diagonal ``Z`` the entry
``(k, m)`` of ``b_i(Z) J ψ_{2,i}(Z)`` is ``b_i(λ_k) J_km ψ_{2,i}(λ_m)``: the identity holds for every
``J`` exactly when ``Σ_i b_i(x) ψ_{2,i}(y) = 0`` for all pairs of eigenvalues ``x, y``, so each
factor gets its own scalar argument below. The order orders are measured in tests/test_fluid.py.
"""

import itertools
import math

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrot
from jaxrot import quaternion as quat
from jaxrot.schemes._phi import phi_functions
from jaxrot.schemes.exp_rk5 import LUAN_OSTERMANN


# Arguments z = −hλ from the Taylor branch of the φ-functions (|z| ≤ 1) to deep in the stiff range.
ZS = (0.0, -0.7, -5.0, -80.0)
# Each a_ij(z), b_i(z) is a sum of ≤ 16 terms with |coefficient · c^k| ≤ 240 and |φ_k| ≤ 1: ≤ 1e-12
# of round-off (16 · 240 · eps); a condition sums ≤ 8³ products of ≤ 4 such entries (|entry| ≤ 30
# over ZS). 1e-10 bounds that round-off; the three conditions that hold only weakly miss by ≥ 1e-6.
TOLERANCE = 1e-10
C = np.array([0.0, *LUAN_OSTERMANN.c])


def _value(terms, z):
    return sum(a * float(phi_functions(np.float64(node * z), k, np)[k]) for a, k, node in terms)


def _weights(row, z):
    w = np.zeros(8)
    for j, terms in row.items():
        w[j] = _value(terms, z)
    return w


@pytest.fixture(scope="module")
def at():
    """For each z of ZS: ``A`` (8, 8), ``b``, ``b̂`` (8,), ``psi[j]`` (the stage defects, j = 1 … 4)."""
    tables = {}
    for z in ZS:
        a = np.zeros((8, 8))
        for i, row in enumerate(LUAN_OSTERMANN.a, start=1):
            a[i] = _weights(row, z)
        psi = {
            j: a @ (C ** (j - 1) / math.factorial(j - 1))
            - np.array([c**j * float(phi_functions(np.float64(c * z), j, np)[j]) for c in C])
            for j in range(1, 5)
        }
        tables[z] = dict(
            a=a, b=_weights(LUAN_OSTERMANN.b, z), b_hat=_weights(LUAN_OSTERMANN.b_embedded, z), psi=psi
        )
    return tables


def _quadrature(weights, j, z):
    """``ψ_j(z) = Σ_i b_i(z) c_i^{j−1}/(j−1)! − φ_j(z)``."""
    return weights @ (C ** (j - 1) / math.factorial(j - 1)) - float(phi_functions(np.float64(z), j, np)[j])


def _conditions(at, b):
    """Conditions 5, 7–9, 11–17 of the table: ``(number, f(x, y, …), arity)``; ``b`` names the weights."""
    A = lambda z: at[z]["a"]  # noqa: E731
    B = lambda z: at[z][b]  # noqa: E731
    P = lambda j, z: at[z]["psi"][j]  # noqa: E731
    return [
        (5, lambda x, y: B(x) @ P(2, y), 2),
        (7, lambda x, y: B(x) @ P(3, y), 2),
        (8, lambda x, y, w: B(x) @ A(y) @ P(2, w), 3),
        (9, lambda x, y: B(x) @ (C * P(2, y)), 2),
        (11, lambda x, y: B(x) @ P(4, y), 2),
        (12, lambda x, y, w: B(x) @ A(y) @ P(3, w), 3),
        (13, lambda x, y, w, v: B(x) @ A(y) @ A(w) @ P(2, v), 4),
        (14, lambda x, y, w: B(x) @ A(y) @ (C * P(2, w)), 3),
        (15, lambda x, y: B(x) @ (C * P(3, y)), 2),
        (16, lambda x, y, w: (C * B(x)) @ A(y) @ P(2, w), 3),
        (17, lambda x, y: B(x) @ (C**2 * P(2, y)), 2),
    ]


def _worst(f, arity, weak=False):
    """max |f| over all arguments in ZS; ``weak``: the first (the weights' ``b_i(Z)``) at z = 0."""
    firsts = (0.0,) if weak else ZS
    return max(abs(f(x, *rest)) for x in firsts for rest in itertools.product(ZS, repeat=arity - 1))


def test_the_stiff_order_conditions_of_order_five(at):
    """Conditions 1–9 and 13–17 hold for all z; 10–12 (ψ_5 and the two with ψ_{4,i}, ψ_{3,j})
    in the weakened form with ``b_i(0)``, which is what the paper's convergence proof uses — and not
    strongly (the paper: no method of order 5 satisfies them all with ≤ 8 stages in this form)."""
    for z in ZS:
        assert np.abs(at[z]["psi"][1]).max() < TOLERANCE  # condition 3: the row sums
        for j in range(1, 5):  # conditions 1, 2, 4, 6
            assert abs(_quadrature(at[z]["b"], j, z)) < TOLERANCE, (j, z)
    assert abs(_quadrature(at[0.0]["b"], 5, 0.0)) < TOLERANCE  # condition 10, weakened
    assert max(abs(_quadrature(at[z]["b"], 5, z)) for z in ZS) > 1e-6
    for number, f, arity in _conditions(at, "b"):
        if number in (11, 12):
            assert _worst(f, arity, weak=True) < TOLERANCE, number
            assert _worst(f, arity) > 1e-6, number
        else:
            assert _worst(f, arity) < TOLERANCE, number


def test_the_embedded_weights_have_stiff_order_four_and_classical_order_four_exactly(at):
    """``b̂`` meets conditions 1–9 for all z, so the estimate is O(h⁵) at any ζΔt/I; its classical
    order is 4, not 5 (``ψ̂_5(0) ≠ 0``), so the estimate does not vanish on a smooth problem."""
    for z in ZS:
        for j in range(1, 5):
            assert abs(_quadrature(at[z]["b_hat"], j, z)) < TOLERANCE, (j, z)
    for number, f, arity in _conditions(at, "b_hat"):
        if number <= 9:
            assert _worst(f, arity) < TOLERANCE, number
    assert abs(_quadrature(at[0.0]["b_hat"], 5, 0.0)) > 1e-4


# The adaptive solver: a prolate spheroid (aspect ratio 4) in the shear u = (y, 0, 0) with a dipole in a
# field, St = I_⊥/ζ_⊥ = 1e-2, started at rest: a layer of width I/ζ (ζΔt/I up to ~5 a step at 1e-9).
SHEAR = jnp.zeros((3, 3)).at[0, 1].set(1.0)
FLUID = jaxrot.Fluid.spheroid(4.0, 1.0, 1.0, velocity_gradient=SHEAR)
INERTIA = 1e-2 * FLUID.friction[0] * jnp.array([1.0, 1.0, 2.0 / 17.0])
STATE = jaxrot.RotState(quat.exp(jnp.array([0.3, -0.5, 0.7])), jnp.zeros(3))
T_END = 1.0


def _magnet(t, q, omega, args):
    return jnp.cross(args * quat.rotate(q, jnp.array([0.0, 0.0, 1.0])), jnp.array([0.0, 1.0, 0.3]))


TERM = jaxrot.RigidBodyTerm(INERTIA, _magnet, fluid=FLUID)


@jax.jit
def _solve(solver, tol):
    sol = diffrax.diffeqsolve(
        TERM, solver, 0.0, T_END, 1e-3, STATE, args=100.0, saveat=diffrax.SaveAt(t1=True),
        stepsize_controller=diffrax.PIDController(rtol=tol, atol=tol), max_steps=100_000,
    )  # fmt: skip
    return sol.ys, sol.stats["num_accepted_steps"]


def test_an_adaptive_diffrax_solver_in_a_fluid():
    """``jaxrot.solver("exp_rk5")`` with a PID controller on a `RigidBodyTerm` with ``fluid=``: against
    diffrax's Tsit5 on the same term (the fluid's torque explicit) at 1e-12, the final error is below
    the tolerance at 1e-6 and 1e-9 and falls with it; ``q`` stays unit to round-off."""
    solver = jaxrot.solver("exp_rk5")
    assert isinstance(solver, diffrax.AbstractAdaptiveSolver)
    reference, _ = _solve(diffrax.Tsit5(), 1e-12)
    errors = []
    for tol in (1e-6, 1e-9):
        y, steps = _solve(solver, tol)
        assert abs(float(jnp.linalg.norm(y.q)) - 1) < 4e-16
        errors.append(float(quat.angle_between(y.q[0], quat.normalize(reference.q[0]))))
        assert errors[-1] < tol, (tol, errors[-1], int(steps))
        assert float(jnp.max(jnp.abs(y.omega - reference.omega))) < tol
    assert errors[1] < 1e-2 * errors[0]


def test_a_term_and_solver_of_different_models_are_refused():
    with pytest.raises(ValueError, match=r"'rkmk_dopri5' integrates a body in vacuum.*'exp_rk4', 'exp_rk5'"):
        diffrax.diffeqsolve(TERM, jaxrot.solver("rkmk_dopri5"), 0.0, 1.0, 0.1, STATE, args=100.0)
    with pytest.raises(ValueError, match=r"'exp_rk5' integrates a body in a fluid.*fluid=jaxrot.Fluid"):
        diffrax.diffeqsolve(
            jaxrot.RigidBodyTerm(INERTIA, None), jaxrot.solver("exp_rk5"), 0.0, 1.0, 0.1, STATE
        )
    with pytest.raises(ValueError, match=r"`fluid.kT` must be 0 for a RigidBodyTerm"):
        jaxrot.RigidBodyTerm(INERTIA, None, fluid=jaxrot.Fluid(jnp.ones(3), kT=1.0))


def test_a_fixed_step_exponential_solver_in_a_fluid_is_the_rollout_without_its_graded_start():
    """``jaxrot.solver("exp_midpoint")`` on the same term at a constant step: `jaxrot.rollout`'s
    steps without the graded start (the same arithmetic: ten steps apart by round-off, 1e-14)."""
    solver = jaxrot.solver("exp_midpoint")
    assert not isinstance(solver, diffrax.AbstractAdaptiveSolver)
    sol = diffrax.diffeqsolve(
        TERM, solver, 0.0, 0.5, 0.05, STATE, args=100.0, saveat=diffrax.SaveAt(t1=True),
        stepsize_controller=diffrax.ConstantStepSize(),
    )  # fmt: skip
    plain = jaxrot.schemes.ExpMidpoint(graded_start=False)
    traj = jaxrot.rollout(plain, STATE, INERTIA, 0.05, 10, torque=_magnet, args=100.0, fluid=FLUID)
    np.testing.assert_allclose(sol.ys.q[0], traj.q[-1], rtol=0, atol=1e-14)
    np.testing.assert_allclose(sol.ys.omega[0], traj.omega[-1], rtol=0, atol=1e-13)


@pytest.mark.slow
def test_gradients_through_the_adaptive_solve_from_zero_angle_and_rate():
    """d/d(inertia scale, viscosity) of the final state through ``diffeqsolve`` (the default
    `diffrax.RecursiveCheckpointAdjoint`), from q = 1 at rest: finite, and the central differences'
    (step 1e-5: truncation ~1e-10 and round-off ~1e-11 relative; the controller's step sizes are
    smooth in the parameters where no step is rejected differently) within 1e-6 relative."""
    y0 = jaxrot.RotState(jnp.array([1.0, 0.0, 0.0, 0.0]), jnp.zeros(3))

    def final(scale, viscosity):
        fluid = jaxrot.Fluid.spheroid(4.0, 1.0, viscosity, velocity_gradient=SHEAR)
        term = jaxrot.RigidBodyTerm(scale * jnp.array([1.0, 1.0, 0.2]), None, fluid=fluid)
        sol = diffrax.diffeqsolve(
            term, jaxrot.solver("exp_rk5"), 0.0, 0.5, 1e-3, y0,
            stepsize_controller=diffrax.PIDController(rtol=1e-8, atol=1e-8),
        )  # fmt: skip
        return sol.ys.q[0, 3] + sol.ys.omega[0, 2]

    final = jax.jit(final)  # one program for the four differences (floats would be static in diffeqsolve)
    grads = jax.jit(jax.grad(final, argnums=(0, 1)))(jnp.asarray(0.1), jnp.asarray(1.0))
    h = 1e-5
    differences = (
        (final(0.1 + h, 1.0) - final(0.1 - h, 1.0)) / (2 * h),
        (final(0.1, 1.0 + h) - final(0.1, 1.0 - h)) / (2 * h),
    )
    for grad, difference in zip(grads, differences, strict=True):
        assert np.isfinite(float(grad))
        assert float(grad) == pytest.approx(float(difference), rel=1e-6)


def test_an_exponential_solver_refuses_to_step_backwards_in_a_fluid():
    """Backwards the friction's relaxation e^{+ζ|Δt|/I} grows without bound: an error when the program runs
    (diffeqsolve traces the direction)."""
    with pytest.raises(Exception, match=r"'exp_midpoint' in a fluid steps forward only"):
        diffrax.diffeqsolve(TERM, jaxrot.solver("exp_midpoint"), 1.0, 0.0, -0.1, STATE, args=100.0)
