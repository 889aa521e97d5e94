"""Cache blocking (`jaxrot._integrate._blocking`): bit-identical to the unblocked loop; never coupled."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import MOMENTS, assert_same, contract_params, driven_problem, rotor_flows

import jaxrot
from jaxrot import quaternion as quat
from jaxrot._integrate import _blocking, _run


@pytest.fixture
def tiny_blocks(monkeypatch):
    """Blocks of 4 bodies, so that a dozen bodies are blocked."""
    monkeypatch.setattr(_blocking, "BLOCK_BODIES", 4)


def test_block_counts():
    block = 4
    assert _blocking.n_blocks_for(7, block) == 1  # fewer than two blocks' worth
    assert _blocking.n_blocks_for(12, block) == 3  # a divisor: no padding
    assert _blocking.n_blocks_for(13, block) == 4  # prime: padded
    assert _blocking.n_blocks_for(1 << 20) == 64  # 16384 bodies a block
    assert _blocking.n_blocks_for(10**6) == 100  # blocks of 10⁴ (a multiple of 8), not 64 of 15625
    # Sharded: the count must divide each device's share, else no blocking.
    assert _blocking.n_blocks_for(48, block, shards=4) == 3
    assert _blocking.n_blocks_for(52, block, shards=4) == 1  # 13 a device
    assert _blocking.n_blocks_for(50, block, shards=4) == 1  # does not split evenly


@pytest.mark.parametrize("n", [12, 13])
def test_blocks_round_trip_with_a_strided_split(n):
    x = jnp.arange(n * 2).reshape(n, 2)
    n_blocks = _blocking.n_blocks_for(n, 4)
    blocks = _blocking.to_blocks(x, n_blocks)
    assert blocks.shape == (n_blocks, -(-n // n_blocks), 2)
    np.testing.assert_array_equal(blocks[1, 2], x[2 * n_blocks + 1])  # body b·n_blocks + i in block i
    np.testing.assert_array_equal(_blocking.from_blocks(blocks, n, body_axis=0), x)
    saved = jnp.stack([blocks, 10 * blocks], axis=1)  # (n_blocks, 2 saves, per_block, 2)
    np.testing.assert_array_equal(_blocking.from_blocks(saved, n, body_axis=1), jnp.stack([x, 10 * x]))


def blocking_cases():
    """``(n, scheme)``: 13 bodies in blocks of 4 (a ragged last block) for one scheme of each family;
    12 (an even split) for Zhao alone: how bodies are split into blocks does not depend on the scheme,
    and the ragged case runs every carry through full blocks as well."""
    ragged = [pytest.param(13, p.values[0], marks=p.marks, id=f"13-{p.values[0]}") for p in contract_params()]
    return [*ragged, pytest.param(12, "zhao", marks=pytest.mark.slow, id="12-zhao")]


@pytest.mark.parametrize("dtype", [jnp.float64, jnp.float32])
@pytest.mark.parametrize("n, scheme", blocking_cases())
def test_blocked_rollout_is_bit_identical(scheme, dtype, n, monkeypatch, default_emitters):
    # Per-body args, per-particle inertia, a drive, the runtime check and the carry all blocked.
    state, _, dt, kwargs = driven_problem(dtype, n)
    inertia = jnp.broadcast_to(MOMENTS.astype(dtype), (n, 3)) * jnp.linspace(1, 2, n, dtype=dtype)[:, None]
    call = dict(n_steps=8, save_every=2, **kwargs, return_carry=True, runtime_check=True)
    one = jaxrot.rollout(scheme, state, inertia, dt, **call)
    monkeypatch.setattr(_blocking, "BLOCK_BODIES", 4)
    run = _run.prepare_run(
        scheme, state, inertia, dt, 8, kwargs["torque"], kwargs["args"], 2, 0.3, kwargs["drive"], False, False
    )
    assert run.n_blocks == _blocking.n_blocks_for(n, 4) > 1
    # The same arithmetic per body. The exception is the free rotor of the splittings, whose code
    # compiled for a block rounds differently from the unblocked one (seen for "splitting": 4 ulp in
    # float64, 6 in float32 after 7 steps; srkn6b up to 126 ulp over its 5 rotor flows a step):
    # 50 ulp per rotor flow of a step.
    ulps = 50 * rotor_flows(scheme)
    assert_same(jaxrot.rollout(scheme, state, inertia, dt, **call), one, ulps)


@pytest.mark.slow
def test_blocked_chunks_and_gradients_match_unblocked(tiny_blocks):
    state, inertia, dt, kwargs = driven_problem(jnp.float64, 12)

    def final_angle(moments, blocked):
        traj = jaxrot.rollout("zhao", state, moments, dt, 20, **kwargs, chunk_steps=8 if blocked else None)
        return jnp.sum(quat.angle_between(traj.q[-1], state.q))

    # Compiled; the block size is read when the rollout is traced, and each value of the static
    # `blocked` traces anew.
    run = jax.jit(jax.value_and_grad(final_angle), static_argnums=1)
    value, grad = run(inertia, True)
    _blocking.BLOCK_BODIES = 1 << 30  # restored by the fixture
    value1, grad1 = run(inertia, False)
    assert np.all(np.isfinite(grad))
    np.testing.assert_array_equal(value, value1)
    # The gradient of the shared inertia sums over bodies, block by block: another order of the sum.
    np.testing.assert_allclose(grad, grad1, rtol=1e-13)


def test_coupled_bodies_are_not_blocked(tiny_blocks):
    scene = jaxrot.SCENES["dipole_cloud"](jnp.float64)
    n = scene.state.q.shape[0]
    assert _blocking.n_blocks_for(n) > 1
    run = _run.prepare_run(
        "zhao", scene.state, scene.inertia, scene.dt, 3, scene.torque, scene.args, 1, 0.0, None, False, False
    )
    assert run.n_blocks == 1
    field = jaxrot.SCENES["dipole_rotating_field"](jnp.float64)
    assert not _blocking.couples_bodies(field.torque, n, jnp.zeros(()), scene.state, field.args, None)


def test_only_cpu_bodies_are_blocked(tiny_blocks, monkeypatch):
    # A GPU needs every body at once: blocks ran one after another there (docs/performance.md).
    scene = jaxrot.SCENES["heavy_top"](jnp.float64)
    state = jaxrot.RotState(
        jnp.broadcast_to(scene.state.q, (64, 4)), jnp.broadcast_to(scene.state.omega, (64, 3))
    )
    assert _blocking.on_cpu(state.q)
    assert jax.jit(lambda q: jnp.asarray(_blocking.on_cpu(q)))(state.q)
    args = ("zhao", state, scene.inertia, 1e-3, 3, scene.torque, scene.args, 1, 0.0, None, False, False)
    assert _run.prepare_run(*args).n_blocks > 1
    monkeypatch.setattr(_blocking, "on_cpu", lambda x: False)
    assert _run.prepare_run(*args).n_blocks == 1
