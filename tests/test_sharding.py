"""Particles sharded over 4 fake CPU devices (conftest.py): same results, same layout, no communication."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import MOMENTS, assert_same, contract_params, driven_problem, rotor_flows
from jax.sharding import AxisType, NamedSharding, PartitionSpec as P

import jaxrot
from jaxrot._integrate import _blocking


N_DEVICES = 4
COLLECTIVES = ("all-gather", "all-reduce", "all-to-all", "collective-permute", "reduce-scatter")

pytestmark = pytest.mark.skipif(
    jax.device_count() < N_DEVICES, reason="needs --xla_force_host_platform_device_count=4 (conftest.py)"
)


def mesh(axis_type):
    return jax.make_mesh((N_DEVICES,), ("p",), axis_types=(axis_type,))


def problem(n):
    state, _, dt, kwargs = driven_problem(jnp.float64, n)
    inertia = MOMENTS[None, :] * jnp.linspace(1, 2, n)[:, None]  # one per body
    return state, inertia, dt, dict(n_steps=6, save_every=2, **kwargs)


def shard(tree, sharding):
    return jax.tree_util.tree_map(lambda x: jax.device_put(x, sharding), tree)


def sharded_inputs(state, inertia, kwargs, m):
    """Every per-body array on the mesh, its body axis split over the devices."""
    rows = NamedSharding(m, P("p"))
    kwargs = dict(kwargs, drive=shard(kwargs["drive"], rows))
    field = kwargs["args"]["rotating_field"]
    amplitude = jaxrot.per_body(jax.device_put(field["amplitude"].value, rows))
    kwargs["args"] = {"rotating_field": {**field, "amplitude": amplitude}}
    return shard(state, rows), jax.device_put(inertia, rows), kwargs


@pytest.mark.parametrize("axis_type", [AxisType.Explicit, AxisType.Auto])
@pytest.mark.parametrize("scheme", contract_params())
def test_sharded_rollout_equals_one_device_and_keeps_the_layout(scheme, axis_type, default_emitters):
    state, inertia, dt, kwargs = problem(16)
    one = jaxrot.rollout(scheme, state, inertia, dt, **kwargs)
    m = mesh(axis_type)
    s, i, kw = sharded_inputs(state, inertia, kwargs, m)
    traj = jaxrot.rollout(scheme, s, i, dt, **kw)
    # XLA compiles each device's program on its own; its rewrites moved ``omega`` of "no_squish" and
    # "rozmanov" by 1-2 ulp (``q`` bit-equal), and "splitting" by up to 19 ulp (jax 0.12): 8 ulp, and
    # 50 per free-rotor flow of a step for the splittings (as in tests/test_blocking.py).
    assert_same(traj, one, ulps=max(8, 50 * rotor_flows(scheme)))
    for x in (traj.q, traj.omega):
        assert x.sharding.is_equivalent_to(NamedSharding(m, P(None, "p")), x.ndim)
        assert {s.data.shape[1] for s in x.addressable_shards} == {16 // N_DEVICES}


@pytest.mark.parametrize("axis_type", [AxisType.Explicit, AxisType.Auto])
@pytest.mark.parametrize("blocked", [False, True])
def test_per_body_torques_communicate_nothing(axis_type, blocked, monkeypatch):
    if blocked:  # 12 bodies a device in 3 blocks of 4
        monkeypatch.setattr(_blocking, "BLOCK_BODIES", 4)
    n = 12 * N_DEVICES
    state, inertia, dt, kwargs = problem(n)
    m = mesh(axis_type)
    s, i, kw = sharded_inputs(state, inertia, kwargs, m)
    run = jax.jit(lambda s, i: jaxrot.rollout("zhao", s, i, dt, **kw))
    hlo = run.lower(s, i).compile().as_text()
    assert not [c for c in COLLECTIVES if c in hlo]
    traj = run(s, i)
    assert_same(traj, jaxrot.rollout("zhao", state, inertia, dt, **kwargs), ulps=8)
    assert traj.q.sharding.is_equivalent_to(NamedSharding(m, P(None, "p")), 3)


def test_a_grid_of_bodies_sharded_on_its_first_axis():
    state, inertia, dt, kwargs = problem(16)
    grid = jaxrot.RotState(state.q.reshape(8, 2, 4), state.omega.reshape(8, 2, 3))
    m = mesh(AxisType.Explicit)
    traj = jaxrot.rollout("no_squish", shard(grid, NamedSharding(m, P("p"))), MOMENTS, dt, n_steps=4)
    one = jaxrot.rollout("no_squish", grid, MOMENTS, dt, n_steps=4)
    assert_same(traj, one, ulps=8)
    assert traj.q.sharding.is_equivalent_to(NamedSharding(m, P(None, "p")), 4)


def test_coupled_torque_gathers_across_devices_and_agrees():
    scene = jaxrot.SCENES["dipole_cloud"](jnp.float64)  # 16 needles, each feels all others
    m = mesh(AxisType.Explicit)
    state = shard(scene.state, NamedSharding(m, P("p")))
    call = dict(torque=scene.torque, args=scene.args)
    traj = jaxrot.rollout("zhao", state, scene.inertia, scene.dt, 20, **call)
    one = jaxrot.rollout("zhao", scene.state, scene.inertia, scene.dt, 20, **call)
    # A gather changes the order of the sums over other bodies: round-off only.
    np.testing.assert_allclose(traj.q, one.q, rtol=0, atol=1e-13)
    assert traj.q.sharding.is_equivalent_to(NamedSharding(m, P(None, "p")), 3)
