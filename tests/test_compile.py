"""jaxrot's own compiler options (`jaxrot._core._compile`): passed at top level, never nested."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrot
from jaxrot._core import _compile
from jaxrot._integrate import _run


def test_options_per_backend():
    assert jaxrot.compiler_options("cpu") == {"xla_cpu_experimental_ynn_fusion_type": ""}
    types = jaxrot.compiler_options("gpu")["xla_gpu_enable_command_buffer"].split(",")
    assert {"WHILE", "CONDITIONAL", "FUSION", "CUBLAS", "CUDNN", "CUSTOM_CALL"} <= set(types)
    assert jaxrot.compiler_options("cuda") == jaxrot.compiler_options("gpu")
    assert jaxrot.compiler_options("tpu") == {}
    assert jaxrot.compiler_options() == jaxrot.compiler_options(jax.default_backend())


@pytest.fixture
def fresh_gpu_options():
    _compile._gpu_options.cache_clear()
    yield
    _compile._gpu_options.cache_clear()


@pytest.mark.parametrize(
    "lists, expected",
    [
        (("NOT_A_TYPE,WHILE", "FUSION,WHILE,CONDITIONAL"), "FUSION,WHILE,CONDITIONAL"),
        (("NOT_A_TYPE,WHILE",), None),
    ],
)
def test_gpu_options_take_the_first_list_this_jaxlib_accepts(monkeypatch, fresh_gpu_options, lists, expected):
    """XLA checks the names when it compiles (on any backend: they are one proto's enum)."""
    monkeypatch.setattr(_compile, "_COMMAND_BUFFER_TYPES", lists)
    options = jaxrot.compiler_options("gpu")
    assert options == ({} if expected is None else {"xla_gpu_enable_command_buffer": expected})


def test_gpu_options_can_be_first_asked_for_inside_a_trace(fresh_gpu_options):
    """The probe compiles a program of its own from shapes: a user's jit around the call is no obstacle."""
    expected = _compile._COMMAND_BUFFER_TYPES[0]

    @jax.jit
    def inside(x):
        return x, jaxrot.compiler_options("gpu")["xla_gpu_enable_command_buffer"] == expected

    assert inside(1.0)[1]


def test_gpu_options_compile_and_change_nothing_on_this_backend():
    """What a GPU user passes to their jit compiles here too (XLA:CPU ignores command buffers)."""
    state = jaxrot.RotState(jnp.array([1.0, 0.0, 0.0, 0.0]), jnp.array([0.3, -1.0, 2.0]))

    def run(s):
        return jaxrot.rollout("splitting", s, jnp.array([1.0, 2.0, 3.0]), 0.01, 20).q

    gpu_options = jax.jit(run, compiler_options=jaxrot.compiler_options("gpu"))
    np.testing.assert_array_equal(gpu_options(state), jax.jit(run)(state))


@pytest.mark.skipif(jax.default_backend() != "cpu", reason="XLA:CPU option")
def test_options_turn_ynn_fusions_off():
    """The float64 renormalisation of 10⁴ bodies is what XLA:CPU 0.10.2 hands to YNNPACK."""
    q = jax.random.normal(jax.random.PRNGKey(0), (10_000, 4))
    state = jaxrot.RotState(jaxrot.quaternion.normalize(q), jnp.ones((10_000, 3)))

    def run(s):
        return jaxrot.rollout("no_squish", s, jnp.array([1.0, 2.0, 3.0]), 1e-3, 20, save_every=20).q[-1]

    text = jax.jit(run, compiler_options=jaxrot.compiler_options()).lower(state).compile().as_text()
    assert "__ynn_fusion" not in text


def test_top_level_calls_pass_the_options_and_nested_calls_do_not(monkeypatch):
    seen = []
    original = eqx.filter_jit

    def recording_filter_jit(fun, **kwargs):
        seen.append(kwargs)
        return original(fun, **kwargs)

    monkeypatch.setattr(_compile.eqx, "filter_jit", recording_filter_jit)
    double = _compile.filter_jit(lambda x: 2 * x)
    x = jnp.arange(3.0)
    np.testing.assert_array_equal(double(x), 2 * x)
    assert seen == [{}, {"compiler_options": jaxrot.compiler_options()}]
    # Nested in a user's jit, grad or vmap a jit with options is an error in JAX; the plain one runs.
    np.testing.assert_array_equal(jax.jit(double)(x), 2 * x)
    np.testing.assert_array_equal(jax.grad(lambda x: double(x).sum())(x), jnp.full(3, 2.0))
    np.testing.assert_array_equal(jax.vmap(double)(x), 2 * x)
    assert len(seen) == 2  # the top-level program was built once


def test_rollout_compiles_through_jaxrot_filter_jit():
    assert _run._rollout_flat.__wrapped__.__name__ == "_rollout_flat"
    assert _run._rollout_flat.__code__ is _compile.filter_jit(lambda: None).__code__


def test_rollout_under_a_user_jit_with_the_options_equals_the_top_level_call(default_emitters):
    state = jaxrot.RotState(jnp.array([1.0, 0.0, 0.0, 0.0]), jnp.array([0.3, -1.0, 2.0]))
    inertia = jnp.array([1.0, 2.0, 3.0])

    dt = jnp.asarray(0.01)

    def run(s, inertia, dt):  # arguments: closed over, XLA would fold them into constants
        return jaxrot.rollout("rkmk4", s, inertia, dt, 50).q

    top_level = run(state, inertia, dt)
    user_jit = jax.jit(run, compiler_options=jaxrot.compiler_options())
    np.testing.assert_array_equal(user_jit(state, inertia, dt), top_level)
