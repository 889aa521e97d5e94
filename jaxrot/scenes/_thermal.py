"""Scenes at a temperature (`THERMAL_SCENES`): magnetic nanoparticles, overdamped and with inertia."""

from types import MappingProxyType

import jax
import jax.numpy as jnp
import numpy as np

from .._fluid._equilibrium import dipole_orientations, maxwell_spins
from .._fluid._fluid import Fluid
from .._state import RotState
from ..torques import UniformField
from ._scene import Scene, _f


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
