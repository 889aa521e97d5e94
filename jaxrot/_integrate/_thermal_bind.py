"""A rollout at a temperature: the scheme that takes the noise, and the per-body keys it draws from."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._core._checks import check_values
from .._particles import unwrap_per_body
from ..schemes import THERMAL_SCHEMES
from ..schemes._brownian import (
    BROWNIAN_SCHEMES,
    DEFAULT_BROWNIAN,
    AbstractBrownianScheme,
    BrownianStart,
    for_steps,
)
from ..schemes._langevin import AbstractLangevinScheme, ThermalArgs
from ..schemes._noise import body_keys, check_key


def _names(registry):
    return ", ".join(f"{name!r} (weak order {s.order})" for name, s in registry.items())


def without_temperature(fluid, scheme_name: str, key, langevin: bool = True):
    """``fluid`` (one body's values) checked for ``kT = 0``: what a scheme without noise needs when a
    ``key`` is given (without one, `jaxrot._fluid._fluid.check_fluid` has checked it already).

    Concrete ``kT``: ValueError now, naming the schemes that take the noise; traced: at run time
    (`jaxrot._core._checks.check_values`: use the returned values)."""
    if key is None:
        return fluid
    capable = _names(THERMAL_SCHEMES if langevin else BROWNIAN_SCHEMES)
    checked = check_values(
        fluid.kT,
        fluid.kT > 0,
        f"scheme {scheme_name!r} has no thermal noise, and `fluid.kT` > 0 needs it: use {capable}; or "
        "pass kT=0 for a deterministic run.",
    )
    return eqx.tree_at(lambda f: f.kT, fluid, checked)


def is_langevin(scheme) -> bool:
    return isinstance(scheme, AbstractLangevinScheme)


def bind_thermal(scheme, fluid, fluid_axes, args, args_axes, key, n: int):
    """``(scheme, args, args_axes)`` of a Langevin scheme in a rollout of ``n`` bodies: the scheme bound
    to the key's implementation, its args a `ThermalArgs` (the body keys per body, or None)."""
    key_data, impl = (None, None) if key is None else body_keys(check_key(key), n)
    axes = ThermalArgs(args_axes, fluid_axes, None if key_data is None else 0)
    return scheme.bind(impl), ThermalArgs(args, fluid, key_data), axes


def brownian_scheme(scheme, key, fluid, dt):
    """The Brownian scheme ``scheme`` names (None with a ``key``: the default), or None (a deterministic
    overdamped scheme, which `jaxrot.overdamped_rollout` resolves). ``fluid`` and ``dt`` as the caller
    gave them (unchecked): where they are concrete, the scheme leaves out what their steps cannot
    need (`jaxrot.schemes._brownian.for_steps`)."""
    if isinstance(scheme, str) and scheme in BROWNIAN_SCHEMES:
        scheme = BROWNIAN_SCHEMES[scheme]
    elif scheme is None and key is not None:
        scheme = BROWNIAN_SCHEMES[DEFAULT_BROWNIAN]
    if not isinstance(scheme, AbstractBrownianScheme):
        return None
    try:
        kT, friction = (np.asarray(unwrap_per_body(x), np.float64) for x in (fluid.kT, fluid.friction))
        diffusion = kT[..., None] / friction if kT.ndim else kT / friction
        return for_steps(scheme, diffusion, np.asarray(dt, np.float64))
    except (AttributeError, TypeError, ValueError, jax.errors.TracerArrayConversionError):
        return scheme  # traced or malformed: everything compiled; the checks that follow explain a bad value


def brownian_start(scheme, q, fluid, key):
    """``(scheme, start)`` of an overdamped rollout at a temperature: ``q`` ``(N, 4)`` with each body's
    key data and diffusion ``kT/ζ`` ``(N, 3)`` (`BrownianStart`); ``fluid`` the flattened values; the
    scheme bound to the key's implementation."""
    n = q.shape[0]
    kT = jnp.asarray(fluid.kT)
    kT = kT[:, None] if kT.ndim else kT  # (N, 1) per body, or shared
    friction = jnp.asarray(fluid.friction)
    friction = friction if friction.ndim == 2 or kT.ndim == 0 else friction[None]
    diffusion = jnp.broadcast_to(kT / friction, (n, 3))
    key_data, impl = (None, None) if key is None else body_keys(check_key(key), n)
    return scheme.bind(impl), BrownianStart(q, key_data, diffusion)
