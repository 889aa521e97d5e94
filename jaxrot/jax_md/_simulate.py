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

import jax
import jax.numpy as jnp

from .. import quaternion as quat
from .._fluid._fluid import Fluid
from .._inertia import body_inertia
from .._state import RotState
from ..schemes._langevin import AbstractLangevinScheme, LangevinCarry
from ..schemes._ou import spin_relaxation
from ._common import (
    check_common,
    check_positive,
    check_rotational_friction,
    jax_md_promotion,
    moments_of,
    normals as draw_normals,
    orientation_parts,
    promoting,
    rotational_friction as friction_per_axis,
    scheme_for,
    split_gamma,
)
from ._convert import angular_momentum, conjugate_momentum


with jax_md_promotion():
    from jax_md import quantity, rigid_body, simulate


def _vacuum_flow(scheme, q, omega, moments, h):
    """One body's torque-free flow over ``h`` by a vacuum scheme's step: ``(q, ω)`` world ω."""
    inertia = body_inertia(moments)
    t0 = jnp.zeros((), q.dtype)
    carry = scheme.init(RotState(q, omega), t0, inertia, None, None)
    return scheme.state(scheme.step(carry, t0, jnp.asarray(h, q.dtype), inertia, None, None))


def _rotation_step(scheme, q, p, moments, friction, kT, dt, key):
    """The orientations' torque-free step over ``dt`` on jax_md's ``(q, P)`` ``(N, 4)`` each: ``(q, P)``.

    ``moments`` ``(3,)`` shared or ``(N, 3)`` per body, ``friction`` per body axis ``(3,)`` shared or
    ``(N, 3)`` per body, ``kT`` scalar (None: NVE, no noise). Shared values stay unbatched under
    `jax.vmap`, so what depends on them alone (the scheme's weights of ``ζΔt/I``, the rotor's modified
    moments) is computed once per step, not once per body."""
    dtype = q.dtype
    half = jnp.asarray(dt, dtype) / 2
    spin = angular_momentum(q, p) / moments  # body frame
    m_axis = None if moments.ndim == 1 else 0
    if kT is None:

        def one(q_, spin_, m_):
            return _vacuum_flow(scheme, q_, _world(q_, spin_), m_, 2 * half)

        q1, omega1 = jax.vmap(one, (0, 0, m_axis))(q, spin, moments)
        return q1, conjugate_momentum(q1, moments * _body(q1, omega1))
    z_axis = None if friction.ndim == 1 else 0
    if isinstance(scheme, AbstractLangevinScheme):
        normals = draw_normals(key, (q.shape[0], scheme.normals_per_step), dtype)

        def one(q_, spin_, xi, m_, zeta):
            fluid = Fluid(zeta, kT=kT)
            carry = LangevinCarry(RotState(q_, _world(q_, spin_)), None, jnp.int32(0))
            out = scheme.advance(
                carry, jnp.zeros((), dtype), 2 * half, body_inertia(m_), None, None, fluid, xi
            )
            return out.state

    else:  # a vacuum scheme's flow as A around the exact O step: BAOAB with that rotor
        normals = draw_normals(key, (q.shape[0], 3), dtype)

        def one(q_, spin_, xi, m_, zeta):
            q_, omega_ = _vacuum_flow(scheme, q_, _world(q_, spin_), m_, half)
            body = _body(q_, omega_)
            body = spin_relaxation(body, jnp.zeros(3, dtype), zeta, m_, kT, 2 * half, xi)
            return _vacuum_flow(scheme, q_, _world(q_, body), m_, half)

    q1, omega1 = jax.vmap(one, (0, 0, 0, m_axis, z_axis))(q, spin, normals, moments, friction)
    return q1, conjugate_momentum(q1, moments * _body(q1, omega1))


def _world(q, body_vector):
    return quat.rotate(q, body_vector)


def _body(q, world_vector):
    return quat.rotate(quat.conjugate(q), world_vector)


def _step_orientation(orientation, scheme, dt, kT, gamma_orientation, friction, key):
    """jax_md's orientation sub-state (position, momentum, mass) after the rotation step."""
    q, p = orientation.position.vec, orientation.momentum.vec
    moments = moments_of(orientation.mass, q)
    zeta = None if kT is None else friction_per_axis(gamma_orientation, friction, moments, q)
    q1, p1 = _rotation_step(scheme, q, p, moments, zeta, kT, dt, key)
    return orientation.set(position=rigid_body.Quaternion(q1), momentum=rigid_body.Quaternion(p1))


def nvt_langevin(
    energy_or_force_fn, shift_fn, dt, kT, gamma=0.1, *, scheme="baoab", rotational_friction=None, **sim_kwargs
):
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
        rotational_friction: the rotational friction about each principal (body) axis, torque per
            angular velocity, ``(3,)`` shared or ``(N, 3)`` per body, as `jaxrot.Fluid`'s ``friction``
            (Perrin's for a spheroid: ``jaxrot.Fluid.spheroid``): axis ``l`` relaxes at ``ζ_l / I_l``.
            It replaces ``gamma``'s rotational part, which jax_md makes the same on every axis
            (jax_md refuses a friction per axis). None (default): ``gamma``'s.
            The axes are jax_md's principal axes, in ascending order of the moments: a prolate
            spheroid's long axis is body x there, so its ``Fluid.spheroid(...).friction`` (symmetry
            axis last) goes in reversed.

    Returns:
        ``(init_fn, apply_fn)``: ``init_fn(key, R, mass=shape.mass(), momenta=None, **kwargs)`` is
        jax_md's own (``jax_md.simulate.NVTLangevinState``); ``apply_fn(state, **kwargs)`` one step
        (``dt=``, ``kT=`` override, the rest go to the energy and ``shift_fn``).

    Raises:
        ValueError: a scheme that does not fit (the names that do are listed), ``dt`` ≤ 0, ``kT`` < 0,
            ``gamma`` ≤ 0 or not finite, a ``rotational_friction`` not ``(3,)``/``(N, 3)`` or not > 0,
            arguments that are not callables; before anything compiles. ``apply_fn`` on positions
            that are not 3-d ``RigidBody``\ s.

    Example:
        >>> import jax, jax.numpy as jnp, jaxrot.jax_md
        >>> from jax_md import energy, rigid_body, space
        >>> displacement, shift = space.free()
        >>> shape = rigid_body.point_union_shape(jnp.array([[-0.5, 0.0, 0.0], [0.5, 0.0, 0.0]]), jnp.ones(2))
        >>> energy_fn = rigid_body.point_energy(energy.soft_sphere_pair(displacement), shape)
        >>> body = rigid_body.RigidBody(jnp.array([[0.0, 0.0, 0.0], [3.0, 0.0, 0.0]]),
        ...                             rigid_body.Quaternion(jnp.tile(jnp.array([1.0, 0, 0, 0]), (2, 1))))
        >>> init_fn, apply_fn = jaxrot.jax_md.nvt_langevin(energy_fn, shift, 1e-2, kT=1.0, gamma=1.0,
        ...                                                 rotational_friction=jnp.array([1.0, 2.0, 2.0]))
        >>> state = init_fn(jax.random.key(0), body, mass=shape.mass())
        >>> state = jax.lax.fori_loop(0, 10, lambda i, s: apply_fn(s), state)
        >>> bool(jnp.all(jnp.isfinite(state.momentum.orientation.vec)))
        True
    """
    check_common(energy_or_force_fn, shift_fn, dt)
    check_positive(kT, "kT", zero_ok=True)
    gamma_center, gamma_orientation = split_gamma(gamma)
    check_rotational_friction(rotational_friction)
    chosen = scheme_for(scheme, ("thermal", "vacuum"), "nvt_langevin")
    init_fn, _ = simulate.nvt_langevin(energy_or_force_fn, shift_fn, dt, kT, gamma, **sim_kwargs)
    force_fn = quantity.canonicalize_force(energy_or_force_fn)

    @jax.jit
    @promoting
    def apply_fn(state, **kwargs):
        _dt = kwargs.pop("dt", dt)
        _kT = kwargs.pop("kT", kT)
        half = _dt / 2
        state = simulate.momentum_step(state, half)
        # jax_md's keys (`rigid_body`'s `stochastic_step`): the centres draw the same numbers.
        key, center_key, orientation_key = jax.random.split(state.rng, 3)
        rest, center, orientation = orientation_parts(state)
        center = simulate.position_step(center, shift_fn, half, **kwargs)
        center = simulate.stochastic_step(center.set(rng=center_key), _dt, _kT, gamma_center)
        center = simulate.position_step(center, shift_fn, half, **kwargs)
        orientation = _step_orientation(
            orientation, chosen, _dt, _kT, gamma_orientation, rotational_friction, orientation_key
        )
        state = rigid_body.merge_center_and_orientation(rest.set(rng=key), center, orientation)
        state = state.set(force=force_fn(state.position, **kwargs))
        return simulate.momentum_step(state, half)

    return promoting(init_fn), apply_fn


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
    check_common(energy_or_force_fn, shift_fn, dt)
    chosen = scheme_for(scheme, ("vacuum",), "nve")
    init_fn, _ = simulate.nve(energy_or_force_fn, shift_fn, dt, **sim_kwargs)
    force_fn = quantity.canonicalize_force(energy_or_force_fn)

    @jax.jit
    @promoting
    def apply_fn(state, **kwargs):
        _dt = kwargs.pop("dt", dt)
        half = _dt / 2
        state = simulate.momentum_step(state, half)
        rest, center, orientation = orientation_parts(state)
        center = simulate.position_step(center, shift_fn, _dt, **kwargs)
        orientation = _step_orientation(orientation, chosen, _dt, None, None, None, None)
        state = rigid_body.merge_center_and_orientation(rest, center, orientation)
        state = state.set(force=force_fn(state.position, **kwargs))
        return simulate.momentum_step(state, half)

    return promoting(init_fn), apply_fn
