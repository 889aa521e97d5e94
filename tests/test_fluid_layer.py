"""The exponential schemes' graded start: order 4 kept through the boundary layer of a body started
off the slow manifold (`jaxrot.schemes._exponential`, `benchmarks/fluid_layer.py`).

The problem is the benchmark's: a magnetised body (moment 3 × (0.3, 0, 1)) in a field rotating at 2
rad/s about z (z part 0.3), frictions ζ = (1, 1, 0.4), decay rates ζ/I = 1e3, started at rest: it
relaxes onto the field's pull within 1e-3, a layer in which the stiff order conditions do not hold.
"""

import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrot
from jaxrot import quaternion as quat
from jaxrot.schemes import ExpRK4, _graded_start


sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import fluid_layer  # noqa: E402


def test_graded_start_can_be_turned_off():
    assert ExpRK4().in_fluid().start_steps == 1
    assert ExpRK4(graded_start=False).in_fluid().start_steps == 0
    assert ExpRK4().start_steps == 0  # without a fluid: no layer to resolve


def test_graded_start_is_a_run_of_its_substeps():
    """The graded first step equals the same substeps taken one by one with `step`: the substep sizes
    are ``s₀ e^{L_min (t − t0)/5}``, ``s₀ = dt min(1/3, (ω/L_max) max(1, (θ/λ)^{1/4}))`` with
    ``ω = |S| + |N|^{1/2}`` at the step's start and ``λ`` the layer's turn (``carry.layer``), the last
    cut to end on the step (`jaxrot.schemes._graded_start`)."""
    scheme = ExpRK4().in_fluid()
    run = fluid_layer.runner(ExpRK4(), 1e3)
    state = fluid_layer.start("off")
    dt = 0.004  # hL = 4 at the fastest rate, 1.6 at the slowest
    graded = run(state, jnp.asarray(dt), 1)
    inertia = jaxrot.body_inertia(fluid_layer.FRICTION / 1e3)
    args = fluid_layer.FluidArgs(
        fluid_layer.FIELD, jaxrot._fluid._fluid.check_fluid(fluid_layer.fluid(), (), jnp.float64)[0]
    )
    carry = jax.jit(lambda s: scheme.init(s, 0.0, inertia, fluid_layer.torque, args))(state)
    assert float(carry.layer) > 0  # at rest: off the slow manifold
    # One compiled step for every substep (t and the size are runtime values).
    step = jax.jit(lambda c, t, size: scheme.step(c, t, size, inertia, fluid_layer.torque, args))
    omega = float(np.linalg.norm(carry.slow) + np.sqrt(np.linalg.norm(carry.forcing)))
    coarsening = max(1.0, (_graded_start._LAYER_TURN / float(carry.layer)) ** 0.25)
    first = dt * min(1 / 3, max(coarsening * omega / 1e3, 5 / (960 * dt * 1e3)))
    t, sizes = 0.0, []
    while True:
        size = first * np.exp(1e3 * t / 5)
        if size >= dt - t:
            size = dt - t
        sizes.append(size)
        carry = step(carry, jnp.asarray(t), jnp.asarray(size))
        t += size
        if t >= dt * (1 - 1e-12):
            break
    assert len(sizes) > 5
    # The same substeps, differently summed offsets: round-off of a few steps' arithmetic.
    assert float(quat.angle_between(scheme.state(carry).q, graded)) < 1e-13


@pytest.mark.parametrize("dtype", [jnp.float32, jnp.float64])
def test_graded_start_finite_far_into_the_stiff_limit(dtype):
    """ζΔt/I = 1e8 and 1e12: the first step's substeps, about 5 (L_max/L_min)/(ω h max(1, (θ/λ)^{1/4}))
    (a layer's turn λ ~ 1e-15 rad and less: a few), within the loop's cap of 1024 (whose last substep
    would take the rest); the body ends turning at the slow velocity."""
    fluid = jaxrot.Fluid(fluid_layer.FRICTION.astype(dtype))
    # The slow velocity at t = 8 in one program, not one per eager operation.
    slow_velocity = jax.jit(
        lambda f, q: f.angular_velocity(q, fluid_layer.torque(8.0, q, None, fluid_layer.FIELD))
    )
    state = jaxrot.RotState(fluid_layer.Q0.astype(dtype), jnp.zeros(3, dtype))
    for rate in (1e8, 1e12):
        traj = jaxrot.rollout(
            "exp_rk4", state, (fluid_layer.FRICTION / rate).astype(dtype), 1.0, 8,
            torque=fluid_layer.torque, args=fluid_layer.FIELD, fluid=fluid,
        )  # fmt: skip
        assert np.all(np.isfinite(np.asarray(traj.q))) and np.all(np.isfinite(np.asarray(traj.omega)))
        slow = slow_velocity(fluid, traj.q[-1])
        # On the slow manifold ω − S = N/L + O(Ṅ/L²), |N| ≤ |Ṡ| + |S|² ≈ 2·3 + 3² here (|S| ≈ 3, the
        # field turning at 2 rad/s): within 20/L, plus the dtype's resolution on |S| over a few hundred
        # operations.
        gap = float(np.linalg.norm(np.asarray(traj.omega[-1]) - np.asarray(slow)))
        assert gap < 20 / rate + 300 * 3 * float(jnp.finfo(dtype).eps)


@pytest.mark.slow  # the bounded loop's reverse mode compiles for a minute on 2 cores
def test_gradients_through_the_graded_start_are_finite():
    """Reverse and forward mode through the bounded loop of the graded start, from rest (ω = 0)."""
    fluid = jaxrot.Fluid(fluid_layer.FRICTION)

    def final_angle(rate):
        traj = jaxrot.rollout(
            "exp_rk4", fluid_layer.start("off"), fluid_layer.FRICTION / rate, 0.05, 4,
            torque=fluid_layer.torque, args=fluid_layer.FIELD, fluid=fluid,
        )  # fmt: skip
        return quat.log(traj.q[-1])[0]

    # Both modes in one compiled program: eagerly, each mode was a forward and a transposed program
    # plus every operation around the rollout compiled one by one (152 programs, now 35; same compile s).
    @jax.jit
    def both(rate):
        return jax.grad(final_angle)(rate), jax.jvp(final_angle, (rate,), (jnp.ones(()),))[1]

    backward, forward = both(jnp.asarray(1e3))
    assert bool(jnp.isfinite(backward)) and bool(jnp.isfinite(forward))
    assert abs(float(backward - forward)) <= 1e-9 * max(1.0, abs(float(backward)))


@pytest.mark.slow  # reverse mode through the bounded loop: a minute's compile on 2 cores
def test_gradients_through_the_graded_start_are_finite_where_nothing_turns():
    """Torque-free in a fluid at rest, at rest or spinning about a principal axis: the slow velocity and
    the forcing are exactly 0, where ``|S|`` and ``|N|^{1/2}`` of the start's sizing have no derivative
    (``(Σx²)^{p/2}`` at 0: `_graded_start._root` gives it as 0). Before, the spinning body's gradient
    was NaN (its start ran: ``v − N/L = u``)."""
    fluid = jaxrot.Fluid(jnp.ones(3))

    def final(omega, inertia):
        traj = jaxrot.rollout(
            "exp_rk4", jaxrot.RotState(jnp.array([1.0, 0, 0, 0]), omega), inertia, 0.1, 3, fluid=fluid
        )
        return traj.q[-1].sum() + traj.omega[-1].sum()

    grad = jax.jit(jax.grad(final, argnums=(0, 1)))
    for omega in (jnp.zeros(3), jnp.array([0.0, 0.0, 1.0])):
        leaves = jax.tree.leaves(grad(omega, jnp.array([1e-3, 2e-3, 3e-3])))
        assert all(bool(jnp.all(jnp.isfinite(g))) for g in leaves), (omega, leaves)


@pytest.mark.slow
def test_graded_start_keeps_order_four_through_the_layer():
    """From rest at ζ/I = 1e3, hL from 250 down to 3.9: with the graded start every halving gains at
    least 3.5 bits (order 4: 4) until the error nears its floor; without it the layer's error falls at
    order ~1.2–1.5 over hL 60–8 (measured; the benchmark's "off" rows). The floor, 1e-10 rad: the
    layer's own remainder after grading (4e-12 measured) and float64 round-off over up to 2e4 steps
    (2.2e-16 × 2e4 × a few operations per step ≈ 1e-11) kept well below it."""
    steps = [16 * 2**k for k in range(7)]
    state = fluid_layer.start("off")
    reference = fluid_layer.runner(ExpRK4(), 1e3)(state, fluid_layer.T_END / (16 * steps[-1]), 16 * steps[-1])
    orders = {}
    for graded in (True, False):
        run = fluid_layer.runner(ExpRK4(graded_start=graded), 1e3)
        errors = [float(quat.angle_between(run(state, fluid_layer.T_END / n, n), reference)) for n in steps]
        orders[graded] = [(np.log2(a / b), b) for a, b in zip(errors, errors[1:], strict=False)]
    assert all(order >= 3.5 for order, error in orders[True] if error > 1e-10), orders[True]
    assert min(order for order, _ in orders[False]) < 2.0, orders[False]
