"""The stiff-start probe: a gyroscopic body under offset gravity and a dipole in a rotating field, in a fluid.

The body of issue 73's error-floor check, shared by `tests/test_fluid_start.py` and
`benchmarks/fluid_layer.py`: principal moments ``I = ζ / (R · (1, 1.25, 0.8))`` (frictions
ζ = (0.5, 1, 1.5) about the body axes, so the decay rates ``ζ_k/I_k`` are R, 1.25 R, 0.8 R: an
asymmetric top whose gyroscopic term ``u × I u`` couples the axes), its centre of mass at
(0.05, 0.02, 0.1) m (body frame) under a 1 kg weight, and a magnetic moment 2 × (0.3, 0, 1) in a
unit field turning about world z at 2 rad/s with a static z part 0.3. Both torques depend on ``q``
(and the field on ``t``) but not on ω: they fold into the slow velocity ``S`` (about 1 rad/s).
Started at rest ("off": a boundary layer of width 1/R) or on its slow manifold ("on":
`on_manifold`), over t = 4.
"""

import contextlib

import jax
import jax.numpy as jnp

import jaxrot
from jaxrot import quaternion as quat
from jaxrot._fluid._fluid import check_fluid
from jaxrot.schemes import ExpRK4, _graded_start
from jaxrot.schemes._base import advance
from jaxrot.schemes._exponential import FluidArgs


FRICTION = jnp.array([0.5, 1.0, 1.5])
RATE_SHAPE = jnp.array([1.0, 1.25, 0.8])
ARGS = {
    "offset_body": jnp.array([0.05, 0.02, 0.1]),
    "weight": jnp.array([0.0, 0.0, -9.81]),
    "moment": 2.0 * jnp.array([0.3, 0.0, 1.0]),
    "angular_frequency": 2.0,
}
Q0 = quat.exp(jnp.array([0.3, -0.5, 0.7]))
T_END = 4.0
SPIN = jnp.array([2.0, 8.0, 4.0])  # rad/s, body frame: the "spin" start


def torque(t, q, omega, args):
    """Offset gravity plus a dipole in a field turning about z: world frame, depends on ``t`` and ``q``."""
    gravity = jnp.cross(quat.rotate(q, args["offset_body"].astype(q.dtype)), args["weight"].astype(q.dtype))
    phase = jnp.asarray(args["angular_frequency"] * t, q.dtype)
    field = jnp.stack([jnp.cos(phase), jnp.sin(phase), jnp.full_like(phase, 0.3)])
    return gravity + jnp.cross(quat.rotate(q, args["moment"].astype(q.dtype)), field)


def inertia(rate):
    """Principal moments ``(3,)`` with decay rates ``ζ_k / I_k = rate · (1, 1.25, 0.8)``."""
    return FRICTION / (rate * RATE_SHAPE)


def fluid_args(dtype=jnp.float64):
    return FluidArgs(ARGS, check_fluid(jaxrot.Fluid(FRICTION.astype(dtype)), (), dtype)[0])


def on_manifold(rate, q0=Q0, t0=0.0, iterations=8):
    """The world ω of a body at ``q0`` on its slow manifold to second order in ``1/L``.

    Equation (1) of `jaxrot.schemes._exponential`, ``v̇ = −L v + N``, has the invariant manifold
    ``v = L⁻¹(N − v̇) = L⁻¹ N − L⁻² Ṅ + O(L⁻³)``; ``Ṅ`` is taken along the slow motion (``t`` and
    ``q̇ = ½ q ⊗ (0, u)`` at fixed ``v``; ``v̇ = O(1/L)`` adds to the next order only). Iterated to its
    fixed point (a contraction while ``|∂N/∂u| < L``)."""
    scheme = ExpRK4().in_fluid()
    inert = jaxrot.body_inertia(inertia(rate))
    args = fluid_args(q0.dtype)
    decay = rate * RATE_SHAPE

    def evaluate(t, q, deviation):
        return scheme._evaluate(t, q, inert, torque, args.args, args.fluid, deviation=deviation)

    deviation = jnp.zeros(3, q0.dtype)
    t0 = jnp.asarray(t0, q0.dtype)
    for _ in range(iterations):
        slow, forcing, u = evaluate(t0, q0, deviation)
        q_dot = 0.5 * quat.multiply(q0, quat.pure(u))
        tangent = (jnp.ones_like(t0), q_dot, jnp.zeros_like(deviation))
        forcing_rate = jax.jvp(lambda t, q, v: evaluate(t, q, v)[1], (t0, q0, deviation), tangent)[1]
        deviation = (forcing - forcing_rate / decay) / decay
    return quat.rotate(q0, slow + deviation)


def start(kind, rate):
    """The `RotState` at t = 0: at rest (``"off"``), at the slow velocity ``S`` (``"slow"``: what
    `jaxrot.Fluid.angular_velocity` gives, off the manifold by ``N/L``) or on the manifold (``"on"``)."""
    if kind == "off":
        return jaxrot.RotState(Q0, jnp.zeros(3))
    if kind == "spin":
        return jaxrot.RotState(Q0, quat.rotate(Q0, SPIN))
    if kind == "slow":
        omega = jaxrot.Fluid(FRICTION).angular_velocity(Q0, torque(0.0, Q0, None, ARGS))
        return jaxrot.RotState(Q0, omega)
    return jaxrot.RotState(Q0, on_manifold(rate))


def runner(scheme, rate):
    """``run(state, dt, n) -> q`` after ``n`` steps: one compiled program for any dt and n."""
    return final_orientation_runner(scheme, jaxrot.body_inertia(inertia(rate)), torque, fluid_args())


def final_orientation_runner(scheme, inert, torque, args):
    """``run(state, dt, n) -> q`` after ``n`` steps of ``scheme``'s fluid form from t = 0 (its graded
    start included), ``advance``d as `jaxrot.rollout` takes them: dt and n runtime values."""
    scheme = scheme.in_fluid()

    @jax.jit
    def run(state, dt, n):
        t0 = jnp.zeros(())
        carry = scheme.init(state, t0, inert, torque, args)
        step = lambda i, c: advance(scheme, c, i, i * dt, t0, dt, inert, torque, args)  # noqa: E731
        return scheme.state(jax.lax.fori_loop(0, n, step, carry)).q

    return run


def errors(run, state, steps, reference):
    """Final orientation errors (rad) of ``run`` at each number of steps over `T_END`."""
    return [float(quat.angle_between(run(state, jnp.asarray(T_END / n), n), reference)) for n in steps]


@contextlib.contextmanager
def counting_substeps():
    """Within it, the graded start counts its work: yields ``[substeps, graded steps]``, added to by a host
    callback around each substep and each graded step (not timed; zero it between runs). The counting
    `_graded_start.graded_step` is read when a run traces ``start_step``: build and first call runners
    inside; restored on exit."""
    counts = [0, 0]
    graded_step = _graded_start.graded_step

    def counting(step, *args):
        def counted(*a):
            jax.debug.callback(lambda: counts.__setitem__(0, counts[0] + 1))
            return step(*a)

        jax.debug.callback(lambda: counts.__setitem__(1, counts[1] + 1))
        return graded_step(counted, *args)

    _graded_start.graded_step = counting
    try:
        yield counts
    finally:
        _graded_start.graded_step = graded_step
