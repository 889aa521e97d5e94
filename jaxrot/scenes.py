"""Built-in scenes: bodies, initial state, torque model, drives, a suggested step and horizon.

A `Scene` declares what is simulated and nothing more: a torque-free scene has
``torque=None`` and no torque is ever evaluated; diagonal inertia (principal
moments) takes the fast path with no 3×3 products; a scene without drives runs
no drive code. `SCENES` maps names to factories ``factory(dtype=float64) ->
Scene``; ``python -m jaxrot compare --scene NAME`` runs any of them and
``--list-scenes`` lists them. Units are SI (kg m², rad/s, N m, s, A m², T)
except in `dipole_cloud`, which uses reduced units (μ₀/4π = 1).

Example:
    >>> import jaxrot
    >>> scene = jaxrot.SCENES["viscous_drag"]()
    >>> traj = jaxrot.rollout("zhao", scene.state, scene.inertia, scene.dt, 100, torque=scene.torque,
    ...                       args=scene.args)
    >>> traj.q.shape
    (101, 4)
"""

from collections.abc import Callable
from types import MappingProxyType
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from . import quaternion as quat
from ._fluid._equilibrium import dipole_orientations, maxwell_spins
from ._fluid._fluid import Fluid
from ._particles import per_body
from ._state import RotState
from .diagnostics import kinetic_energy
from .torques import DipoleInteraction, Gravity, RotatingField, UniformField, ViscousDrag


class Scene(NamedTuple):
    """A rotation problem.

    Attributes:
        name: key in `SCENES`.
        description: one line of physics.
        state: initial `RotState`; leading axes are bodies (none for one body).
        inertia: body-frame principal moments ``(3,)`` / tensor ``(3, 3)``, shared
            or one per body, kg m².
        torque: a `jaxrot.torques` model (or any torque callable), or None.
        args: the torque's parameters.
        dt: a suggested time step (s): second-order schemes reach about 1e-3 rad
            over the horizon at this step.
        t_end: the horizon (s).
        drive: a `jaxrot.Drive`, or None.
        fluid: a `jaxrot.Fluid` the bodies turn in (`FLUID_SCENES`), or None. With a fluid and
            ``inertia=None`` the scene is overdamped: `jaxrot.overdamped_rollout` integrates it.
    """

    name: str
    description: str
    state: RotState
    inertia: Any
    torque: Callable | None
    args: Any
    dt: float
    t_end: float
    drive: Any = None
    fluid: Any = None

    @property
    def n_bodies(self) -> int:
        return int(np.prod(self.state.q.shape[:-1]))

    def energy(self, t, q, omega):
        """Total energy (J) of all bodies: kinetic plus the torque model's potential.

        ``q`` ``(..., 4)`` and ``omega`` ``(..., 3)`` with the scene's body axes
        last (any leading time axes); None when the torque is not conservative or a fluid drags.
        """
        if self.fluid is not None or (
            self.torque is not None and not getattr(self.torque, "conservative", False)
        ):
            return None
        body_ndim = self.state.q.ndim - 1
        kinetic = kinetic_energy(q, omega, self.inertia)
        kinetic = jnp.sum(kinetic, axis=tuple(range(kinetic.ndim - body_ndim, kinetic.ndim)))
        if self.torque is None:
            return kinetic
        bodies = q.reshape(-1, self.n_bodies, 4)  # one row of all bodies per leading index
        potential = jax.vmap(lambda qi: self.torque.energy(t, qi, self.args))(bodies)
        return kinetic + potential.reshape(kinetic.shape)


def gravity_torque(t, q, omega, args):
    """``r × F`` for ``args = {"offset_body": r_b, "weight": F}``: `torques.Gravity` as a plain function."""
    return jnp.cross(quat.rotate(q, args["offset_body"]), args["weight"])


def _f(x, dtype):
    return jnp.asarray(x, dtype=dtype)


def free_top(dtype=jnp.float64) -> Scene:
    """Torque-free asymmetric top spun about its intermediate axis: the tennis-racket (Dzhanibekov) flip.

    Inertia ``(1, 2, 3)`` kg m², ``ω_b = (0.01, 2, 0.01)`` rad/s: the spin about the
    intermediate axis is unstable and flips over every ~6 s. Energy and world
    angular momentum are conserved; `jaxrot.analytic.free_top` is the exact motion.
    """
    q0 = quat.identity(dtype=dtype)
    return Scene(
        "free_top",
        "torque-free asymmetric top, intermediate-axis (tennis-racket) flip",
        RotState(q0, _f([0.01, 2.0, 0.01], dtype)),
        _f([1.0, 2.0, 3.0], dtype),
        None,
        None,
        dt=0.01,
        t_end=20.0,
    )


def _gravity_args(offset, dtype):
    return {"gravity": {"offset_body": _f(offset, dtype), "weight": _f([0.0, 0.0, -9.81], dtype)}}


def heavy_top(dtype=jnp.float64) -> Scene:
    """Asymmetric heavy top: gravity on a centre of mass offset from a fixed pivot.

    Inertia ``(1, 2, 3)`` kg m² about the pivot (principal axes = body axes),
    centre of mass at ``(0.1, 0.05, 0.3)`` m in the body, weight ``(0, 0, −9.81)``
    N (1 kg), spun mostly about the body z axis and tilted by about 0.37 rad.
    The orientation-dependent torque makes the motion nutate and precess
    chaotically. Energy is conserved.
    """
    q0 = quat.exp(_f([0.1, 0.2, 0.3], dtype))
    return Scene(
        "heavy_top",
        "asymmetric heavy top, I=(1,2,3), gravity on an offset centre of mass",
        RotState(q0, quat.rotate(q0, _f([0.3, 1.0, 6.0], dtype))),
        _f([1.0, 2.0, 3.0], dtype),
        Gravity(),
        _gravity_args([0.1, 0.05, 0.3], dtype),
        dt=0.005,
        t_end=5.0,
    )


def lagrange_top(dtype=jnp.float64) -> Scene:
    """Symmetric heavy (Lagrange) top: a fast spinning top precessing and nutating under gravity.

    Inertia ``(2, 2, 1)`` kg m² about the pivot, centre of mass 0.25 m up the
    symmetry axis, weight 9.81 N, tilted 0.3 rad, spin 25 rad/s about the axis.
    Energy and the angular momentum components about the vertical and about the
    symmetry axis are conserved.
    """
    q0 = quat.from_axis_angle(_f([1.0, 0.0, 0.0], dtype), _f(0.3, dtype))
    return Scene(
        "lagrange_top",
        "symmetric heavy top, I=(2,2,1), spin 25 rad/s, tilted 0.3 rad",
        RotState(q0, quat.rotate(q0, _f([0.0, 0.0, 25.0], dtype))),
        _f([2.0, 2.0, 1.0], dtype),
        Gravity(),
        _gravity_args([0.0, 0.0, 0.25], dtype),
        dt=0.002,
        t_end=3.0,
    )


def _needle(dtype, tilt):
    q0 = quat.from_axis_angle(_f([0.0, 1.0, 0.0], dtype), _f(tilt, dtype))
    return q0, _f([1.0, 1.0, 0.2], dtype), _f([0.0, 0.0, 1.0], dtype)


def dipole_field(dtype=jnp.float64) -> Scene:
    """A magnetised needle (compass) in a uniform field: it swings about the field and spins.

    Inertia ``(1, 1, 0.2)`` kg m², moment 1 A m² along the body z (needle) axis,
    field ``(1, 0, 0)`` T, needle tilted 0.5 rad from the world z towards x
    (1.07 rad from the field), spin 2 rad/s about the needle. Energy is conserved,
    and so is the angular momentum component along the field.
    """
    q0, inertia, moment = _needle(dtype, 0.5)
    return Scene(
        "dipole_field",
        "magnetic needle in a uniform 1 T field",
        RotState(q0, quat.rotate(q0, _f([0.3, 0.0, 2.0], dtype))),
        inertia,
        UniformField(),
        {"field": {"moment_body": moment, "field": _f([1.0, 0.0, 0.0], dtype)}},
        dt=0.005,
        t_end=10.0,
    )


def dipole_rotating_field(dtype=jnp.float64) -> Scene:
    """A magnetised needle dragged by a field rotating in the xy plane at 0.5 rad/s.

    The needle of `dipole_field` lying along world x, the field
    ``B(t) = (cos 0.5t, sin 0.5t, 0)`` T: the needle follows the field with a lag
    and oscillates about it. Time-dependent torque; energy is not conserved.
    """
    q0, inertia, moment = _needle(dtype, np.pi / 2)
    field = {"moment_body": moment, "amplitude": _f(1.0, dtype), "angular_frequency": _f(0.5, dtype)}
    return Scene(
        "dipole_rotating_field",
        "magnetic needle in a 1 T field rotating at 0.5 rad/s",
        RotState(q0, quat.rotate(q0, _f([0.0, 0.0, 1.0], dtype))),
        inertia,
        RotatingField(),
        {"rotating_field": field},
        dt=0.005,
        t_end=10.0,
    )


def viscous_drag(dtype=jnp.float64) -> Scene:
    """A tumbling asymmetric body slowed by rotational drag ``τ = −c ω``.

    Inertia ``(1, 2, 3)`` kg m², ``c = 0.2`` N m s, ``ω_b(0) = (0.3, 1, 6)`` rad/s.
    A velocity-dependent torque: the kinetic energy decays at exactly
    ``dE/dt = −c |ω|²``.
    """
    q0 = quat.exp(_f([0.1, 0.2, 0.3], dtype))
    return Scene(
        "viscous_drag",
        "asymmetric body under viscous drag c = 0.2 N m s",
        RotState(q0, quat.rotate(q0, _f([0.3, 1.0, 6.0], dtype))),
        _f([1.0, 2.0, 3.0], dtype),
        ViscousDrag(),
        {"drag": {"coefficient": _f(0.2, dtype)}},
        dt=0.005,
        t_end=10.0,
    )


def dipole_cloud(dtype=jnp.float64, n_side=4, external_field=(0.0, 0.0, 0.5)) -> Scene:
    """``n_side²`` magnetic needles pinned on a square grid, each turned by all the others' fields.

    Reduced units: μ₀/4π = 1, grid spacing 1, moment 1 along each needle,
    inertia ``(0.1, 0.1, 0.02)``, random initial orientations (seed 0) at rest,
    plus a uniform ``external_field`` (pass zeros for none). The dipole–dipole
    torque is coupled (`jaxrot.torques.DipoleInteraction`). Energy is conserved;
    the total spin angular momentum changes by the external torque and by the
    pins' reaction (see `DipoleInteraction`).
    """
    n = n_side * n_side
    grid = np.stack(np.meshgrid(np.arange(n_side), np.arange(n_side), indexing="ij"), -1).reshape(n, 2)
    positions = _f(np.concatenate([grid, np.zeros((n, 1))], axis=1), dtype)
    q0 = quat.normalize(jax.random.normal(jax.random.PRNGKey(0), (n, 4), dtype=dtype))
    moment = _f([0.0, 0.0, 1.0], dtype)
    args = {
        "dipoles": {"positions": positions, "moment_body": moment, "strength": _f(1.0, dtype)},
        "field": {"moment_body": moment, "field": _f(external_field, dtype)},
    }
    return Scene(
        "dipole_cloud",
        f"{n} coupled magnetic needles on a grid (dipole–dipole torques), reduced units",
        RotState(q0, jnp.zeros((n, 3), dtype)),
        _f([0.1, 0.1, 0.02], dtype),
        DipoleInteraction() + UniformField(),
        args,
        dt=0.002,
        t_end=3.0,
    )


def tumbling_cloud(dtype=jnp.float64, n=256, seed=0) -> Scene:
    """``n`` free asymmetric bodies with random inertia, orientation and spin (throughput).

    Principal moments uniform in [1, 2] kg m² (always physical), orientations
    uniform, ``ω_b`` normal with 2 rad/s per component. Torque-free: each body's
    energy and world angular momentum are conserved.
    """
    k1, k2, k3 = jax.random.split(jax.random.PRNGKey(seed), 3)
    moments = jax.random.uniform(k1, (n, 3), dtype=dtype, minval=1.0, maxval=2.0)
    q0 = quat.normalize(jax.random.normal(k2, (n, 4), dtype=dtype))
    omega_b = 2 * jax.random.normal(k3, (n, 3), dtype=dtype)
    return Scene(
        "tumbling_cloud",
        f"{n} free bodies with random inertia, orientation and spin",
        RotState(q0, quat.rotate(q0, omega_b)),
        moments,
        None,
        None,
        dt=0.005,
        t_end=5.0,
    )


def _spheroid_in_shear(dtype, stokes):
    aspect = 4.0
    shear = jnp.zeros((3, 3), dtype).at[0, 1].set(1.0)
    fluid = Fluid.spheroid(_f(aspect, dtype), _f(1.0, dtype), _f(1.0, dtype), velocity_gradient=shear)
    q0 = quat.exp(_f([0.3, -0.5, 0.7], dtype))
    state = RotState(q0, fluid.angular_velocity(q0))
    inertia = None
    if stokes:
        shape = _f([aspect**2 + 1, aspect**2 + 1, 2.0], dtype) / 5  # a uniform spheroid's moments / mass
        inertia = stokes * fluid.friction[0] / shape[0] * shape
    return fluid, state, inertia, 2 * np.pi * (aspect + 1 / aspect)


def spheroid_shear(dtype=jnp.float64, stokes=1e-2) -> Scene:
    """A prolate spheroid (aspect ratio 4) with inertia in a simple shear: Jeffery's orbit, drifting.

    Reduced units: semi-axes 4 and 1, viscosity 1, the shear ``u = (y, 0, 0)`` of rate 1 (Perrin's
    frictions, `jaxrot.Fluid.spheroid`); the moments of a uniform spheroid, scaled to the Stokes
    number ``St = I_⊥ γ̇ / ζ_⊥`` (default 1e-2: the friction relaxes the tumbling in 0.01 and the spin
    in 0.0056 time units, so ``ζΔt/I`` is 5–9 at the suggested step). Started off the shear plane,
    turning at the overdamped angular velocity. The horizon is one Jeffery period,
    ``2π(λ + 1/λ)/γ̇``. Needs a fluid scheme (`jaxrot.FLUID_SCHEMES`): ``rollout(..., fluid=scene.fluid)``.
    """
    fluid, state, inertia, period = _spheroid_in_shear(dtype, stokes)
    return Scene(
        "spheroid_shear",
        f"spheroid (aspect 4) in simple shear at Stokes number {stokes:g}, reduced units",
        state, inertia, None, None, dt=0.05, t_end=float(period), fluid=fluid,
    )  # fmt: skip


def spheroid_shear_overdamped(dtype=jnp.float64) -> Scene:
    """`spheroid_shear` without inertia (Stokes number 0): Jeffery's orbit, `jaxrot.overdamped_rollout`.

    The orientation alone: ``inertia=None``; ``state.omega`` is the overdamped angular velocity.
    """
    fluid, state, _, period = _spheroid_in_shear(dtype, 0.0)
    return Scene(
        "spheroid_shear_overdamped",
        "spheroid (aspect 4) in simple shear without inertia: Jeffery's orbit, reduced units",
        state, None, None, None, dt=0.1, t_end=float(period), fluid=fluid,
    )  # fmt: skip


# Scenes in a fluid: run by `jaxrot.rollout(..., fluid=scene.fluid)` with a fluid scheme, or by
# `jaxrot.overdamped_rollout` (inertia None); ``python -m jaxrot compare`` knows them. Kept apart
# from `SCENES`, which every scheme of `jaxrot.SCHEMES` runs.
FLUID_SCENES = MappingProxyType({f.__name__: f for f in (spheroid_shear, spheroid_shear_overdamped)})


# Magnetic nanoparticles at a temperature: magnetite cores (radius 10 nm, 5200 kg/m³, saturation
# magnetisation 4.8e5 A/m) in shells of hydrodynamic radius 20 nm, in water (1 mPa s) at 300 K.
_NANO = {"kT": 1.380649e-23 * 300.0, "friction": 8 * np.pi * 1e-3 * (20e-9) ** 3,
         "moment": 4.8e5 * 4 / 3 * np.pi * (10e-9) ** 3, "field": 0.01}  # fmt: skip


def magnetic_nanoparticles(dtype=jnp.float64, n=4096) -> Scene:
    """Magnetic nanoparticles in water at 300 K aligning in a 10 mT field: Brownian rotation (SI units).

    Magnetite cores of radius 10 nm (moment ``μ = M_s V = 2.0e-18 A m²`` along body z) in shells of
    hydrodynamic radius 20 nm: friction ``8πηa³ = 2.0e-25 N m s``, ``D = kT/ζ = 2.1e4 s⁻¹`` (Debye
    time ``1/(2D) = 24 µs``); ``x = μB/kT = 4.86``, so ``⟨cos θ⟩ = L(x) = 0.794`` at equilibrium. The
    core's inertia (``I/ζ ≈ 4e-12 s``) is negligible: ``inertia=None``, `jaxrot.overdamped_rollout`
    with a key. ``n`` bodies started from the exact equilibrium (the Boltzmann law of the field).
    """
    kT, zeta, moment, field = (_NANO[k] for k in ("kT", "friction", "moment", "field"))
    q0 = dipole_orientations(jax.random.key(0), n, moment * field / kT, dtype)
    fluid = Fluid(_f([zeta, zeta, zeta], dtype), kT=_f(kT, dtype))
    args = {"field": {"moment_body": _f([0.0, 0.0, moment], dtype), "field": _f([0.0, 0.0, field], dtype)}}
    debye = zeta / (2 * kT)
    torque = jax.vmap(UniformField(), (None, 0, None, None))(0.0, q0, None, args)
    return Scene(
        "magnetic_nanoparticles",
        f"{n} magnetite nanoparticles in water at 300 K in a 10 mT field (Brownian, SI units)",
        RotState(q0, fluid.angular_velocity(q0, torque)), None, UniformField(), args,
        dt=debye / 8, t_end=8 * debye, fluid=fluid,
    )  # fmt: skip


def magnetic_nanoparticles_inertial(dtype=jnp.float64, n=4096) -> Scene:
    """`magnetic_nanoparticles` in reduced units with inertia: spheres with ``I = 1``, ``ζ = 2``, ``kT = 1``,
    ``μB/kT = 2`` (``⟨cos θ⟩ = L(2) = 0.537``, ``⟨I ω_k²⟩ = kT``): the spin relaxes in ``I/ζ = 0.5``, the
    orientation in the Debye time ``ζ/(2kT) = 1``. Started from the exact Boltzmann and Maxwell laws;
    `jaxrot.rollout` with a scheme of `jaxrot.THERMAL_SCHEMES`, ``fluid=scene.fluid`` and a key."""
    q0 = dipole_orientations(jax.random.key(0), n, 2.0, dtype)
    inertia = _f([1.0, 1.0, 1.0], dtype)
    omega = maxwell_spins(jax.random.key(1), q0, inertia, 1.0)
    args = {"field": {"moment_body": _f([0.0, 0.0, 1.0], dtype), "field": _f([0.0, 0.0, 2.0], dtype)}}
    return Scene(
        "magnetic_nanoparticles_inertial",
        f"{n} magnetic spheres with inertia at kT = 1 in a field, μB/kT = 2 (Langevin, reduced units)",
        RotState(q0, omega), inertia, UniformField(), args, dt=0.125, t_end=8.0,
        fluid=Fluid(_f([2.0, 2.0, 2.0], dtype), kT=_f(1.0, dtype)),
    )  # fmt: skip


# Scenes at a temperature: run with a key, by `jaxrot.rollout` (a scheme of `jaxrot.THERMAL_SCHEMES`) or
# `jaxrot.overdamped_rollout` (inertia None); ``python -m jaxrot compare`` measures their weak errors.
THERMAL_SCENES = MappingProxyType(
    {f.__name__: f for f in (magnetic_nanoparticles, magnetic_nanoparticles_inertial)}
)


SCENES = MappingProxyType(
    {
        f.__name__: f
        for f in (
            free_top,
            heavy_top,
            lagrange_top,
            dipole_field,
            dipole_rotating_field,
            viscous_drag,
            dipole_cloud,
            tumbling_cloud,
        )
    }
)

__all__ = [
    "FLUID_SCENES",
    "SCENES",
    "THERMAL_SCENES",
    "Scene",
    "gravity_torque",
    "per_body",
    *SCENES,
    *FLUID_SCENES,
    *THERMAL_SCENES,
]
