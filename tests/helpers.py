"""Shared problems and measurement helpers for the tests."""

import jax
import jax.numpy as jnp
import numpy as np

import jaxrot
from jaxrot import quaternion as quat
from jaxrot.schemes._base import advance as advance_step


MOMENTS = jnp.array([1.0, 2.0, 3.0])
Q0 = quat.exp(jnp.array([0.1, 0.2, 0.3]))
OMEGA_BODY0 = jnp.array([0.3, 1.0, 0.2])
# A fixed rotation from the principal frame to a "lab-chosen" body frame in which
# the same body has a full, non-diagonal inertia tensor.
PRINCIPAL_TO_BODY = quat.exp(jnp.array([0.4, -0.7, 0.25]))


def principal_state(omega_body=OMEGA_BODY0, q0=Q0):
    return jaxrot.RotState(q0, quat.rotate(q0, omega_body))


def full_tensor(moments=MOMENTS, r=PRINCIPAL_TO_BODY):
    rot = quat.to_matrix(r)
    return rot @ jnp.diag(moments) @ rot.T


def to_body_frame(state, r=PRINCIPAL_TO_BODY):
    """The same physical state, with orientation expressed for the body frame of `full_tensor`."""
    return jaxrot.RotState(quat.multiply(state.q, quat.conjugate(r)), state.omega)


def assert_same(a, b, ulps=0):
    """Same tree, shapes and dtypes, and equal bits, or within ``ulps`` units of round-off at magnitude 1."""
    assert jax.tree_util.tree_structure(a) == jax.tree_util.tree_structure(b)
    for x, y in zip(jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b), strict=True):
        assert x.shape == y.shape and x.dtype == y.dtype
        if ulps and jnp.issubdtype(x.dtype, jnp.floating):
            np.testing.assert_allclose(x, y, rtol=0, atol=ulps * float(jnp.finfo(x.dtype).eps))
        else:
            np.testing.assert_array_equal(x, y)


def driven_problem(dtype, n_bodies):
    """``(state, inertia, dt, rollout kwargs)``: bodies in a rotating field (time-dependent torque),
    a per-body field strength, body 0 spun at an imposed rate about z and body 1 with an imposed
    z moment: every carry path of a scheme."""
    scene = jaxrot.SCENES["dipole_rotating_field"](dtype)
    rng = np.random.default_rng(1)
    q = quat.normalize(jnp.asarray(rng.normal(size=(n_bodies, 4)), dtype))
    state = jaxrot.RotState(q, jnp.asarray(rng.normal(size=(n_bodies, 3)), dtype))
    amplitude = jaxrot.per_body(jnp.asarray(np.resize([1.0, 0.5, 2.0], n_bodies), dtype))
    args = {"rotating_field": {**scene.args["rotating_field"], "amplitude": amplitude}}
    omega_mask, omega, moment_mask, moment = (np.zeros((n_bodies, 3), t) for t in (bool, float, bool, float))
    omega_mask[0, 2], omega[0, 2] = True, 1.5
    moment_mask[1, 2], moment[1, 2] = True, 0.3
    drive = jaxrot.Drive(
        omega_mask=jnp.asarray(omega_mask),
        omega=jnp.asarray(omega, dtype),
        moment_mask=jnp.asarray(moment_mask),
        moment=jnp.asarray(moment, dtype),
    )
    kwargs = {"torque": scene.torque, "args": args, "drive": drive, "t0": 0.3}
    return state, MOMENTS.astype(dtype), 0.01, kwargs


def gravity_args(offset_principal=(0.1, 0.05, 0.3), r=None):
    offset = jnp.array(offset_principal)
    if r is not None:
        offset = quat.rotate(r, offset)
    return {"offset_body": offset, "weight": jnp.array([0.0, 0.0, -9.81])}


def order_errors(scheme, state, inertia, t_end, coarse_steps, levels, torque=None, args=None):
    """(dts, max orientation errors at the coarse times) over a halving ladder, against a 1e-13 reference.

    Every rung runs through one compiled ``advance`` (`fixed_step_advance`): one compilation for the
    ladder instead of one `jaxrot.rollout` per rung."""
    dt0 = t_end / coarse_steps
    ts = jnp.arange(coarse_steps + 1, dtype=jnp.float64) * dt0
    ref = jaxrot.reference_rollout(state, inertia, ts, torque=torque, args=args, rtol=1e-13, atol=1e-13)
    init, advance, to_state = fixed_step_advance(scheme, inertia, torque, args)
    dts, errors = [], []
    for k in range(levels):
        factor = 2**k
        dt = dt0 / factor
        carry, qs = init(state), [state.q]
        for j in range(coarse_steps):
            carry = advance(carry, j * factor, dt, factor)
            qs.append(to_state(carry).q)
        dts.append(dt)
        errors.append(float(jnp.max(quat.angle_between(jnp.stack(qs), ref.q))))
    return np.array(dts), np.array(errors)


def fitted_order(dts, errors):
    return float(np.polyfit(np.log(dts), np.log(errors), 1)[0])


def central_difference_grad(f, primals, argnum, rel_step=1e-4):
    """Gradient of scalar `f` w.r.t. `primals[argnum]` by the fourth-order central stencil.

    Truncation is O(h^4) and round-off O(eps/h), so h = 1e-4·scale resolves
    gradients to ~1e-10 relative, well inside the 1e-6 the tests ask for.
    """
    x = jnp.asarray(primals[argnum])
    h = rel_step * max(float(jnp.max(jnp.abs(x))), 1e-2)
    flat = x.reshape(-1)
    grad = []
    for j in range(flat.size):
        e = jnp.zeros_like(flat).at[j].set(h).reshape(x.shape)

        def at(shift, e=e):
            args = list(primals)
            args[argnum] = x + shift * e
            return f(*args)

        grad.append((-at(2) + 8 * at(1) - 8 * at(-1) + at(-2)) / (12 * h))
    return jnp.stack(grad).reshape(x.shape)


def fixed_step_advance(scheme, inertia, torque=None, args=None):
    """``(init, advance, state)`` for one body: the scheme's own ``init``/``step``/``state``, with
    ``advance(carry, first_step, dt, n)`` taking ``n`` steps from step number ``first_step`` (time
    ``first_step · dt``; a fluid scheme's graded start counted from step 0) in a ``fori_loop`` with a
    runtime trip count, so any dt and n share one
    compilation (`jaxrot.rollout` fixes ``n_steps`` at trace time; its equivalence to these methods is
    tested for every scheme elsewhere)."""
    scheme = jaxrot.schemes.resolve_scheme(scheme)
    inertia = jaxrot.body_inertia(inertia)

    def init(state):
        return scheme.init(state, jnp.zeros((), state.q.dtype), inertia, torque, args)

    @jax.jit
    def advance(carry, first_step, dt, n):
        def step(i, c):
            index = first_step + i
            t = index.astype(dt.dtype) * dt
            return advance_step(scheme, c, index, t, jnp.zeros_like(dt), dt, inertia, torque, args)

        return jax.lax.fori_loop(0, n, step, carry)

    def run(carry, first_step, dt, n):
        dtype = scheme.state(carry).q.dtype
        return advance(carry, jnp.asarray(first_step), jnp.asarray(dt, dtype), n)

    return init, run, scheme.state


def compiled_for_a_long_run(fn, *example_args):
    """``jax.jit(fn)`` compiled for ``example_args`` at XLA's default optimisation level.

    conftest.py runs the suite at LLVM -O0 (compiling dominates most tests); a program that then runs
    for 10⁴ steps pays for that instead: jax.grad through 1000 splitting steps ran 11.6 s at -O0 and
    0.46 s at the default level, for 4 s more compilation (2-core EPYC, jax 0.10.2). The level changes
    rounding (fused multiply-adds), not what is computed."""
    lowered = jax.jit(fn).lower(*example_args)
    return lowered.compile(compiler_options={"xla_backend_optimization_level": 2})


def fixed_step_runner(scheme, inertia, torque=None, args=None):
    """``run(state, dt, n) -> RotState`` after ``n`` steps of one body, one compilation for any dt, n
    (`fixed_step_advance` from the start)."""
    init, advance, to_state = fixed_step_advance(scheme, inertia, torque, args)
    return lambda state, dt, n: to_state(advance(init(state), 0, dt, n))


# Generic contract tests (batching, blocking, chunks, sharding, drives, scenes, extremes) run on
# every scheme in the slow set (`pytest -m slow`) and on Zhao's alone by default: they test the shared
# rollout machinery, which every scheme goes through the same way; each scheme's own arithmetic
# (order, torque counts, float32 norm, exactness) has default tests of its own.
DEFAULT_SCHEMES = {"zhao"}


# Members of a family run the same code on other coefficients (Butcher tableaux for rkmk4,
# rkmk_dopri5 and rkmk_dopri8; RKN weights for srkn6b and srkn14a): the contract tests of the shared
# machinery (batching, blocking, chunks, sharding, drives, memory, finite gradients at rest, bad input)
# run on one member of each family; what depends on the coefficients (orders, limits, drift, accuracy
# tables, gradients against central differences in tests/test_high_order.py) runs on every scheme.
SAME_CODE_AS = {"rkmk_dopri5": "rkmk4", "rkmk_dopri8": "rkmk4", "srkn14a": "srkn6b"}


def scheme_params(names=None):
    """``names`` (default: every registered scheme) for parametrize, the others marked slow."""
    import pytest

    names = list(jaxrot.SCHEMES) if names is None else list(names)
    return [pytest.param(n, marks=() if n in DEFAULT_SCHEMES else pytest.mark.slow) for n in names]


def contract_params():
    """One scheme of each family (`SAME_CODE_AS`), for the contract tests, as `scheme_params`."""
    return scheme_params(sorted(n for n in jaxrot.SCHEMES if n not in SAME_CODE_AS))


def rotor_flows(name):
    """Free-rotor flows per step: the sub-steps whose roundings a splitting adds up (0 for the others)."""
    from jaxrot.schemes import AbstractRKNSplitting, Splitting

    scheme = jaxrot.SCHEMES[name]
    if isinstance(scheme, AbstractRKNSplitting):
        return len(scheme.rotor_weights)
    return 1 if isinstance(scheme, Splitting) else 0


# The schemes over the free rotor (`rotor_flows` > 0): splitting, srkn6b, srkn14a.
ROTOR_SCHEMES = tuple(name for name in jaxrot.SCHEMES if rotor_flows(name))


def refuses_velocity_torques(name):
    """Whether the scheme refuses a torque that depends on ω, by design (the RKN splittings)."""
    from jaxrot.schemes import AbstractRKNSplitting

    return isinstance(jaxrot.SCHEMES[name], AbstractRKNSplitting)
