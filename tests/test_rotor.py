"""The fast free rotor `jaxrot._free_body._rotor.free_rotor` against the exact `jaxrot.analytic.free_motion`.

Every test reads the shared batches below, evaluated once per dtype, each output when a test first
reads it (each compiled program costs seconds on 2 cores): random states with |ω| = 1 for several
bodies and times, plus the special cases (ω = 0, t = 0, sphere, symmetric tops, t < 0, outside the
valid range).
"""

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxrot import analytic, quaternion as quat
from jaxrot._free_body import _rotor, _rotor_loop
from jaxrot._free_body._rotor import free_rotor, substeps_for


BODIES = ((1.0, 2.0, 3.0), (1.0, 1.0, 1.9), (1.0, 2.0, 2.0), (1.0, 1.5, 2.0), (0.5, 1.0, 1.2))
TIMES = (0.05, 0.2, 0.5, -0.4)
ORDER_TIMES = (0.3, 0.4, 0.5, 0.6)  # one DMV10 step: error well above round-off, below O(1)
N_STATES = 24


def _states(n, seed=0):
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(n, 4))
    w = rng.normal(size=(n, 3))
    return q / np.linalg.norm(q, axis=1, keepdims=True), w / np.linalg.norm(w, axis=1, keepdims=True)


def _random_batch():
    """(q, ω, moments, t) rows: every body × time × state, with |ω| = 1, so |ω| |t| = |t|."""
    q, w = _states(N_STATES)
    rows = [(qi, wi, body, t) for body in BODIES for t in TIMES for qi, wi in zip(q, w, strict=True)]
    return tuple(np.array([r[k] for r in rows]) for k in range(4))


def _batched(fn):
    return jax.jit(jax.vmap(fn))


SPECIAL = {
    # name: (omega body, moments, t)
    "omega_zero": ((0.0, 0.0, 0.0), (1.0, 2.0, 3.0), 0.7),
    "t_zero": ((0.3, 1.0, 0.2), (1.0, 2.0, 3.0), 0.0),
    "sphere": ((0.3, -0.8, 0.5), (1.5, 1.5, 1.5), 0.5),
    "symmetric_12": ((0.3, 1.0, 0.2), (1.0, 1.0, 2.0), 0.5),
    "symmetric_23": ((0.3, 1.0, 0.2), (1.0, 2.0, 2.0), 0.5),
    "steady_intermediate": ((0.0, 1.0, 0.0), (1.0, 2.0, 3.0), 0.5),
    "t_negative": ((0.3, 1.0, 0.2), (1.0, 2.0, 3.0), -0.5),
    "long_flow": ((0.3, 1.0, 0.2), (1.0, 2.0, 3.0), 4.0),  # |ω| t = 4.4: 22 DMV steps of 0.2 rad
    "needle_long": ((0.3, 1.0, 0.2), (1e-6, 1.0, 1.0), 0.3),  # modification lost to cancellation
    "needle_short": ((0.3, 1.0, 0.2), (1e-3, 1.0, 1.0), 0.3),
}
Q0 = quat.exp(jnp.array([0.1, 0.2, 0.3]))
N_RANDOM = len(BODIES) * len(TIMES) * N_STATES
N_ORDER = len(ORDER_TIMES) * N_STATES


@functools.cache
def _inputs():
    """One batch, so that each program compiles once: rows ``[:N_RANDOM]`` random (every body ×
    time × state), then ``N_ORDER`` rows for the order test (body (1, 2, 3)), then `SPECIAL`."""
    q, w = _states(N_STATES)
    rows = [(qi, wi, body, t) for body in BODIES for t in TIMES for qi, wi in zip(q, w, strict=True)]
    rows += [(qi, wi, BODIES[0], t) for t in ORDER_TIMES for qi, wi in zip(q, w, strict=True)]
    q0 = np.asarray(Q0)
    rows += [(q0, np.asarray(quat.rotate(Q0, jnp.array(v[0]))), v[1], v[2]) for v in SPECIAL.values()]
    return tuple(jnp.asarray(np.array([r[k] for r in rows])) for k in range(4))


# Each output of the batch is computed (compiled) when a test first reads it: the default set reads
# the rotor's only; the exact motion and the one-step rotor are the slow tests' (seconds of compiles).
@functools.cache
def _exact():
    return _batched(analytic.free_motion)(*_inputs())


@functools.cache
def _rotor_out():
    return jax.jit(free_rotor)(*_inputs())  # leading axes broadcast, as under vmap


@functools.cache
def _rotor32():
    return _batched(free_rotor)(*(a.astype(jnp.float32) for a in _inputs()))


@functools.cache
def _one_step():
    return _batched(functools.partial(free_rotor, substeps=1))(*_inputs())


def _rows(tree, start, stop):
    return jax.tree.map(lambda a: a[start:stop], tree)


def _errors(a, b):
    """Per row: (orientation angle between, largest ω component difference)."""
    return np.asarray(quat.angle_between(a[0], b[0])), np.asarray(jnp.max(jnp.abs(a[1] - b[1]), axis=-1))


@pytest.mark.slow
def test_matches_exact_motion_to_round_off():
    """Round-off (a few hundred ulp in both solutions) at every |ω| |t|: the rotor takes steps of at
    most 0.2 rad (`_bound`)."""
    inputs, exact, rotor = _inputs(), _exact(), _rotor_out()
    angle, omega = _errors(_rows(rotor, 0, N_RANDOM), _rows(exact, 0, N_RANDOM))
    assert np.all(np.isfinite(angle)) and np.all(np.isfinite(omega))
    bound = _bound(np.abs(np.asarray(inputs[3][:N_RANDOM])))  # |ω| = 1
    assert np.all(angle < bound) and np.all(omega < bound), (angle.max(), omega.max())


def _bound(turn, loop_batch=1):
    """The error bound at ``|ω| |t| = turn``: ``n = max(2, ⌈turn / 0.2⌉)`` DMV10 steps (`substeps_for`;
    with ``loop_batch`` k, ``n − 2`` rounded up to a multiple of k), each within the one-step
    truncation bound of the order test below (1e-8 at 0.6 rad, slope 11) and adding round-off (the
    1e-13 of two steps, measured in both solutions, per two steps)."""
    n = np.maximum(2, np.ceil(np.asarray(turn) / 0.2))
    n = 2 + np.ceil((n - 2) / loop_batch) * loop_batch
    return 1e-13 * n / 2 + n * 1e-8 * (turn / n / 0.6) ** 11


@pytest.mark.slow
def test_order_ten_in_t():
    """One DMV10 step (``substeps=1``): local error ∝ t^11 (Hairer & Vilmart's order 10). A wrong
    coefficient of degree k in the modified moments would leave order 2k <= 8 (slope <= 9)."""
    exact, one_step = _exact(), _one_step()
    rows = slice(N_RANDOM, N_RANDOM + N_ORDER)
    angle, omega = _errors(_rows(one_step, rows.start, rows.stop), _rows(exact, rows.start, rows.stop))
    worst = [
        max(a.max(), o.max())
        for a, o in zip(angle.reshape(len(ORDER_TIMES), -1), omega.reshape(len(ORDER_TIMES), -1), strict=True)
    ]
    slope = np.polyfit(np.log(ORDER_TIMES), np.log(worst), 1)[0]
    assert 10.5 < slope < 12, (slope, worst)
    assert worst[-1] < 1e-8  # |ω| t = 0.6 in one step (measured 5e-9)


def test_invariants_and_unit_quaternion():
    """|L|, the energy and |q| after one call, from the float64 results: a few ulp."""
    (q, w, moments, _), (q1, w1) = _rows(_inputs(), 0, N_RANDOM), _rows(_rotor_out(), 0, N_RANDOM)

    q, w, moments, q1, w1 = (np.asarray(a) for a in (q, w, moments, q1, w1))

    def invariants(q, w):
        u = _body_frame(q, w)
        return np.linalg.norm(moments * u, axis=-1), np.sum(moments * u * u, axis=-1)

    (l0, e0), (l1, e1) = invariants(q, w), invariants(q1, w1)
    eps = np.finfo(np.float64).eps
    assert np.max(np.abs(l1 / l0 - 1)) < 32 * eps
    assert np.max(np.abs(e1 / e0 - 1)) < 64 * eps
    assert np.max(np.abs(np.linalg.norm(q1, axis=-1) - 1)) < 4 * eps


def _body_frame(q, w):
    """``quat.rotate(quat.conjugate(q), w)`` in numpy, on computed arrays (eagerly, each jnp operation
    compiles a program of its own): ``w + s t + v × t`` with ``t = 2 v × w``, ``(s, v)`` = conj(q)."""
    s, v = q[..., :1], -q[..., 1:]
    t = 2 * np.cross(v, w)
    return w + s * t + np.cross(v, t)


def _special(name, exact=True):
    """Row ``name`` of (inputs, exact motion, rotor); without ``exact``, None for the exact motion."""
    i = N_RANDOM + N_ORDER + list(SPECIAL).index(name)
    trees = (_inputs(), _exact() if exact else None, _rotor_out())
    return tuple(None if tree is None else jax.tree.map(lambda a: a[i], tree) for tree in trees)


def test_special_cases_closed_forms():
    eps = np.finfo(np.float64).eps
    (q, w, _, _), _, (q1, w1) = _special("omega_zero", exact=False)
    np.testing.assert_allclose(q1, q, atol=4 * eps)
    np.testing.assert_array_equal(w1, 0)
    (q, w, _, _), _, (q1, w1) = _special("t_zero", exact=False)
    np.testing.assert_allclose(q1, q, atol=4 * eps)
    np.testing.assert_allclose(w1, w, atol=8 * eps)
    # Sphere: rotation at constant ω, q(t) = exp(ω t) ⊗ q0. A DMV step of angle θ turns by θ' with
    # sin θ' = θ (modified moment × I), and the modified moments are the series of sin θ / θ to θ^8:
    # each of the two steps (θ = |ω|t/2) falls short by θ^11 / (11! cos θ), 1.1e-14 in all here.
    (q, w, _, t), _, (q1, w1) = _special("sphere", exact=False)
    theta = float(jnp.linalg.norm(w) * t) / 2
    truncation = 2 * theta**11 / (math.factorial(11) * math.cos(theta))
    assert float(quat.angle_between(q1, quat.multiply(quat.exp(w * t), q))) < truncation + 8 * eps
    np.testing.assert_allclose(w1, w, atol=8 * eps)
    # Spin about a principal axis (even the unstable intermediate one) is steady: ω exactly, the
    # angle within the truncation bound of the random states.
    (q, w, _, t), _, (q1, w1) = _special("steady_intermediate", exact=False)
    angle = float(quat.angle_between(q1, quat.multiply(quat.exp(w * t), q)))
    assert angle < _bound(float(jnp.linalg.norm(w) * t)), angle
    np.testing.assert_allclose(w1, w, atol=8 * eps)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["symmetric_12", "symmetric_23", "t_negative", "needle_short", "long_flow"])
def test_special_cases_against_exact(name):
    (_, w, _, t), exact, rotor = _special(name)
    angle, omega = _errors(rotor, exact)
    bound = _bound(float(jnp.linalg.norm(w) * jnp.abs(t)))
    assert angle < bound and omega < bound, (angle, omega, bound)


def test_outside_valid_range_is_nan():
    """The needle's modified moments lose their digits to cancellation: NaN, not noise."""
    _, _, (q1, w1) = _special("needle_long", exact=False)
    assert np.all(np.isnan(q1)) and np.all(np.isnan(w1))


@pytest.mark.slow
def test_substeps_argument():
    (q, w, moments, t), exact, _ = _special("long_flow")
    with pytest.raises(ValueError, match="substeps"):
        free_rotor(q, w, moments, t, substeps=0)
    # A fixed count: one DMV step may turn by at most 1 rad, so two are NaN at |ω| t = 4.4, and
    # eight (0.55 rad each) are the free motion to their truncation error, 8 × 1e-8 (0.55/0.6)^11.
    assert np.all(np.isnan(free_rotor(q, w, moments, t, substeps=2)[0]))
    q8, w8 = free_rotor(q, w, moments, t, substeps=8)
    angle, omega = _errors((q8, w8), exact)
    assert angle < 1e-8 and omega < 1e-8, (angle, omega)


def test_substeps_for_rule():
    """At least two steps (the common range costs what it did), at most 64, ⌈|ω| t / a⌉ between."""
    angles = jnp.array([0.0, 0.3, 0.4, 0.41, 1.0, 10.0, 1e3, jnp.inf])
    np.testing.assert_array_equal(substeps_for(angles, jnp.float64), [2, 2, 2, 3, 5, 50, 64, 64])
    np.testing.assert_array_equal(
        substeps_for(angles.astype(jnp.float32), jnp.float32), [2, 2, 2, 2, 2, 20, 64, 64]
    )


FAST_BODIES = {"generic": (1.0, 2.0, 3.0), "sphere": (2.0, 2.0, 2.0), "symmetric": (1.0, 1.0, 1.9)}
FAST_TURNS = (1.0, 3.15, 6.0, 10.0)


# One case in the default set; the rest in the slow set (each compiles its own programs).
TURN_CASES = [
    pytest.param(body, dtype, marks=() if (body, dtype) == ("generic", jnp.float64) else pytest.mark.slow)
    for body in FAST_BODIES
    for dtype in (jnp.float64, jnp.float32)
]


@pytest.mark.parametrize(("body", "dtype"), TURN_CASES)
def test_any_turn_up_to_ten_rad(body, dtype):
    """Finite and exact to round-off for |ω| |t| up to 10 rad per flow, the step count chosen per body
    (one batch mixes all turns). float64: `_bound`. float32 against the float64 exact flow: each of
    the n <= 20 steps of <= 0.5 rad rounds ~10 operations (10 n eps in ω), and the orientation error
    grows with the angle turned at that ω error: 10 n eps (1 + turn)."""
    moments = jnp.asarray(FAST_BODIES[body])
    q, w = _states(8, seed=5)
    turns = np.repeat(FAST_TURNS, 2)
    w = w * turns[:, None]
    # Compiled: eagerly, each of the oracle's operations compiled a program of its own (10.5 -> 5.2 s).
    exact_flow = jax.jit(jax.vmap(analytic.free_motion, (0, 0, None, None)))
    exact = exact_flow(jnp.asarray(q), jnp.asarray(w), moments, 1.0)
    args = (jnp.asarray(q, dtype), jnp.asarray(w, dtype), moments.astype(dtype), jnp.asarray(1.0, dtype))
    got = jax.jit(free_rotor)(*args)
    assert got[0].dtype == dtype
    assert np.all(np.isfinite(got[0])) and np.all(np.isfinite(got[1]))
    angle, omega = _errors(jax.tree.map(lambda a: a.astype(jnp.float64), got), exact)
    if dtype == jnp.float64:
        bound = _bound(turns)
    else:
        n = np.maximum(2, np.ceil(turns / 0.5))
        bound = 10 * n * np.finfo(np.float32).eps * (1 + turns)
    assert np.all(angle < bound) and np.all(omega / turns < bound), (angle, omega / turns, bound)


def test_gpu_loop_form_any_turn(monkeypatch):
    """The while loop as traced for a GPU (`_rotor_loop.LOOP_BATCH` = 8 DMV steps per iteration, each
    body's steps past the first two rounded up to a multiple of 8) is exact to round-off at every
    turn up to 10 rad, float64 (`_bound` with the rounded counts), and its steps are the CPU form's
    (same results where the counts agree: ``|ω| t <= 0.4`` and 2 + 8 steps at 2 rad, 10 steps)."""
    monkeypatch.setattr(_rotor_loop, "LOOP_BATCH", 8)
    moments = jnp.asarray(FAST_BODIES["generic"])
    q, w = _states(8, seed=5)
    turns = np.array([0.3, 0.4, 2.0, 3.15, 6.0, 10.0, 1.0, 2.0])
    w = jnp.asarray(w * turns[:, None])
    # Traced afresh (free_rotor's own jit would reuse its CPU-form trace).
    got = jax.jit(_rotor.free_rotor.__wrapped__)(jnp.asarray(q), w, moments, 1.0)
    exact = jax.jit(jax.vmap(analytic.free_motion, (0, 0, None, None)))(jnp.asarray(q), w, moments, 1.0)
    angle, omega = _errors(got, exact)
    bound = _bound(turns, loop_batch=8)
    assert np.all(angle < bound) and np.all(omega / turns < bound), (angle, omega / turns, bound)
    same = np.isin(turns, (0.3, 0.4, 2.0))
    cpu_form = jax.jit(_rotor.free_rotor.__wrapped__, static_argnames="substeps")
    for k in np.flatnonzero(same):
        n = 2 if turns[k] <= 0.4 else 10
        expected = cpu_form(jnp.asarray(q[k]), w[k], moments, 1.0, substeps=n)
        # The same DMV steps, but the fixed count runs h = t/n on m (the rule: t/2 on (2/n) m).
        np.testing.assert_allclose(got[0][k], expected[0], rtol=0, atol=1e-14)


def test_batched_loop_is_each_body_alone():
    """Under `jax.vmap` the extra steps run as one loop over the batch up to the largest count,
    each body kept once its own count is done (`_rotor_loop._repeat`'s rule). A batch mixing 2 to 50
    steps equals each body integrated alone (the same DMV steps in the same order; bounded by a few
    ulp per step, 50 × 4 eps, in case XLA vectorises the arithmetic differently), also when all
    bodies share one count (an unbatched count) and under two nested `vmap`s."""
    moments = jnp.asarray((1.0, 2.0, 3.0))
    q, w = _states(6, seed=11)
    turns = np.array([0.1, 0.3, 0.5, 2.0, 3.15, 10.0])
    q, w = jnp.asarray(q), jnp.asarray(w * turns[:, None])
    rotor = jax.jit(_rotor.free_rotor.__wrapped__)
    alone = [rotor(q[k], w[k], moments, 1.0) for k in range(len(turns))]
    alone = tuple(jnp.stack([a[i] for a in alone]) for i in range(2))
    tol = 50 * 4 * np.finfo(np.float64).eps
    batched = jax.jit(jax.vmap(rotor, (0, 0, None, None)))(q, w, moments, 1.0)
    for got, want in zip(batched, alone, strict=True):
        np.testing.assert_allclose(got, want, rtol=0, atol=tol)
    nested = jax.jit(jax.vmap(jax.vmap(rotor, (0, 0, None, None)), (0, 0, None, None)))(
        q.reshape(2, 3, 4), w.reshape(2, 3, 3), moments, 1.0
    )
    for got, want in zip(nested, alone, strict=True):
        np.testing.assert_allclose(got.reshape(want.shape), want, rtol=0, atol=tol)
    # One ω for all (the count unbatched): 16 steps for every orientation.
    shared = jax.jit(jax.vmap(rotor, (0, None, None, None)))(q, w[4], moments, 1.0)
    for k in range(len(turns)):
        want = rotor(q[k], w[4], moments, 1.0)
        np.testing.assert_allclose(shared[0][k], want[0], rtol=0, atol=tol)
        np.testing.assert_allclose(shared[1][k], want[1], rtol=0, atol=tol)


@pytest.mark.slow
@pytest.mark.parametrize("loop_batch", [1, 4])
def test_gradients_beyond_the_first_steps(monkeypatch, loop_batch):
    """The extra steps' derivative rule (a carried Jacobian) agrees with the exact solution's
    derivatives in the moments, ω and t, in reverse and forward mode, at 3 rad per flow (15 steps;
    with 4 steps per loop iteration, the GPU form, 18). Tolerance: the values agree to ~1e-13
    (`_bound`); derivatives amplify the difference by the flow's sensitivity (~turn² here): 1e-9."""
    monkeypatch.setattr(_rotor_loop, "LOOP_BATCH", loop_batch)
    free_rotor = jax.jit(_rotor.free_rotor.__wrapped__)  # traced afresh, with this loop form
    q0 = jnp.asarray(_states(1, seed=9)[0][0])

    def loss(fn):
        def f(x):  # x = (moments, ω, t)
            q1, w1 = fn(q0, x[3:6], x[:3], x[6])
            return jnp.sum(jnp.sin(q1)) + jnp.sum(w1**2)

        return f

    x = jnp.array([1.0, 2.0, 3.0, 0.9, 2.0, -2.0, 1.0])
    # Compiled: run eagerly, each derivative dispatched its thousands of operations one by one.
    exact = jax.jit(jax.grad(loss(analytic.free_motion)))(x)
    np.testing.assert_allclose(jax.jit(jax.grad(loss(free_rotor)))(x), exact, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(jax.jit(jax.jacfwd(loss(free_rotor)))(x), exact, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("dtype", [jnp.float32, jnp.float64])
def test_long_run_conservation(dtype):
    """10⁴ calls (|ω| t = 0.05) as a splitting makes them, with the principal-frame round trip
    ``q ⊗ r* ⊗ r`` between calls: |L| and the energy random-walk at round-off and do not drift.

    Per call each invariant moves by the difference of two measurements of it (at input and at
    output, ~6 roundings each: the frame change, the moments, the sum): at most ~12 eps, in
    practice random, so after n calls ~12 eps √n as a bound on the spread (×2 for the energy,
    quadratic in ω), and a mean over 64 bodies within 4 eps √n of zero. A bias of even 0.1 ulp
    per call (normalise-then-rotate frame changes had 0.3) would reach ~10 eps √n in the mean.
    """
    n_calls, n_bodies = 10_000, 64
    moments = jnp.array([1.0, 2.0, 3.0], dtype)
    r = jax.jit(quat.exp)(jnp.array([0.4, -0.7, 0.25], dtype))
    q, w = (jnp.asarray(a, dtype) for a in _states(n_bodies, seed=3))
    step = jax.vmap(lambda q, w: free_rotor(q, w, moments, jnp.asarray(0.05, dtype)))

    @jax.jit
    def run(q, w):
        def body(carry, _):
            q, w = step(*carry)
            return (quat.multiply(quat.multiply(q, quat.conjugate(r)), r), w), None

        return jax.lax.scan(body, (q, w), None, length=n_calls)[0]

    def invariants(q, w):
        q, w, m = (np.asarray(a, np.float64) for a in (q, w, moments))
        q = q / np.linalg.norm(q, axis=-1, keepdims=True)
        u = _body_frame(q, w)
        return np.linalg.norm(m * u, axis=-1), np.sum(m * u * u, axis=-1)

    (l0, e0), (l1, e1) = invariants(q, w), invariants(*run(q, w))
    eps, root_n = float(jnp.finfo(dtype).eps), np.sqrt(n_calls)
    dl, de = l1 / l0 - 1, e1 / e0 - 1
    assert np.all(np.isfinite(dl)) and np.all(np.isfinite(de))
    assert np.max(np.abs(dl)) < 12 * eps * root_n, np.max(np.abs(dl))
    assert np.max(np.abs(de)) < 24 * eps * root_n, np.max(np.abs(de))
    assert abs(np.mean(dl)) < 4 * eps * root_n and abs(np.mean(de)) < 4 * eps * root_n, (
        np.mean(dl),
        np.mean(de),
    )


def test_float32_keeps_dtype_and_accuracy():
    q64, w64 = _rows(_rotor_out(), 0, N_RANDOM)
    q1, w1 = _rotor32()
    q1, w1 = q1[:N_RANDOM], w1[:N_RANDOM]
    assert q1.dtype == jnp.float32 and w1.dtype == jnp.float32
    # Two DMV10 steps in float32: truncation ~7e-10 at |ω| t = 0.5, the rest is float32 round-off.
    assert np.max(np.abs(np.asarray(w1, np.float64) - np.asarray(w64))) < 64 * np.finfo(np.float32).eps
    assert np.max(np.abs(np.asarray(q1, np.float64) - np.asarray(q64))) < 64 * np.finfo(np.float32).eps


GRAD_CASES = (
    "omega_zero",
    "t_zero",
    "sphere",
    "symmetric_12",
    "symmetric_23",
    "steady_intermediate",
    "t_negative",
)


def _flat(x):
    q, w = free_rotor(x[:4], x[4:7], x[7:10], x[10])
    return jnp.concatenate([q, w])


@pytest.mark.slow
def test_gradients_match_central_differences():
    """Forward and reverse derivatives in q, ω, moments and t at the special points and a generic
    one, against central differences (step 1e-6: truncation ~1e-12 · f''', round-off ~1e-10)."""
    points = [jnp.concatenate([q, w, m, t[None]]) for (q, w, m, t), _, _ in map(_special, GRAD_CASES)]
    generic = jnp.concatenate(
        [Q0, quat.rotate(Q0, jnp.array([0.3, 1.0, 0.2])), jnp.array([1.0, 2.0, 3.0, 0.4])]
    )
    x = jnp.stack([*points, generic])
    jac_fwd = jax.jit(jax.vmap(jax.jacfwd(_flat)))(x)
    weights = jnp.asarray(np.random.default_rng(5).normal(size=7))
    grad_rev = jax.jit(jax.vmap(jax.grad(lambda x: jnp.dot(weights, _flat(x)))))(x)
    step = 1e-6
    shifts = step * jnp.eye(11)
    both = jax.jit(jax.vmap(jax.vmap(_flat)))(
        jnp.concatenate([x[:, None, :] + shifts[None], x[:, None, :] - shifts[None]], axis=1)
    )
    central = jnp.swapaxes((both[:, :11] - both[:, 11:]) / (2 * step), 1, 2)
    assert np.all(np.isfinite(jac_fwd)) and np.all(np.isfinite(grad_rev))
    np.testing.assert_allclose(jac_fwd, central, atol=1e-8)
    np.testing.assert_allclose(grad_rev, jnp.einsum("k,nki->ni", weights, jac_fwd), atol=1e-12)
