"""One contract for every scheme and model: the registry, `schemes_for`, and the binder's decision for
every scheme × model pair.

A scheme declares the models it integrates; the call names the model (`jaxrot._integrate._bind`).
For every registered scheme and every model: where the scheme declares the model, the call traces
(`jax.eval_shape`: the binder accepted it and the model's form of the scheme runs; nothing compiles);
where it does not, the call raises one `ValueError` before anything compiles, naming every scheme of
`schemes_for(model)` (each of which traces that very call: no circle of suggestions) and the entry
point where the scheme's own models need the other one.
"""

import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrot
from jaxrot._integrate import _overdamped, _run
from jaxrot.schemes import MODELS, REGISTRY


Q = jnp.array([[1.0, 0.0, 0.0, 0.0], [0.0, 0.6, 0.0, 0.8]])
STATE = jaxrot.RotState(Q, jnp.array([[0.3, 1.0, 0.2], [0.0, 0.1, 0.0]]))
INERTIA = jnp.array([1.0, 2.0, 3.0])
FRICTION = jnp.array([1.0, 1.0, 2.0])
ENTRY = {"vacuum": "jaxrot.rollout", "fluid": "jaxrot.rollout", "thermal": "jaxrot.rollout",
         "overdamped": "jaxrot.overdamped_rollout", "brownian": "jaxrot.overdamped_rollout"}  # fmt: skip


def call(model, scheme):
    """The call that runs ``model`` with ``scheme``: two bodies, two steps."""
    key = jax.random.key(0)
    if model == "vacuum":
        return jaxrot.rollout(scheme, STATE, INERTIA, 0.01, 2)
    if model == "fluid":
        return jaxrot.rollout(scheme, STATE, INERTIA, 0.01, 2, fluid=jaxrot.Fluid(FRICTION))
    if model == "thermal":
        return jaxrot.rollout(scheme, STATE, INERTIA, 0.01, 2, fluid=jaxrot.Fluid(FRICTION, kT=0.5), key=key)
    if model == "overdamped":
        return jaxrot.overdamped_rollout(Q, jaxrot.Fluid(FRICTION), 0.01, 2, scheme=scheme)
    return jaxrot.overdamped_rollout(Q, jaxrot.Fluid(FRICTION, kT=0.5), 0.01, 2, scheme=scheme, key=key)


@pytest.fixture
def nothing_compiles(monkeypatch):
    """The compiled loops of both entry points fail the test if reached."""

    def compiled(*args, **kwargs):
        raise AssertionError("a refused call reached the compiled loop")

    monkeypatch.setattr(_run, "_rollout_flat", compiled)
    monkeypatch.setattr(_overdamped, "_overdamped_flat", compiled)


def test_each_name_is_one_scheme_and_the_views_agree_with_schemes_for():
    assert len(REGISTRY) == 19  # 10 in vacuum, 3 in a fluid, 2 thermal, 2 more overdamped, 2 Brownian
    # The thermal (Brownian) schemes run the fluid (overdamped) call at kT = 0, so they list it.
    assert {"baoab", "exp_euler"} <= set(jaxrot.FLUID_SCHEMES)
    assert {"brownian_euler", "brownian_splitting"} <= set(jaxrot.OVERDAMPED_SCHEMES)
    for name, scheme in REGISTRY.items():
        assert scheme.name == name
        assert scheme.models and set(scheme.models) <= set(MODELS), name
    views = {
        "vacuum": jaxrot.SCHEMES,
        "fluid": jaxrot.FLUID_SCHEMES,
        "thermal": jaxrot.THERMAL_SCHEMES,
        "overdamped": jaxrot.OVERDAMPED_SCHEMES,
        "brownian": jaxrot.BROWNIAN_SCHEMES,
    }
    for model, view in views.items():
        assert dict(view) == jaxrot.schemes_for(model), model
        assert all(view[name] is REGISTRY[name] for name in view)
    # Every registered scheme integrates some model, and the five views cover the registry.
    assert set().union(*views.values()) == set(REGISTRY)
    assert jaxrot.SCHEMES["rkmk4"] is jaxrot.OVERDAMPED_SCHEMES["rkmk4"]  # one name, one scheme
    with pytest.raises(ValueError, match="`model` must be one of 'vacuum'"):
        jaxrot.schemes_for("liquid")


# Every scheme × model pair: the call runs exactly the schemes that declare its model (`models` is
# complete: a thermal scheme that runs the fluid call at kT = 0 declares "fluid", a Brownian one
# "overdamped"), and refuses every other.
PAIRS = [(name, model) for name in REGISTRY for model in MODELS]


@pytest.mark.parametrize("name, model", [p for p in PAIRS if p[1] in REGISTRY[p[0]].models])
def test_a_scheme_runs_every_model_it_declares(name, model):
    traj = jax.eval_shape(lambda: call(model, name))
    assert traj.q.shape == (3, 2, 4) and traj.omega.shape == (3, 2, 3)
    assert traj.q.dtype == Q.dtype


@pytest.mark.parametrize("name, model", [p for p in PAIRS if p[1] not in REGISTRY[p[0]].models])
def test_a_scheme_refuses_every_model_it_does_not_declare_naming_those_that_run_it(
    name, model, nothing_compiles
):
    with pytest.raises(ValueError) as raised:
        call(model, name)
    message = str(raised.value)
    assert f"{name!r}" in message
    for other in jaxrot.schemes_for(model):
        assert f"{other!r}" in message, (other, message)
    own_entries = {ENTRY[m] for m in REGISTRY[name].models}
    if ENTRY[model] not in own_entries:  # the scheme needs the other entry point: the message says which
        assert all(entry in message for entry in own_entries), message


def test_an_unknown_name_lists_the_schemes_of_the_call(nothing_compiles):
    for model in MODELS:
        with pytest.raises(ValueError, match=r"`scheme` must be one of") as raised:
            call(model, "brownian_eulr")
        assert all(f"{name!r}" in str(raised.value) for name in jaxrot.schemes_for(model)), model


def test_suggestions_do_not_circle():
    """`rollout("zhao", fluid=Fluid(kT=1), key=k)` names the thermal schemes, which run that call."""
    with pytest.raises(ValueError, match=r"'zhao' has no thermal noise.*'baoab'.*'exp_euler'") as raised:
        call("thermal", "zhao")
    assert "exp_rk4" not in str(raised.value)
    for name in re.findall(r"'(\w+)' \(weak order", str(raised.value)):
        jax.eval_shape(lambda name=name: call("thermal", name))


def test_the_other_entry_point_is_named():
    with pytest.raises(ValueError, match=r"'brownian_euler' integrates .*jaxrot.overdamped_rollout"):
        call("vacuum", "brownian_euler")
    with pytest.raises(ValueError, match=r"'baoab' integrates a body in a fluid.*jaxrot.rollout"):
        call("brownian", "baoab")
    with pytest.raises(ValueError, match=r"'zhao' integrates a body in vacuum.*jaxrot.rollout"):
        call("overdamped", "zhao")


@pytest.mark.parametrize("name", ["exp_midpoint", "baoab"])
def test_a_traced_temperature_without_a_key_fails_at_trace_time(name):
    """Under jit a traced kT may be > 0: without a key that is refused while tracing, with the words of
    the concrete case (no runtime callback); a key makes it the thermal model."""

    def inertial(kT, key=None):
        fluid = jaxrot.Fluid(FRICTION, kT=kT)
        return jaxrot.rollout(name, STATE, INERTIA, 0.01, 2, fluid=fluid, key=key).q

    with pytest.raises(ValueError, match=r"(?s)`fluid.kT` is traced.*`fluid.kT` > 0 .* needs a PRNG `key`"):
        jax.make_jaxpr(inertial)(0.5)
    if name == "baoab":
        jax.make_jaxpr(lambda kT: inertial(kT, jax.random.key(0)))(0.5)
    else:
        with pytest.raises(ValueError, match="'exp_midpoint' has no thermal noise"):
            jax.make_jaxpr(lambda kT: inertial(kT, jax.random.key(0)))(0.5)


def test_a_traced_temperature_without_a_key_fails_at_trace_time_overdamped():
    def overdamped(kT, scheme=None, key=None):
        fluid = jaxrot.Fluid(FRICTION, kT=kT)
        return jaxrot.overdamped_rollout(Q, fluid, 0.01, 2, scheme=scheme, key=key).q

    for scheme in (None, "lie_euler", "brownian_euler"):
        with pytest.raises(ValueError, match=r"(?s)`fluid.kT` is traced.*needs a PRNG `key`"):
            jax.make_jaxpr(lambda kT, scheme=scheme: overdamped(kT, scheme))(0.5)
    jax.make_jaxpr(lambda kT: overdamped(kT, key=jax.random.key(0)))(0.5)  # brownian_splitting


def test_a_fluid_built_outside_jit_keeps_its_model():
    """A Fluid passed through jit has a traced kT; the sign it recorded when built decides the model."""
    cold, warm = jaxrot.Fluid(FRICTION), jaxrot.Fluid(FRICTION, kT=0.5)
    jax.make_jaxpr(lambda f: jaxrot.rollout("exp_rk4", STATE, INERTIA, 0.01, 2, fluid=f).q)(cold)
    with pytest.raises(ValueError, match=r"`fluid.kT` > 0 .* needs a PRNG `key`"):
        jax.make_jaxpr(lambda f: jaxrot.rollout("baoab", STATE, INERTIA, 0.01, 2, fluid=f).q)(warm)


def test_at_zero_temperature_a_thermal_scheme_runs_without_noise():
    """At a concrete kT = 0 a thermal (Brownian) scheme runs the fluid (overdamped) call
    deterministically, a key given or not, and a fluid scheme runs with a key."""
    cold = jaxrot.Fluid(FRICTION)
    with_key = jaxrot.rollout("exp_rk4", STATE, INERTIA, 0.01, 2, fluid=cold, key=jax.random.key(0))
    without = jaxrot.rollout("exp_rk4", STATE, INERTIA, 0.01, 2, fluid=cold)
    # The comparisons in NumPy: an eager jnp comparison compiles a small program per shape.
    assert np.all(np.asarray(with_key.q) == np.asarray(without.q))
    a = jaxrot.rollout("baoab", STATE, INERTIA, 0.01, 2, fluid=cold)
    b = jaxrot.rollout("baoab", STATE, INERTIA, 0.01, 2, fluid=cold, key=jax.random.key(1))
    assert np.all(np.asarray(a.q) == np.asarray(b.q))
    for name in ("brownian_euler", "brownian_splitting"):
        c = jaxrot.overdamped_rollout(Q, cold, 0.01, 2, scheme=name)
        d = jaxrot.overdamped_rollout(Q, cold, 0.01, 2, scheme=name, key=jax.random.key(2))
        assert np.all(np.asarray(c.q) == np.asarray(d.q)), name
    # The default is the model's: rkmk4 at kT = 0, a key given or not.
    e = jaxrot.overdamped_rollout(Q, cold, 0.01, 2, key=jax.random.key(2))
    assert np.all(
        np.asarray(e.q) == np.asarray(jaxrot.overdamped_rollout(Q, cold, 0.01, 2, scheme="rkmk4").q)
    )
