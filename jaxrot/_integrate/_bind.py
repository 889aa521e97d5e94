"""Which scheme integrates which call: the model a call asks for, decided once, and the bound scheme.

A scheme is a method, a model what it integrates (`jaxrot.schemes`: every scheme declares its
``models``; `jaxrot.schemes_for` lists a model's). The call names the model:

- `jaxrot.rollout` without ``fluid``: ``"vacuum"``; with a `jaxrot.Fluid`: ``"fluid"`` at
  ``kT = 0`` and ``"thermal"`` at ``kT > 0`` with a ``key``;
- `jaxrot.overdamped_rollout`: ``"overdamped"`` at ``kT = 0``, ``"brownian"`` at ``kT > 0`` with a
  ``key``.

A thermal (Brownian) scheme also lists the fluid (overdamped) model: at ``kT = 0`` it runs without
noise, a key given or not (the same program). Whether ``kT`` is 0
is read from its value, or under ``jit`` from what `jaxrot.Fluid` recorded where it was built; a
``kT`` built from a traced value counts as a temperature when a ``key`` is given, and without one it
is refused at trace time: whether it is 0 is not known before the program runs. `scheme_for_call` checks the
scheme once, before anything compiles, and raises one `ValueError` that names the schemes that run
that very call (and the other entry point where the scheme's model needs it); `bind_fluid`,
`bind_thermal` and `bind_brownian` then give the model's form of the scheme and its arguments.
"""

import jax
import jax.numpy as jnp
import numpy as np

from .._fluid._fluid import Fluid, check_fluid, temperature_of
from .._inertia import is_diagonal_form
from .._particles import unwrap_per_body
from ..schemes import MODELS, THERMAL_MODELS, resolve_scheme, schemes_for
from ..schemes._brownian import BrownianStart, for_steps
from ..schemes._exponential import FluidArgs
from ..schemes._langevin import ThermalArgs
from ..schemes._noise import body_keys, check_key


INERTIAL, OVERDAMPED = "jaxrot.rollout", "jaxrot.overdamped_rollout"
# The models each entry point runs: (at kT = 0, at a temperature).
_ENTRY_MODELS = {INERTIAL: ("fluid", "thermal"), OVERDAMPED: ("overdamped", "brownian")}
_ENTRY_OF = {"vacuum": INERTIAL} | {model: entry for entry, pair in _ENTRY_MODELS.items() for model in pair}
DEFAULT_OVERDAMPED, DEFAULT_BROWNIAN = "rkmk4", "brownian_splitting"

_BODY = {
    "vacuum": "a body in vacuum",
    "fluid": "a body in a fluid at kT = 0",
    "thermal": "a body in a fluid at a temperature",
    "overdamped": "a body without inertia in a fluid at kT = 0 (the overdamped model)",
    "brownian": "a body without inertia in a fluid at a temperature (Brownian rotation)",
}
_HOW = {
    "vacuum": "call jaxrot.rollout(scheme, state, inertia, dt, n_steps) without `fluid`",
    "fluid": "pass fluid=jaxrot.Fluid(friction) to jaxrot.rollout",
    "thermal": "pass fluid=jaxrot.Fluid(friction, kT=...) and a PRNG key=jax.random.key(0) to jaxrot.rollout",
    "overdamped": "call jaxrot.overdamped_rollout(q, fluid, dt, n_steps, scheme=...)",
    "brownian": "call jaxrot.overdamped_rollout(q, jaxrot.Fluid(friction, kT=...), dt, n_steps, scheme=..., "
    "key=jax.random.key(0))",
}
_NEEDS_KEY = (
    "`fluid.kT` > 0 (a fluid at a temperature) needs a PRNG `key`, e.g. key=jax.random.key(0): the thermal "
    "torque is random."
)
_TRACED = (
    "`fluid.kT` is traced (under jax.jit or another transformation), so whether it is 0 is not known "
    "before the program runs: "
)
_DETERMINISTIC = "Pass kT=0 for a deterministic run."
_DETERMINISTIC_TRACED = (
    "For a deterministic run give kT as a concrete 0 (a Python number, or a Fluid built outside the traced "
    "function)."
)


def candidates(model: str) -> str:
    """The schemes of ``model`` as a user reads them: ``'exp_midpoint' (order 2), 'exp_rk4' (order 4)``."""
    kind = "weak order" if model in THERMAL_MODELS else "order"
    return ", ".join(f"{name!r} ({kind} {s.order})" for name, s in schemes_for(model).items())


def temperature(fluid) -> str:
    """``"zero"``, ``"positive"`` or ``"traced"``: from ``fluid.kT`` where it is concrete, else from what
    the fluid recorded where it was built (`jaxrot.Fluid`'s static ``temperature``)."""
    now = temperature_of(fluid.kT)
    return fluid.temperature if now == "traced" else now


def call_model(entry: str, fluid, key) -> str | None:
    """The model of this call; None when it needs a key it lacks (a concrete ``kT > 0`` or a traced
    ``kT`` without ``key``)."""
    if entry == INERTIAL and fluid is None:
        return "vacuum"
    if not isinstance(fluid, Fluid):
        raise ValueError(f"`fluid` must be {'None or ' if entry == INERTIAL else ''}a jaxrot.Fluid; got "
                         f"{type(fluid).__name__}.")  # fmt: skip
    cold, warm = _ENTRY_MODELS[entry]
    if temperature(fluid) == "zero":
        return cold  # a key, if given, has nothing to draw
    return warm if key is not None else None


def scheme_for_call(scheme, entry: str, fluid=None, key=None):
    """``(scheme object, model)`` for a call of ``entry`` (`INERTIAL` or `OVERDAMPED`) with ``fluid``
    and ``key``; ``scheme`` a registered name, an instance, or (overdamped) None for the model's default.

    Raises:
        ValueError: an unknown name, a scheme whose ``models`` do not hold the call's model, or a
            temperature without a ``key``, naming the schemes that run this very call.
    """
    model = call_model(entry, fluid, key)
    if scheme is None and entry == OVERDAMPED:
        scheme = DEFAULT_BROWNIAN if model == "brownian" else DEFAULT_OVERDAMPED
    try:
        scheme = resolve_scheme(scheme)
    except ValueError:  # the same refusal, with the schemes of this very call
        raise ValueError(_unknown(scheme, entry, model, fluid)) from None
    if model is None:
        raise ValueError(_needs_key(scheme, entry, fluid))
    if model not in scheme.models:
        raise ValueError(_misfit(scheme, entry, model))
    return scheme, model


def _unknown(scheme, entry, model, fluid) -> str:
    known = model is not None
    model = model if known else _ENTRY_MODELS[entry][1]
    text = (
        f"`scheme` must be one of {candidates(model)} for this call ({_BODY[model]}), or a jaxrot.schemes "
        f"scheme instance; got {scheme!r}."
    )
    if not known:
        text += " " + (_TRACED if temperature(fluid) == "traced" else "") + _NEEDS_KEY
    return text + " Every scheme by model: jaxrot.schemes_for(model)."


def _needs_key(scheme, entry, fluid) -> str:
    warm = _ENTRY_MODELS[entry][1]
    traced = temperature(fluid) == "traced"
    prefix = _TRACED if traced else ""
    deterministic = _DETERMINISTIC_TRACED if traced else _DETERMINISTIC
    if warm in scheme.models:
        return f"{prefix}{_NEEDS_KEY} {deterministic}"
    return (
        f"{prefix}`fluid.kT` > 0 (a fluid at a temperature) needs a PRNG `key` and a scheme with thermal "
        f"noise, which {scheme.name!r} has not: use {candidates(warm)} with key=jax.random.key(0). "
        f"{deterministic}"
    )


def _misfit(scheme, entry, model) -> str:
    name = scheme.name
    own = [m for m in scheme.models if _ENTRY_OF[m] == entry]
    if model == "fluid" and "vacuum" in scheme.models:
        return (
            f"scheme {name!r} cannot integrate a fluid's friction (`fluid=`): its explicit steps are stable "
            f"only while ζΔt/I stays below about 2. Use {candidates('fluid')}, which take the friction's "
            "relaxation exactly at any step; or pass the fluid's torque as a plain torque callable, "
            "torque=lambda t, q, omega, args: fluid.torque(q, omega), with a step inside that limit."
        )
    if model in THERMAL_MODELS and own:
        return (
            f"scheme {name!r} has no thermal noise, and `fluid.kT` > 0 needs it: use {candidates(model)}; or "
            f"{'pass kT=0' if model == 'thermal' else 'pass kT=0 without a key'} for a deterministic run."
        )
    declared = [m for m in MODELS if m in scheme.models]  # in MODELS' order: the same words every run
    return (
        f"scheme {name!r} integrates {' and '.join(_BODY[m] for m in declared)}: {_HOW[declared[0]]}. "
        f"For this call ({_BODY[model]}), use "
        f"{candidates(model)}."
    )


# --- the model's form of the scheme and its arguments ----------------------------------------------


def bind_fluid(scheme, model, fluid, key, batch_shape, dtype, inertia, args, args_axes, drive):
    """``(scheme, args, args_axes)`` of a rollout in ``fluid`` (``model`` ``"fluid"`` or ``"thermal"``):
    the scheme's form for the model, its args the torque's own with the flattened per-body
    `jaxrot.Fluid` values (a `FluidArgs`, or a `ThermalArgs` with the body keys).

    Raises ValueError, before anything compiles, for a full inertia tensor or a drive."""
    if not is_diagonal_form(inertia):
        raise ValueError(
            "`inertia` must be principal moments (..., 3) about the body axes of the fluid's friction for a "
            "rollout with `fluid`: a full (3, 3) tensor, whose principal axes differ from the friction's, "
            "is not supported. Express the body in its principal frame."
        )
    if drive is not None:
        raise ValueError("`drive` and `fluid` cannot be combined: pass one of them.")
    values, axes = check_fluid(fluid, batch_shape, dtype)
    if model == "thermal":
        return bind_thermal(scheme, values, axes, args, args_axes, key, int(np.prod(batch_shape)))
    return scheme.in_fluid(), FluidArgs(args, values), FluidArgs(args_axes, axes)


def bind_thermal(scheme, fluid, fluid_axes, args, args_axes, key, n: int):
    """``(scheme, args, args_axes)`` of a Langevin scheme in a rollout of ``n`` bodies: the scheme bound
    to the key's implementation, its args a `ThermalArgs` (the body keys per body). ``key`` is never
    None: `call_model` gives ``"thermal"`` only with one."""
    key_data, impl = body_keys(check_key(key), n)
    return scheme.bind(impl), ThermalArgs(args, fluid, key_data), ThermalArgs(args_axes, fluid_axes, 0)


def for_concrete_steps(scheme, fluid, dt):
    """A Brownian ``scheme`` without what its steps cannot need, where ``fluid`` and ``dt`` (as the
    caller gave them, unchecked) are concrete (`jaxrot.schemes._brownian.for_steps`)."""
    try:
        kT, friction = (np.asarray(unwrap_per_body(x), np.float64) for x in (fluid.kT, fluid.friction))
        diffusion = kT[..., None] / friction if kT.ndim else kT / friction
        return for_steps(scheme, diffusion, np.asarray(dt, np.float64))
    except (AttributeError, TypeError, ValueError, jax.errors.TracerArrayConversionError):
        return scheme  # traced or malformed: everything compiled; the checks that follow explain a bad value


def bind_brownian(scheme, q, fluid, key):
    """``(scheme, start)`` of an overdamped rollout at a temperature: ``q`` ``(N, 4)`` with each body's
    key data and diffusion ``kT/ζ`` ``(N, 3)`` (`BrownianStart`); ``fluid`` the flattened values; the
    scheme bound to the key's implementation. ``key`` is never None: `call_model` gives ``"brownian"``
    only with one."""
    n = q.shape[0]
    kT = jnp.asarray(fluid.kT)
    kT = kT[:, None] if kT.ndim else kT  # (N, 1) per body, or shared
    friction = jnp.asarray(fluid.friction)
    friction = friction if friction.ndim == 2 or kT.ndim == 0 else friction[None]
    diffusion = jnp.broadcast_to(kT / friction, (n, 3))
    key_data, impl = body_keys(check_key(key), n)
    return scheme.bind(impl), BrownianStart(q, key_data, diffusion)
