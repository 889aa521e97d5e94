"""Rozmanov–Kusalik velocity Verlet: the capped, differentiable half-step iteration."""

import warnings

import jax
import jax.numpy as jnp
import pytest
from helpers import MOMENTS, gravity_args, principal_state

import jaxrot
from jaxrot.scenes import gravity_torque
from jaxrot.schemes import Rozmanov


TUMBLING = principal_state(omega_body=jnp.array([1.0, 2.0, 0.5]))


def test_converges_within_max_iter_at_a_typical_step():
    """dt = 0.01 at |ω| ≈ 2.3: RMPCDMD's tolerance 1e-13 in a few iterations (measured 4)."""
    traj, carry = jaxrot.rollout(
        "rozmanov",
        TUMBLING,
        MOMENTS,
        0.01,
        500,
        torque=gravity_torque,
        args=gravity_args(),
        return_carry=True,
    )
    assert int(carry.unconverged_steps[0]) == 0
    assert 1 <= int(carry.max_iterations[0]) <= 5
    assert 1 <= int(carry.iterations[0]) <= int(carry.max_iterations[0])


@pytest.mark.slow
def test_says_so_when_it_does_not_converge():
    with pytest.warns(RuntimeWarning, match="did not reach tol.*max_iter=1"):
        traj, carry = jaxrot.rollout(Rozmanov(max_iter=1), TUMBLING, MOMENTS, 0.05, 20, return_carry=True)
    assert int(carry.unconverged_steps[0]) == 20
    assert int(carry.max_iterations[0]) == 1
    # Without the carry the compiled core returns only its count (`Rozmanov.summarize`): an integer,
    # with no tangent, so it is concrete under jax.grad too.
    with pytest.warns(RuntimeWarning, match="on 20 particle-step"):
        jaxrot.rollout(Rozmanov(max_iter=1), TUMBLING, MOMENTS, 0.05, 20)

    def last_q(omega):
        traj = jaxrot.rollout(Rozmanov(max_iter=1), TUMBLING._replace(omega=omega), MOMENTS, 0.05, 20)
        return jnp.sum(traj.q[-1])

    with pytest.warns(RuntimeWarning, match="on 20 particle-step"):
        jax.grad(last_q)(TUMBLING.omega)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        jax.jit(last_q)(TUMBLING.omega)  # traced count: no warning (docs/schemes/rozmanov.md)


def test_more_iterations_than_needed_change_nothing():
    """Converged iterates are frozen, so the result does not depend on the cap beyond convergence."""
    few = jaxrot.rollout(Rozmanov(max_iter=6), TUMBLING, MOMENTS, 0.01, 200)
    many = jaxrot.rollout(Rozmanov(max_iter=30), TUMBLING, MOMENTS, 0.01, 200)
    assert float(jnp.max(jnp.abs(few.q - many.q))) == 0.0


def test_float32_default_tolerance_converges():
    state = jaxrot.RotState(TUMBLING.q.astype(jnp.float32), TUMBLING.omega.astype(jnp.float32))
    _, carry = jaxrot.rollout("rozmanov", state, MOMENTS.astype(jnp.float32), 0.01, 200, return_carry=True)
    assert int(carry.unconverged_steps[0]) == 0


def test_iteration_counts_are_observable_under_jit_and_vmap():
    run = jax.jit(lambda s: jaxrot.rollout("rozmanov", s, MOMENTS, 0.01, 50, return_carry=True)[1])
    states = jaxrot.RotState(
        jnp.stack([TUMBLING.q] * 3), jnp.stack([TUMBLING.omega * k for k in (0.0, 1.0, 3.0)])
    )
    carry = run(states)
    assert carry.max_iterations.shape == (3,)
    # A body at rest converges at once; faster bodies need more iterations.
    assert int(carry.max_iterations[0]) <= int(carry.max_iterations[1]) <= int(carry.max_iterations[2])
