"""A rollout's compiled memory depends on the saved states, not on the number of steps."""

import functools
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import contract_params

import jaxrot
from jaxrot._integrate import _blocking, _run


@functools.cache
def bodies(n):
    """``n`` bodies at distinct orientations, all spinning at (1, 1, 1). Built once per ``n`` and in
    one compiled program (eagerly, each of `exp`'s operations compiles a program of its own)."""
    q = jax.jit(jaxrot.quaternion.exp)(np.linspace(0.1, 1.0, 3 * n).reshape(n, 3))
    return jaxrot.RotState(q, jnp.asarray(np.ones((n, 3))))


@functools.cache
def heavy_top():
    """The heavy-top scene, built once (its construction runs eager operations)."""
    return jaxrot.SCENES["heavy_top"]()


def compiled_memory(scheme, n_bodies, n_steps, save_every, gradient=False):
    """XLA's memory accounting of a heavy-top rollout of ``n_bodies``, or with ``gradient`` of
    ``jax.grad`` of its last saved orientations with respect to the inertia."""
    state = bodies(n_bodies)
    top = heavy_top()

    def run(state, inertia):
        return jaxrot.rollout(
            scheme, state, inertia, 1e-3, n_steps, torque=top.torque, args=top.args, save_every=save_every
        )

    if gradient:
        program, example = jax.grad(lambda inertia: jnp.sum(run(state, inertia).q[-1])), top.inertia
    else:
        program, example = lambda state: run(state, top.inertia), state
    return jax.jit(program).lower(example).compile().memory_analysis()


@pytest.mark.parametrize(
    ("scheme", "blocked"),
    [pytest.param(p.values[0], False, marks=p.marks) for p in contract_params()]
    + [pytest.param("zhao", True, marks=pytest.mark.slow)],  # the blocked variant: 5-7 s of compiles
)
def test_memory_is_independent_of_the_number_of_steps(scheme, blocked, monkeypatch):
    if blocked:
        monkeypatch.setattr(_blocking, "BLOCK_BODIES", 16)  # 64 bodies in 4 blocks
    sizes = {}
    for n_steps, save_every in [(100, 100), (10_000, 10_000), (1000, 100), (100_000, 10_000)]:
        stats = compiled_memory(scheme, 64, n_steps, save_every)
        sizes[n_steps] = (stats.temp_size_in_bytes, stats.output_size_in_bytes)
    assert sizes[100] == sizes[10_000]  # 2 saved states
    assert sizes[1000] == sizes[100_000]  # 11 saved states
    # The output holds the saved states: t, and q and omega of 64 bodies, float64.
    assert sizes[1000][1] - sizes[100][1] == 9 * (1 + 64 * 7) * 8


@pytest.mark.parametrize("scheme", ["no_squish", pytest.param("rozmanov", marks=pytest.mark.slow)])
@pytest.mark.parametrize("runtime_check", [False, True])
def test_the_compiled_core_keeps_the_final_carry_only_when_asked(scheme, runtime_check):
    """`rollout` without ``return_carry`` gets the saved states and the scheme's summary of the
    final carry (rozmanov: its count of unconverged steps), not the carry itself."""
    n = 64
    state = bodies(n)
    run = _run.prepare_run(
        scheme, state, jnp.array([1.0, 2.0, 3.0]), 1e-3, 20, None, None, 10, 0.0, None, True, runtime_check
    )

    def output_bytes(keep_carry):
        """Bytes of the outputs, less XLA's table of 8-byte pointers to them."""
        flat = jax.jit(lambda s: run.flat(run.n_saves, state=s, keep_carry=keep_carry))
        table = 8 * len(jax.tree_util.tree_leaves(jax.eval_shape(flat, run.flat_state)))
        return flat.lower(run.flat_state).compile().memory_analysis().output_size_in_bytes - table

    saved = 3 * (1 + n * 7) * 8  # t, q and omega of 3 saved states, float64
    summary = 8 if scheme == "rozmanov" else 0
    report = output_bytes(False) - saved - summary
    assert report == (n * (4 + 4 + 8) if runtime_check else 0)  # StepReport: step, kind, norm error
    assert output_bytes(True) - report - saved > n * 7 * 8  # the carry: at least a state per body


def memory_maps():
    with open("/proc/self/maps") as f:
        return sum(1 for _ in f)


@pytest.mark.slow
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="counts /proc/self/maps")
def test_clear_caches_releases_the_mappings_of_compiled_rollouts():
    """docs/performance.md, "Many compiles in one process": each compiled rollout holds memory mappings
    until `jax.clear_caches()` (conftest.py relies on it to stay under vm.max_map_count)."""
    state = jaxrot.RotState(jnp.array([1.0, 0.0, 0.0, 0.0]), jnp.array([0.1, 0.2, 0.3]))
    inertia = jnp.array([1.0, 2.0, 3.0])
    before = memory_maps()
    for n_steps in range(10, 15):
        jaxrot.rollout("no_squish", state, inertia, 0.01, n_steps)
    added = memory_maps() - before
    assert added > 5 * 20  # per program measured: 162 (jax 0.10.2), 38 (jax 0.12)
    jax.clear_caches()
    assert memory_maps() < before + 0.1 * added


@pytest.mark.parametrize("scheme", contract_params())
def test_a_gradient_keeps_each_steps_carry_not_its_stages(scheme):
    """Reverse mode through `rollout` keeps, per step and body, the scheme's carry and nothing more:
    the step is checkpointed (`jaxrot._integrate._run`) and its stages are recomputed in the reverse
    pass. The carry is the least a reverse pass through a loop can keep; any stage value kept as well
    adds at least a (3,) vector of each of several stages (before the checkpoint: 17-28x the carry,
    measured). The bound, twice the carry, leaves room for XLA's layout, not for a stage."""
    n = 8
    tape = {
        n_steps: compiled_memory(scheme, n, n_steps, n_steps, gradient=True).temp_size_in_bytes
        for n_steps in (100, 200)
    }
    top = heavy_top()
    carry = jax.eval_shape(
        lambda s: jaxrot.SCHEMES[scheme].init(s, 0.0, top.inertia, top.torque, top.args),
        jax.tree_util.tree_map(lambda x: x[0], bodies(1)),  # one body
    )
    carry_bytes = sum(x.size * x.dtype.itemsize for x in jax.tree_util.tree_leaves(carry))
    per_step_and_body = (tape[200] - tape[100]) / (100 * n)
    assert 0 < per_step_and_body <= 2 * carry_bytes  # > 0: the tape grows with the steps (a reverse pass)
