"""Chunked rollouts: bit-identical to one call, saved and resumed, progress, bounded compilation."""

import jax.numpy as jnp
import numpy as np
import pytest
from helpers import MOMENTS, assert_same, contract_params, driven_problem

import jaxrot


N_BODIES = 3


def problem(dtype):
    return driven_problem(dtype, N_BODIES)


# float64: save_every = 2, two saves a chunk; float32: one step per save and a shorter last chunk
# of a lone step (the case where XLA removes the loop, see `_rollout_flat`).
SETUPS = {
    jnp.float64: ({"n_steps": 8, "save_every": 2}, 4, [3, 2], [4, 8]),
    jnp.float32: ({"n_steps": 5}, 2, [3, 2, 1], [2, 4, 5]),
}


def concatenate(chunks):
    return jaxrot.Trajectory(*(jnp.concatenate(parts) for parts in zip(*chunks, strict=True)))


@pytest.mark.parametrize("dtype", [jnp.float64, jnp.float32])
@pytest.mark.parametrize("scheme", contract_params())
def test_chunks_concatenate_to_one_call_bit_for_bit(scheme, dtype, default_emitters):
    state, inertia, dt, kwargs = problem(dtype)
    setup, chunk_steps, lengths, steps = SETUPS[dtype]
    one, carry = jaxrot.rollout(scheme, state, inertia, dt, **setup, **kwargs, return_carry=True)
    pieces = list(
        jaxrot.rollout_chunks(scheme, state, inertia, dt, **setup, **kwargs, chunk_steps=chunk_steps)
    )
    assert [len(c.t) for c, _ in pieces] == lengths  # the first holds the initial state too
    assert [ckpt.step for _, ckpt in pieces] == steps
    assert_same(concatenate([c for c, _ in pieces]), one)
    assert_same(pieces[-1][1].carry, carry)
    # rollout(chunk_steps=...) is the same concatenation.
    assert_same(jaxrot.rollout(scheme, state, inertia, dt, **setup, **kwargs, chunk_steps=chunk_steps), one)


def test_save_load_resume_gives_the_one_call_result(tmp_path):
    # rozmanov carries the last torque and iteration counters: the carry, not the state, must resume.
    state, inertia, dt, kwargs = problem(jnp.float64)
    setup = dict(n_steps=10, save_every=2)
    one, carry = jaxrot.rollout("rozmanov", state, inertia, dt, **setup, **kwargs, return_carry=True)
    chunks = jaxrot.rollout_chunks("rozmanov", state, inertia, dt, **setup, **kwargs, chunk_steps=4)
    first, checkpoint = next(chunks)
    del chunks  # the run "stops" here
    path = jaxrot.save_checkpoint(tmp_path / "run", checkpoint)
    assert path.endswith("run.npz")
    loaded = jaxrot.load_checkpoint(path)
    assert loaded._replace(carry=None) == checkpoint._replace(carry=None)
    assert loaded.batch_shape == (N_BODIES,) and loaded.dtype == "float64" and loaded.step == 4
    rest = list(
        jaxrot.rollout_chunks("rozmanov", state, inertia, dt, **setup, **kwargs, chunk_steps=4, resume=loaded)
    )
    assert [ckpt.step for _, ckpt in rest] == [8, 10]
    assert_same(concatenate([first] + [c for c, _ in rest]), one)
    assert_same(rest[-1][1].carry, carry)
    # Resuming at the end yields nothing.
    end = jaxrot.rollout_chunks(
        "rozmanov", state, inertia, dt, **setup, **kwargs, chunk_steps=4, resume=rest[-1][1]
    )
    assert list(end) == []


def small_state():
    return jaxrot.RotState(jnp.array([1.0, 0, 0, 0]), jnp.array([0.3, 1.0, 0.2]))


def small_run(**overrides):
    kwargs = dict(
        scheme="zhao", state=small_state(), inertia=MOMENTS, dt=0.01, n_steps=8, save_every=2, chunk_steps=4
    )
    kwargs.update(overrides)
    return jaxrot.rollout_chunks(**kwargs)


@pytest.mark.parametrize(
    "field, overrides",
    [
        ("scheme", {"scheme": "euler"}),
        ("dt", {"dt": 0.02}),
        ("t0", {"t0": 1.0}),
        ("save_every", {"save_every": 4}),
        ("n_steps", {"n_steps": 12}),
        ("batch_shape", {"state": jaxrot.RotState(jnp.array([[1.0, 0, 0, 0]] * 2), jnp.ones((2, 3)))}),
        (
            "dtype",
            {"state": jaxrot.RotState(jnp.array([1.0, 0, 0, 0], jnp.float32), jnp.ones(3, jnp.float32))},
        ),
    ],
)
def test_resume_with_other_settings_is_rejected_naming_the_field(field, overrides):
    _, checkpoint = next(small_run())
    with pytest.raises(ValueError, match=f"`{field}`"):
        small_run(resume=checkpoint, **overrides)  # raised at the call, before any chunk runs


def test_bad_chunk_steps_and_a_damaged_checkpoint_are_rejected(tmp_path):
    for chunk_steps in (0, 3, 2.0):
        with pytest.raises(ValueError, match="`chunk_steps`"):
            small_run(chunk_steps=chunk_steps)
    with pytest.raises(ValueError, match=r"`save_every` \(= 2\) must divide `n_steps` \(= 9\)"):
        small_run(n_steps=9)  # at the call, before any chunk
    with pytest.raises(ValueError, match="multiple of `save_every`.*Use 2 or 4"):
        small_run(chunk_steps=3)
    with pytest.raises(ValueError, match="`chunk_steps`"):
        jaxrot.rollout("zhao", small_state(), MOMENTS, 0.1, 4, save_every=2, chunk_steps=1)
    _, checkpoint = next(small_run())
    with pytest.raises(ValueError, match="`carry`"):
        small_run(resume=checkpoint._replace(carry=checkpoint.carry.q))
    with pytest.raises(ValueError, match="`step`"):
        small_run(resume=checkpoint._replace(step=3))
    np.savez(tmp_path / "other.npz", x=np.zeros(3))
    with pytest.raises(ValueError, match="not a jaxrot checkpoint"):
        jaxrot.load_checkpoint(tmp_path / "other.npz")


def test_progress_bar_draws_and_changes_nothing(capsys):
    state, inertia, dt, kwargs = problem(jnp.float64)
    one = jaxrot.rollout("zhao", state, inertia, dt, 10, save_every=2, **kwargs)
    capsys.readouterr()
    with_bar = jaxrot.rollout("zhao", state, inertia, dt, 10, save_every=2, **kwargs, progress=True)
    err = capsys.readouterr().err
    assert "rollout zhao" in err and "10/10" in err  # counts steps
    assert_same(with_bar, one)
    # The default is about 100 chunks of whole saves.
    from jaxrot._integrate._chunked import default_chunk_steps

    assert default_chunk_steps(10_000, 10) == 100 and default_chunk_steps(1001, 1) == 11
    assert default_chunk_steps(5, 2) == 2 and default_chunk_steps(0, 1) == 1


def counting_torque():
    """A torque that counts its traces: jax traces once per compilation and never calls it again."""
    calls = []

    def torque(t, q, omega, args):
        calls.append(1)
        return jnp.stack([jnp.sin(t), jnp.cos(t), jnp.zeros_like(t)])

    return torque, calls


@pytest.mark.slow
def test_chunks_of_one_size_compile_once():
    state = small_state()

    def traces(n_steps):
        torque, calls = counting_torque()
        for _ in jaxrot.rollout_chunks("zhao", state, MOMENTS, 0.01, n_steps, torque=torque, chunk_steps=4):
            pass
        return len(calls)

    # Two full chunks and a short one, against seven full chunks and a short one: no more traces.
    assert traces(10) == traces(30) > 0
    torque, calls = counting_torque()
    jaxrot.rollout("zhao", state, MOMENTS, 0.01, 30, torque=torque)
    one_call = len(calls)
    # The initial carry (no steps), full chunks and the last chunk: three programs at most.
    assert traces(30) <= 3 * one_call


def test_runtime_check_names_the_same_global_step():
    def blows_up(t, q, omega, args):
        return jnp.where(t > 0.064, jnp.nan, 0.0) * jnp.ones(3)

    state = small_state()
    run = dict(torque=blows_up, save_every=2, runtime_check=True)
    with pytest.raises(jaxrot.IntegrationError) as one:
        jaxrot.rollout("euler", state, MOMENTS, 0.01, 20, **run)
    assert "at step 8 " in str(one.value)
    chunks = jaxrot.rollout_chunks("euler", state, MOMENTS, 0.01, 20, chunk_steps=4, **run)
    first, _ = next(chunks)  # steps 1..4 are fine
    assert first.t.shape == (3,)
    with pytest.raises(jaxrot.IntegrationError) as chunked:
        next(chunks)
    assert str(chunked.value) == str(one.value)


def test_scheme_warnings_point_at_the_callers_line():
    # rozmanov with one iteration reports unconverged half steps; the warning must name this file,
    # not jaxrot's wrappers (`particle_sharded`, `rollout` delegating to the chunks).
    scheme = jaxrot.schemes.Rozmanov(max_iter=1)
    state = jaxrot.RotState(jnp.array([1.0, 0, 0, 0]), jnp.array([30.0, 100.0, 20.0]))
    with pytest.warns(RuntimeWarning) as record:
        jaxrot.rollout(scheme, state, MOMENTS, 0.1, 5)
        jaxrot.rollout(scheme, state, MOMENTS, 0.1, 5, chunk_steps=2)
        list(jaxrot.rollout_chunks(scheme, state, MOMENTS, 0.1, 5, chunk_steps=2))
    assert [w.filename for w in record] == [__file__] * 3
