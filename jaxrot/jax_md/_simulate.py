r"""`nvt_langevin` and `nve` in jax_md's convention, their rotation stepped by jaxrot's schemes.

One step of `nvt_langevin` is jax_md's BAOAB (``jax_md.simulate.nvt_langevin``) but for the rotation:

1. B: ``P += Δt/2 F`` on centres and orientations (jax_md's ``momentum_step``; on the
   orientation it is ``L_b += Δt/2 τ_b``);
2. the centres: A(Δt/2), O(Δt), A(Δt/2) by jax_md's own ``position_step`` and ``stochastic_step``,
   from the same keys as jax_md's (so the same numbers);
3. the orientations: a jaxrot thermal scheme's torque-free step over ``Δt`` on ``(q, ω)`` (for
   ``"baoab"``: exact free rotor over Δt/2, exact Ornstein–Uhlenbeck step of the body spin over Δt,
   exact rotor over Δt/2), or a vacuum scheme's torque-free flow as A around the exact O step;
4. the force at the new positions (jax_md's ``energy_or_force_fn``), B.

`nve` is jax_md's velocity Verlet with the orientations' drift a vacuum scheme's torque-free flow
over ``Δt``: ``"splitting"`` (jaxrot's exact free rotor, the default) or ``"no_squish"`` (jax_md's own
splitting of the rotor, Miller et al. 2002).

jax_md's friction convention is kept: ``gamma = RigidBody(γ_centre, G)`` (a float gives both), and
body axis ``l`` relaxes at jax_md's rate ``G M / (4 I_l)`` with ``M = 4 / Σ_k 1/I_k``: a rotational
friction ``ζ = G / Σ_k (1/I_k)`` on every axis (torque per angular velocity), so ``ζ / I_l`` is that rate.
"""

import contextlib
import functools

import jax
import jax.numpy as jnp
import numpy as np


@contextlib.contextmanager
def _jax_md_promotion():
    """JAX's default promotion rules, which jax_md's code relies on (it mixes float32 constants with
    the positions' dtype and broadcasts ranks implicitly): it fails under a caller's
    ``jax_numpy_dtype_promotion="strict"`` or ``jax_numpy_rank_promotion="raise"`` (jaxrot's test
    settings), even at import (its shape tables). jaxrot's own code runs under either."""
    with jax.numpy_dtype_promotion("standard"), jax.numpy_rank_promotion("allow"):
        yield


with _jax_md_promotion():
    from jax_md import quantity, rigid_body, simulate

from .. import quaternion as quat
from .._core._concrete import is_concrete
from .._fluid._fluid import Fluid
from .._inertia import body_inertia
from .._state import RotState
from ..schemes import resolve_scheme, schemes_for
from ..schemes._langevin import AbstractLangevinScheme, LangevinCarry
from ..schemes._ou import spin_relaxation
from ._convert import angular_momentum, conjugate_momentum, moments_per_body


def _promoting(fn):
    """``fn`` traced (and run) under `_jax_md_promotion`."""

    @functools.wraps(fn)
    def wrapped(*args, **kwargs):
        with _jax_md_promotion():
            return fn(*args, **kwargs)

    return wrapped


def _check_positive(value, name, *, zero_ok=False):
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


def _split_gamma(gamma):
    """``(γ_centre, G)`` of jax_md's ``gamma`` (a float, or ``RigidBody(center, orientation)``)."""
    if isinstance(gamma, rigid_body.RigidBody):
        center, orientation = gamma.center, gamma.orientation
        if isinstance(orientation, rigid_body.Quaternion):
            raise ValueError(
                "`gamma.orientation` must be a float or an array, not a Quaternion (as in jax_md)."
            )
    else:
        center = orientation = gamma
    _check_positive(center, "gamma.center" if isinstance(gamma, rigid_body.RigidBody) else "gamma")
    _check_positive(orientation, "gamma.orientation" if isinstance(gamma, rigid_body.RigidBody) else "gamma")
    return center, orientation


def _scheme_for(scheme, models, call):
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


def _check_common(energy_or_force_fn, shift_fn, dt):
    if not callable(energy_or_force_fn):
        raise ValueError(
            "`energy_or_force_fn` must be a callable of the positions (a jax_md energy or force)."
        )
    if not callable(shift_fn):
        raise ValueError(
            "`shift_fn` must be a callable, as jax_md's `space.free()` or `space.periodic(box)` return."
        )
    _check_positive(dt, "dt")


def _vacuum_flow(scheme, q, omega, moments, h):
    """One body's torque-free flow over ``h`` by a vacuum scheme's step: ``(q, ω)`` world ω."""
    inertia = body_inertia(moments)
    t0 = jnp.zeros((), q.dtype)
    carry = scheme.init(RotState(q, omega), t0, inertia, None, None)
    return scheme.state(scheme.step(carry, t0, jnp.asarray(h, q.dtype), inertia, None, None))


def _rotation_step(scheme, q, p, moments, friction, kT, dt, key):
    """The orientations' torque-free step over ``dt`` on jax_md's ``(q, P)`` ``(N, 4)`` each: ``(q, P)``.

    ``friction`` ``(N,)`` per body (jax_md's isotropic ζ), ``kT`` scalar (None: NVE, no noise)."""
    dtype = q.dtype
    half = jnp.asarray(dt, dtype) / 2
    spin = angular_momentum(q, p) / moments  # body frame
    if kT is None:

        def one(q_, spin_, m_):
            return _vacuum_flow(scheme, q_, _world(q_, spin_), m_, 2 * half)

        q1, omega1 = jax.vmap(one)(q, spin, moments)
    elif isinstance(scheme, AbstractLangevinScheme):
        normals = jax.random.normal(key, (q.shape[0], scheme.normals_per_step), dtype)

        def one(q_, spin_, m_, zeta, xi):
            fluid = Fluid(jnp.broadcast_to(zeta, (3,)), kT=kT)
            carry = LangevinCarry(RotState(q_, _world(q_, spin_)), None, jnp.int32(0))
            out = scheme.advance(
                carry, jnp.zeros((), dtype), 2 * half, body_inertia(m_), None, None, fluid, xi
            )
            return out.state

        q1, omega1 = jax.vmap(one)(q, spin, moments, friction, normals)
    else:  # a vacuum scheme's flow as A around the exact O step: BAOAB with that rotor
        normals = jax.random.normal(key, (q.shape[0], 3), dtype)

        def one(q_, spin_, m_, zeta, xi):
            q_, omega_ = _vacuum_flow(scheme, q_, _world(q_, spin_), m_, half)
            body = _body(q_, omega_)
            body = spin_relaxation(
                body, jnp.zeros(3, dtype), jnp.broadcast_to(zeta, (3,)), m_, kT, 2 * half, xi
            )
            return _vacuum_flow(scheme, q_, _world(q_, body), m_, half)

        q1, omega1 = jax.vmap(one)(q, spin, moments, friction, normals)
    return q1, conjugate_momentum(q1, moments * _body(q1, omega1))


def _world(q, body_vector):
    return quat.rotate(q, body_vector)


def _body(q, world_vector):
    return quat.rotate(quat.conjugate(q), world_vector)


def _orientation_parts(state):
    """``(rest, center, orientation)`` of a jax_md rigid-body state; ValueError unless 3-d quaternions."""
    if not isinstance(state.position, rigid_body.RigidBody) or not isinstance(
        state.position.orientation, rigid_body.Quaternion
    ):
        raise ValueError(
            "jaxrot.jax_md steps 3-d rigid bodies: the positions must be a jax_md.rigid_body.RigidBody whose "
            f"orientation is a rigid_body.Quaternion; got {type(state.position).__name__}."
        )
    return rigid_body.split_center_and_orientation(state)


def _step_orientation(orientation, scheme, dt, kT, rotational_gamma, key):
    """jax_md's orientation sub-state (position, momentum, mass) after the rotation step."""
    q, p = orientation.position.vec, orientation.momentum.vec
    moments = moments_per_body(orientation.mass, q)
    friction = None
    if kT is not None:
        friction = jnp.broadcast_to(jnp.asarray(rotational_gamma, q.dtype), q.shape[:-1]) / jnp.sum(
            1 / moments, axis=-1
        )
    q1, p1 = _rotation_step(scheme, q, p, moments, friction, kT, dt, key)
    return orientation.set(position=rigid_body.Quaternion(q1), momentum=rigid_body.Quaternion(p1))


def nvt_langevin(energy_or_force_fn, shift_fn, dt, kT, gamma=0.1, *, scheme="baoab", **sim_kwargs):
    r"""jax_md's ``simulate.nvt_langevin`` for rigid bodies, the rotation by a jaxrot scheme.

    The same call and the same state as ``jax_md.simulate.nvt_langevin`` on
    ``jax_md.rigid_body.RigidBody`` positions: swap the call, keep the energy, shapes, neighbour
    lists, ``shift_fn`` and state. The centres move exactly as jax_md moves them (BAOAB, from the
    same keys: the same numbers); the orientations by ``scheme``'s torque-free step between jax_md's
    half kicks, the torque the energy's gradient in the orientation (jax_md's force). With the
    default ``"baoab"`` (exact free rotor, exact Ornstein–Uhlenbeck step) each body axis samples
    ``⟨L_l²/I_l⟩ = kT`` at any ``dt`` for free bodies; jax_md's own O step misses it on each axis
    (about 5/6 kT at small dt; docs/jax_md_upstream_report.md).

    Args:
        energy_or_force_fn: jax_md's energy (or force) of the ``RigidBody`` positions.
        shift_fn: jax_md's ``shift_fn`` (``space.free()``, ``space.periodic(box)``).
        dt: the step (time units; > 0).
        kT: the temperature in energy units (≥ 0); ``apply_fn(state, kT=...)`` overrides it.
        gamma: jax_md's friction: a float for both, or ``RigidBody(γ_centre, G)``; body axis ``l``
            relaxes at ``G M / (4 I_l)``, ``M = 4 / Σ_k 1/I_k``, as in jax_md.
        scheme: a jaxrot scheme (name or object): a thermal one (``"baoab"``, ``"exp_euler"``) runs its
            own torque-free step; a vacuum one (``"no_squish"``, ``"splitting"``, ...) is the free flow
            of BAOAB's A steps around the exact O step (``"no_squish"``: jax_md's algorithm with
            its O step corrected).

    Returns:
        ``(init_fn, apply_fn)``: ``init_fn(key, R, mass=shape.mass(), momenta=None, **kwargs)`` is
        jax_md's own (``jax_md.simulate.NVTLangevinState``); ``apply_fn(state, **kwargs)`` one step
        (``dt=``, ``kT=`` override, the rest go to the energy and ``shift_fn``).

    Raises:
        ValueError: a scheme that does not fit (the names that do are listed), ``dt`` ≤ 0, ``kT`` < 0,
            ``gamma`` ≤ 0 or not finite, arguments that are not callables; before anything compiles.
            ``apply_fn`` on positions that are not 3-d ``RigidBody``\ s.

    Example:
        >>> import jax, jax.numpy as jnp, jaxrot.jax_md
        >>> from jax_md import energy, rigid_body, space
        >>> displacement, shift = space.free()
        >>> shape = rigid_body.point_union_shape(jnp.array([[-0.5, 0.0, 0.0], [0.5, 0.0, 0.0]]), jnp.ones(2))
        >>> energy_fn = rigid_body.point_energy(energy.soft_sphere_pair(displacement), shape)
        >>> body = rigid_body.RigidBody(jnp.array([[0.0, 0.0, 0.0], [3.0, 0.0, 0.0]]),
        ...                             rigid_body.Quaternion(jnp.tile(jnp.array([1.0, 0, 0, 0]), (2, 1))))
        >>> init_fn, apply_fn = jaxrot.jax_md.nvt_langevin(energy_fn, shift, 1e-2, kT=1.0, gamma=1.0)
        >>> state = init_fn(jax.random.key(0), body, mass=shape.mass())
        >>> state = jax.lax.fori_loop(0, 10, lambda i, s: apply_fn(s), state)
        >>> bool(jnp.all(jnp.isfinite(state.momentum.orientation.vec)))
        True
    """
    _check_common(energy_or_force_fn, shift_fn, dt)
    _check_positive(kT, "kT", zero_ok=True)
    gamma_center, gamma_orientation = _split_gamma(gamma)
    chosen = _scheme_for(scheme, ("thermal", "vacuum"), "nvt_langevin")
    init_fn, _ = simulate.nvt_langevin(energy_or_force_fn, shift_fn, dt, kT, gamma, **sim_kwargs)
    force_fn = quantity.canonicalize_force(energy_or_force_fn)

    @jax.jit
    @_promoting
    def apply_fn(state, **kwargs):
        _dt = kwargs.pop("dt", dt)
        _kT = kwargs.pop("kT", kT)
        half = _dt / 2
        state = simulate.momentum_step(state, half)
        # jax_md's keys (`rigid_body`'s `stochastic_step`): the centres draw the same numbers.
        key, center_key, orientation_key = jax.random.split(state.rng, 3)
        rest, center, orientation = _orientation_parts(state)
        center = simulate.position_step(center, shift_fn, half, **kwargs)
        center = simulate.stochastic_step(center.set(rng=center_key), _dt, _kT, gamma_center)
        center = simulate.position_step(center, shift_fn, half, **kwargs)
        orientation = _step_orientation(orientation, chosen, _dt, _kT, gamma_orientation, orientation_key)
        state = rigid_body.merge_center_and_orientation(rest.set(rng=key), center, orientation)
        state = state.set(force=force_fn(state.position, **kwargs))
        return simulate.momentum_step(state, half)

    return _promoting(init_fn), apply_fn


def nve(energy_or_force_fn, shift_fn, dt=1e-3, *, scheme="splitting", **sim_kwargs):
    r"""jax_md's ``simulate.nve`` for rigid bodies, the orientations' drift by a jaxrot scheme.

    Velocity Verlet as jax_md's: half kick ``P += Δt/2 F``, the centres' drift by ``shift_fn``, the
    orientations' torque-free flow over ``Δt`` by ``scheme``, the force, half kick. The state is
    jax_md's ``NVEState``. Unlike jax_md's ``velocity_verlet``, ``dt`` is not rounded to float32.

    Args:
        energy_or_force_fn, shift_fn: as jax_md's.
        dt: the step (> 0).
        scheme: a vacuum scheme of jaxrot (name or object): ``"splitting"`` (default: the exact free
            rotor, the energy drift then only the kicks'), ``"no_squish"`` (jax_md's rotor: the same
            numbers as jax_md's ``nve`` to round-off), or any other of ``jaxrot.SCHEMES``.

    Returns:
        ``(init_fn, apply_fn)``: ``init_fn(key, R, kT, mass=shape.mass(), momenta=None, **kwargs)``
        is jax_md's own; ``apply_fn(state, **kwargs)`` one step (``dt=`` overrides).

    Raises:
        ValueError: a scheme not in ``jaxrot.SCHEMES`` (they are listed), ``dt`` ≤ 0, arguments that
            are not callables; before anything compiles.

    Example:
        >>> import jax, jax.numpy as jnp, jaxrot.jax_md
        >>> from jax_md import energy, rigid_body, space
        >>> displacement, shift = space.free()
        >>> shape = rigid_body.point_union_shape(jnp.array([[-0.5, 0.0, 0.0], [0.5, 0.0, 0.0]]), jnp.ones(2))
        >>> energy_fn = rigid_body.point_energy(energy.soft_sphere_pair(displacement), shape)
        >>> body = rigid_body.RigidBody(jnp.array([[0.0, 0.0, 0.0], [1.5, 0.0, 0.0]]),
        ...                             rigid_body.Quaternion(jnp.tile(jnp.array([1.0, 0, 0, 0]), (2, 1))))
        >>> init_fn, apply_fn = jaxrot.jax_md.nve(energy_fn, shift, 1e-3)
        >>> state = init_fn(jax.random.key(0), body, 0.1, mass=shape.mass())
        >>> kinetic = lambda s: rigid_body.kinetic_energy(s.position, s.momentum, s.mass)
        >>> total = lambda s: energy_fn(s.position) + kinetic(s)
        >>> e0 = total(state)
        >>> state = jax.lax.fori_loop(0, 100, lambda i, s: apply_fn(s), state)
        >>> bool(abs(total(state) / e0 - 1) < 1e-4)
        True
    """
    _check_common(energy_or_force_fn, shift_fn, dt)
    chosen = _scheme_for(scheme, ("vacuum",), "nve")
    init_fn, _ = simulate.nve(energy_or_force_fn, shift_fn, dt, **sim_kwargs)
    force_fn = quantity.canonicalize_force(energy_or_force_fn)

    @jax.jit
    @_promoting
    def apply_fn(state, **kwargs):
        _dt = kwargs.pop("dt", dt)
        half = _dt / 2
        state = simulate.momentum_step(state, half)
        rest, center, orientation = _orientation_parts(state)
        center = simulate.position_step(center, shift_fn, _dt, **kwargs)
        orientation = _step_orientation(orientation, chosen, _dt, None, None, None)
        state = rigid_body.merge_center_and_orientation(rest, center, orientation)
        state = state.set(force=force_fn(state.position, **kwargs))
        return simulate.momentum_step(state, half)

    return _promoting(init_fn), apply_fn
