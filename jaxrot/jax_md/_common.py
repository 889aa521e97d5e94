"""What `nvt_langevin`, `nve` and `brownian` share: jax_md under its promotion rules, the checks of
their arguments, jax_md's friction convention, the rigid-body state's parts."""

import contextlib
import functools

import jax
import jax.numpy as jnp
import numpy as np


@contextlib.contextmanager
def jax_md_promotion():
    """JAX's default promotion rules, which jax_md's code relies on (it mixes float32 constants with
    the positions' dtype and broadcasts ranks implicitly): it fails under a caller's
    ``jax_numpy_dtype_promotion="strict"`` or ``jax_numpy_rank_promotion="raise"`` (jaxrot's test
    settings), even at import (its shape tables). jaxrot's own code runs under either."""
    with jax.numpy_dtype_promotion("standard"), jax.numpy_rank_promotion("allow"):
        yield


with jax_md_promotion():
    from jax_md import rigid_body

from .._core._concrete import is_concrete
from .._core._fusion import stage
from ..schemes import resolve_scheme, schemes_for
from ._convert import moments_per_body


def promoting(fn):
    """``fn`` traced (and run) under `jax_md_promotion`."""

    @functools.wraps(fn)
    def wrapped(*args, **kwargs):
        with jax_md_promotion():
            return fn(*args, **kwargs)

    return wrapped


def check_positive(value, name, *, zero_ok=False):
    """ValueError for a concrete ``value`` that is not finite and > 0 (≥ 0 with ``zero_ok``)."""
    if value is None or not is_concrete(value):
        return
    try:
        raw = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"`{name}` must be a number; got {value!r}.") from None
    bad = ~np.isfinite(raw) | ((raw < 0) if zero_ok else (raw <= 0))
    if np.any(bad):
        bound = ">= 0" if zero_ok else "> 0"
        raise ValueError(f"`{name}` must be finite and {bound}; got {raw if raw.size < 7 else '...'}.")


def split_gamma(gamma):
    """``(γ_centre, G)`` of jax_md's ``gamma`` (a float, or ``RigidBody(center, orientation)``)."""
    if isinstance(gamma, rigid_body.RigidBody):
        center, orientation = gamma.center, gamma.orientation
        if isinstance(orientation, rigid_body.Quaternion):
            raise ValueError(
                "`gamma.orientation` must be a float or an array, not a Quaternion (as in jax_md)."
            )
    else:
        center = orientation = gamma
    check_positive(center, "gamma.center" if isinstance(gamma, rigid_body.RigidBody) else "gamma")
    check_positive(orientation, "gamma.orientation" if isinstance(gamma, rigid_body.RigidBody) else "gamma")
    return center, orientation


def scheme_for(scheme, models, call):
    """The scheme object of ``scheme`` (a name or an instance) if one of ``models`` fits, else ValueError."""
    fitting = {name: s for model in models for name, s in schemes_for(model).items()}
    try:
        chosen = resolve_scheme(scheme)
    except ValueError:
        chosen = None
    if chosen is None or not any(model in chosen.models for model in models):
        raise ValueError(
            f"`scheme` of jaxrot.jax_md.{call} must be one of {', '.join(map(repr, fitting))} "
            f"(or such a scheme object); got {scheme!r}."
        )
    return chosen


def check_common(energy_or_force_fn, shift_fn, dt):
    if not callable(energy_or_force_fn):
        raise ValueError(
            "`energy_or_force_fn` must be a callable of the positions (a jax_md energy or force)."
        )
    if not callable(shift_fn):
        raise ValueError(
            "`shift_fn` must be a callable, as jax_md's `space.free()` or `space.periodic(box)` return."
        )
    check_positive(dt, "dt")


def check_positions(position, call="jaxrot.jax_md"):
    """ValueError unless ``position`` is a ``RigidBody`` of 3-d quaternions (``call`` names the caller)."""
    if not isinstance(position, rigid_body.RigidBody) or not isinstance(
        position.orientation, rigid_body.Quaternion
    ):
        raise ValueError(
            f"{call} steps 3-d rigid bodies: the positions must be a jax_md.rigid_body.RigidBody whose "
            f"orientation is a rigid_body.Quaternion; got {type(position).__name__}."
        )


def orientation_parts(state):
    """``(rest, center, orientation)`` of a jax_md rigid-body state; ValueError unless 3-d quaternions."""
    check_positions(state.position)
    return rigid_body.split_center_and_orientation(state)


def moments_of(mass, q):
    """The principal moments ``(3,)`` when all bodies share them (jax_md's ``shape.mass()`` of one
    shape: ``(1, 3)``), else ``(N, 3)`` per body."""
    mass = jnp.asarray(mass).astype(q.dtype)
    if mass.size == 3:
        return mass.reshape(3)
    return moments_per_body(mass, q)


def normals(key, shape, dtype):
    """Standard normals, staged: XLA would otherwise fuse the generator into each of their consumers
    and run it once per consumer (`jaxrot.schemes._noise.step_normals`)."""
    return stage(jax.random.normal(key, shape, dtype))


def check_rotational_friction(value):
    """ValueError for a concrete ``rotational_friction`` that is not ``(3,)`` / ``(N, 3)``, finite and > 0."""
    if value is None:
        return
    shape = np.shape(value)
    if len(shape) not in (1, 2) or shape[-1] != 3:
        raise ValueError(
            "`rotational_friction` must be the principal frictions about the body axes, shape (3,) shared "
            f"or (N, 3) per body (torque per angular velocity, as jaxrot.Fluid's); got shape {shape}."
        )
    check_positive(value, "rotational_friction")


def rotational_friction(gamma_orientation, friction, moments, q):
    """The rotational friction per body axis, ``(3,)`` shared or ``(N, 3)`` per body.

    ``friction`` (``(3,)`` or ``(N, 3)``, torque per angular velocity) when given; else jax_md's
    convention from ``G = gamma_orientation`` (a scalar or ``(N,)``): ``ζ = G / Σ_k (1/I_k)`` on every
    axis, body axis ``l`` relaxing at jax_md's rate ``G M / (4 I_l)``, ``M = 4 / Σ_k 1/I_k``."""
    dtype = q.dtype
    if friction is not None:
        # Shapes are known while tracing, before XLA compiles: a per-body friction of another length.
        if np.ndim(friction) == 2 and np.shape(friction)[0] != q.shape[0]:
            raise ValueError(
                f"`rotational_friction` has {np.shape(friction)[0]} rows but there are {q.shape[0]} bodies: "
                "give (N, 3), one row per body, or (3,) shared."
            )
        return jnp.asarray(friction, dtype)
    g = jnp.asarray(gamma_orientation, dtype)
    if moments.ndim == 1 and g.ndim == 0:
        return jnp.broadcast_to(g / jnp.sum(1 / moments), (3,))
    g = jnp.broadcast_to(g, q.shape[:-1])
    return jnp.broadcast_to((g / jnp.sum(1 / moments, axis=-1))[..., None], (*q.shape[:-1], 3))
