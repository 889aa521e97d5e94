r"""`brownian`: overdamped rigid bodies in jax_md's call, the orientations by jaxrot's Brownian schemes.

jax_md's ``simulate.brownian`` cannot take ``RigidBody`` positions (it unpacks its state with
``dataclasses.astuple``, which turns the ``RigidBody`` into a tuple: ``AttributeError: 'tuple' object
has no attribute 'orientation'`` in ``rigid_body``'s ``shift``). Here one step is, from the force
``F`` of jax_md's ``energy_or_force_fn`` at the start of the step (held over it):

1. the centres by jax_md's Euler–Maruyama step, the same formula and key as ``simulate.brownian``:
   ``ΔR = F_c Δt / (m γ_c) + √(2 kT Δt / (m γ_c)) ξ``, moved by ``shift_fn``;
2. the orientations by a jaxrot Brownian scheme (`jaxrot.schemes.BrownianSplitting` by default: exact
   in law for free rotational diffusion at any step) with the body-frame torque
   ``τ_b = (½ q* ⊗ F_q)[1:]`` of jax_md's orientation force held in the world frame over the step:
   angular velocity ``ω = R ζ⁻¹ Rᵀ τ`` (``ζ`` the rotational friction per body axis) and diffusion
   ``D_l = kT / ζ_l`` about body axis ``l``.

With the force held over the step, the step is of weak order 1 with interactions (as jax_md's
centres); free bodies diffuse exactly at any ``Δt`` (spheres and bodies with at most one distinct
faster axis; weak order 2 otherwise, `jaxrot.schemes._brownian.free_diffusion`).
"""

import jax
import jax.numpy as jnp
import numpy as np

from .. import quaternion as quat
from .._core._concrete import is_concrete
from ..schemes._brownian import for_steps
from ._common import (
    check_common,
    check_positions,
    check_positive,
    check_rotational_friction,
    jax_md_promotion,
    moments_of,
    normals as draw_normals,
    promoting,
    rotational_friction as friction_per_axis,
    scheme_for,
    split_gamma,
)
from ._convert import body_torque


with jax_md_promotion():
    from jax_md import quantity, rigid_body, simulate


def _turn_orientations(scheme, q, torque_body, zeta, kT, dt, key):
    """The orientations ``(N, 4)`` after one step of ``scheme`` with the body torques ``(N, 3)`` held
    (in the world frame) and the friction ``zeta`` ``(3,)`` shared or ``(N, 3)`` per body."""
    dtype = q.dtype
    xi = draw_normals(key, (q.shape[0], scheme.normals_per_step), dtype)
    torque_world = quat.rotate(q, torque_body)
    z_axis = None if zeta.ndim == 1 else 0

    def one(q_, tau, z, xi_):
        def velocity(t, q):  # overdamped: ω = R ζ⁻¹ Rᵀ τ, the world torque held over the step
            return quat.rotate(q, quat.rotate(quat.conjugate(q), tau) / z)

        t0 = jnp.zeros((), dtype)
        q1, _ = scheme.advance(q_, velocity(t0, q_), kT / z, t0, jnp.asarray(dt, dtype), velocity, xi_)
        return q1

    return jax.vmap(one, (0, 0, z_axis, 0))(q, torque_world, zeta, xi)


def brownian(
    energy_or_force_fn,
    shift_fn,
    dt,
    kT,
    gamma=0.1,
    *,
    scheme="brownian_splitting",
    rotational_friction=None,
):
    r"""Brownian (overdamped) dynamics of rigid bodies in jax_md's call: what ``simulate.brownian``
    cannot run on ``RigidBody`` positions.

    The call, state and conventions of ``jax_md.simulate.brownian``: swap the call (jax_md's raises
    ``AttributeError`` on rigid bodies), keep the energy, shapes, ``shift_fn``. The state is jax_md's
    ``BrownianState(position, mass, rng)``. The centres take jax_md's Euler–Maruyama step (its formula,
    its key split); the orientations a jaxrot Brownian scheme's step under the torque of the
    energy's orientation gradient (jax_md's force, held over the step) and the thermal noise: the
    module docstring has the step.

    Friction, as jax_md's: ``gamma`` is friction over mass. The centres' friction is ``m γ_c``
    (diffusion ``kT / (m γ_c)``, jax_md's); the rotational friction about every body axis is
    ``ζ = G / Σ_k (1/I_k)`` (torque per angular velocity) for ``gamma = RigidBody(γ_c, G)`` (a float
    gives both), the friction `nvt_langevin` uses (jax_md's rate ``G M / (4 I_l)`` times ``I_l``), so
    this is the overdamped limit of `nvt_langevin` with the same ``gamma``; its rotational diffusion
    is ``D = kT / ζ`` about each axis. ``rotational_friction`` gives one per axis instead.

    Args:
        energy_or_force_fn: jax_md's energy (or force) of the ``RigidBody`` positions.
        shift_fn: jax_md's ``shift_fn`` (``space.free()``, ``space.periodic(box)``).
        dt: the step (> 0).
        kT: the temperature in energy units (≥ 0).
        gamma: a float, or ``RigidBody(γ_c, G)`` (friction over mass; above).
        scheme: a Brownian scheme of jaxrot (name or object): ``"brownian_splitting"`` (default; exact
            free diffusion, the drift by the Lie midpoint rule around it) or ``"brownian_euler"``
            (geometric Euler–Maruyama, cheaper, weak order 1).
        rotational_friction: the rotational friction about each principal (body) axis, torque per
            angular velocity, ``(3,)`` shared or ``(N, 3)`` per body, as `jaxrot.Fluid`'s ``friction``
            (Perrin's for a spheroid: ``jaxrot.Fluid.spheroid``): diffusion ``kT / ζ_l`` about axis
            ``l``. It replaces ``gamma``'s rotational part. None (default): ``gamma``'s.
            The axes are jax_md's principal axes, in ascending order of the moments: a prolate
            spheroid's long axis is body x there, so its ``Fluid.spheroid(...).friction`` (symmetry
            axis last) goes in reversed.

    Returns:
        ``(init_fn, apply_fn)``: ``init_fn(key, R, mass=shape.mass())`` is jax_md's own
        (``jax_md.simulate.BrownianState``); ``apply_fn(state, **kwargs)`` one step (``dt=``, ``kT=``,
        ``gamma=`` override as in jax_md; the rest go to the energy and ``shift_fn``).

    Raises:
        ValueError: a scheme that is not one of ``jaxrot.BROWNIAN_SCHEMES`` (they are listed),
            ``dt`` ≤ 0, ``kT`` < 0, ``gamma`` ≤ 0 or not finite, a ``rotational_friction`` not
            ``(3,)``/``(N, 3)`` or not > 0, arguments that are not callables; before anything
            compiles. ``apply_fn`` on positions that are not 3-d ``RigidBody``\ s.

    Example:
        >>> import jax, jax.numpy as jnp, jaxrot.jax_md
        >>> from jax_md import rigid_body, space
        >>> _, shift = space.free()
        >>> shape = rigid_body.point_union_shape(jnp.array([[-0.5, 0.0, 0.0], [0.5, 0.0, 0.0]]), jnp.ones(2))
        >>> # a dipole along body x in a field along z: U = -5 (R e_x)·e_z
        >>> def energy_fn(position, **kwargs):
        ...     axis = rigid_body.quaternion_rotate(position.orientation, jnp.array([1.0, 0.0, 0.0]))
        ...     return -5.0 * jnp.sum(axis[:, 2])
        >>> n = 1000
        >>> body = rigid_body.RigidBody(jnp.zeros((n, 3)),
        ...                             rigid_body.Quaternion(jnp.tile(jnp.array([1.0, 0, 0, 0]), (n, 1))))
        >>> init_fn, apply_fn = jaxrot.jax_md.brownian(energy_fn, shift, 1e-2, kT=1.0,
        ...                                            rotational_friction=jnp.array([1.0, 2.0, 2.0]))
        >>> state = init_fn(jax.random.key(0), body, mass=shape.mass())
        >>> state = jax.lax.fori_loop(0, 300, lambda i, s: apply_fn(s), state)
        >>> axis = rigid_body.quaternion_rotate(state.position.orientation, jnp.array([1.0, 0.0, 0.0]))
        >>> round(float(jnp.mean(axis[:, 2])), 1)  # Langevin function L(5) = coth 5 - 1/5 = 0.80
        0.8
    """
    check_common(energy_or_force_fn, shift_fn, dt)
    check_positive(kT, "kT", zero_ok=True)
    split_gamma(gamma)
    check_rotational_friction(rotational_friction)
    chosen = scheme_for(scheme, ("brownian",), "brownian")
    fast = chosen
    if rotational_friction is not None and is_concrete(kT, rotational_friction):
        # Without the heat kernel's spectral branch where no body's D_min Δt reaches it (at the
        # construction's dt and kT: a step that overrides them runs the whole scheme).
        fast = for_steps(chosen, kT / np.asarray(rotational_friction, np.float64), dt)
    force_fn = quantity.canonicalize_force(energy_or_force_fn)
    init_fn, _ = simulate.brownian(energy_or_force_fn, shift_fn, dt, kT, gamma)

    @jax.jit
    @promoting
    def apply_fn(state, **kwargs):
        scheme_now = chosen if {"dt", "kT"} & set(kwargs) else fast
        _dt = kwargs.pop("dt", dt)
        _kT = kwargs.pop("kT", kT)
        gamma_center, gamma_orientation = split_gamma(kwargs.pop("gamma", gamma))
        position, mass = state.position, state.mass
        check_positions(position, "jaxrot.jax_md.brownian")
        key, split = jax.random.split(state.rng)  # jax_md's: the centres draw its numbers
        force = force_fn(position, **kwargs)
        center = position.center
        mass_center = jnp.asarray(mass.center)
        nu = 1 / ((mass_center[..., None] if mass_center.ndim == 1 else mass_center) * gamma_center)
        xi = jax.random.normal(split, center.shape, center.dtype)
        d_center = force.center * _dt * nu + jnp.sqrt(2 * _kT * _dt * nu) * xi
        q = position.orientation.vec
        zeta = friction_per_axis(gamma_orientation, rotational_friction, moments_of(mass.orientation, q), q)
        q1 = _turn_orientations(
            scheme_now, q, body_torque(q, force.orientation.vec), zeta, _kT, _dt, jax.random.fold_in(split, 1)
        )
        center1 = shift_fn(center, d_center, **kwargs)
        return state.set(position=rigid_body.RigidBody(center1, rigid_body.Quaternion(q1)), rng=key)

    return promoting(init_fn), apply_fn
