"""The thermal oracles as problems for the weak-error ladder (`jaxrot.comparison._weak`).

Each builder takes a scheme (one of `jaxrot.THERMAL_SCHEMES` or `jaxrot.BROWNIAN_SCHEMES`), a number
of bodies, a key for the initial state and a dtype, and returns a `WeakProblem` with its closed form:

- `dipole`: a dipole (moment ``μ`` along body z) in a field along world z at ``x = μB/kT``, started
  from its exact Boltzmann law (and, with inertia, the Maxwell law): observed ``cos θ`` (oracle
  ``L(x)``) and, with inertia, ``I_k ω_k² / kT`` per axis (oracle 1).
- `free_body`: free rotational diffusion of a body started at the identity: observed the diagonal
  of its rotation matrix, ``e_i(t)·e_i(0)`` (oracle ``exp(−(D_j + D_k) t)`` for the overdamped
  model; the underdamped model has no closed form there, and is measured by its limit).
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .. import quaternion as quat
from .._fluid._equilibrium import axis_correlation, dipole_orientations, langevin_function, maxwell_spins
from .._fluid._fluid import Fluid
from .._inertia import body_inertia
from .._integrate._overdamped import velocity_field
from .._state import RotState
from ..schemes._brownian import AbstractBrownianScheme, for_steps
from ..schemes._langevin import LangevinCarry
from ..torques import UniformField
from ._weak import WeakProblem


class ThermalSetting(NamedTuple):
    """A problem's physics: friction ``(3,)``, inertia ``(3,)`` or None (overdamped), ``kT``, and the
    dipole's ``x = μB/kT`` (None: no field)."""

    friction: tuple
    inertia: tuple | None
    kT: float
    x: float | None


# The settings of the measured tables (docs/thermal.md): moderate friction (ζ/I from 2/3 to 2), a
# dipole at x = 2 (⟨cos θ⟩ = 0.537), a triaxial free body.
DIPOLE_INERTIAL = ThermalSetting((2.0, 2.0, 2.0), (1.0, 2.0, 3.0), 1.0, 2.0)
DIPOLE_OVERDAMPED = ThermalSetting((1.0, 1.5, 2.0), None, 1.0, 2.0)
FREE_INERTIAL = ThermalSetting((2.0, 2.0, 2.0), (1.0, 2.0, 3.0), 1.0, None)
FREE_SPHERE = ThermalSetting((1.0, 1.0, 1.0), None, 1.0, None)  # ⟨u(t)·u(0)⟩ = e^{−2Dt}
FREE_OVERDAMPED = ThermalSetting((1.0, 2.0, 4.0), None, 1.0, None)
FREE_PROLATE = ThermalSetting((2.0, 2.0, 1.0), None, 1.0, None)  # D_∥ = 2 D_⊥: exact for the splitting


def _fluid(setting, dtype):
    return Fluid(jnp.asarray(setting.friction, dtype), kT=jnp.asarray(setting.kT, dtype))


def _field(setting, dtype):
    if setting.x is None:
        return None, None
    strength = setting.x * setting.kT  # μ = 1
    args = {
        "field": {
            "moment_body": jnp.array([0.0, 0.0, 1.0], dtype),
            "field": jnp.array([0.0, 0.0, strength], dtype),
        }
    }
    return UniformField(), args


def problem(scheme, setting: ThermalSetting, n: int, key, dtype=jnp.float64, largest_dt=None) -> WeakProblem:
    """The `WeakProblem` of ``setting`` for ``scheme`` with ``n`` bodies (initial state from ``key``);
    ``largest_dt``, when given, lets a Brownian scheme leave out what smaller steps cannot need."""
    fluid = jax.tree_util.tree_map(jnp.asarray, _fluid(setting, dtype))
    torque, args = _field(setting, dtype)
    key_q, key_w = jax.random.split(key)
    if setting.x is None:
        q0 = jnp.tile(jnp.array([1.0, 0.0, 0.0, 0.0], dtype), (n, 1))
    else:
        q0 = dipole_orientations(key_q, n, setting.x, dtype)
    if isinstance(scheme, AbstractBrownianScheme):
        if setting.inertia is not None:
            raise ValueError("an overdamped scheme needs a setting without inertia")
        velocity = velocity_field(fluid, torque, args)
        diffusion = fluid.kT / fluid.friction
        if largest_dt is not None:
            scheme = for_steps(scheme, diffusion[None], largest_dt)

        def advance(carry, t, dt, normals):
            return scheme.advance(*carry, diffusion, t, dt, velocity, normals)

        carry0 = (q0, jax.vmap(velocity, (None, 0))(jnp.zeros((), dtype), q0))
    else:
        inertia = body_inertia(jnp.asarray(setting.inertia, dtype))
        omega0 = maxwell_spins(key_w, q0, inertia.tensor, setting.kT)

        def advance(carry, t, dt, normals):
            return scheme.advance(carry, t, dt, inertia, torque, args, fluid, normals)

        def start(q, omega):
            state = RotState(q, omega)
            tau = scheme.initial_torque(jnp.zeros((), dtype), state, torque, args)
            return LangevinCarry(state, tau, jnp.int32(0))

        carry0 = jax.vmap(start)(q0, omega0)

    def observe(carry):
        q, omega = (carry.state if isinstance(carry, LangevinCarry) else carry)[:2]
        if setting.x is None:
            return jnp.diagonal(quat.to_matrix(q))
        cos_theta = quat.rotate(q, jnp.array([0.0, 0.0, 1.0], dtype))[2]
        if setting.inertia is None:
            return cos_theta[None]
        spin = quat.rotate(quat.conjugate(q), omega)
        return jnp.concatenate([cos_theta[None], jnp.asarray(setting.inertia, dtype) * spin**2 / setting.kT])

    return WeakProblem(advance, carry0, observe, scheme.normals_per_step)


def oracle(setting: ThermalSetting, t_end: float):
    """The closed form of `problem`'s observed quantities ``(k,)`` (NaN where none: the inertial free
    body), at ``t_end`` for the free body."""
    if setting.x is None:
        if setting.inertia is not None:
            return np.full(3, np.nan)
        return axis_correlation(np.asarray(setting.kT) / np.asarray(setting.friction), t_end)
    mean_cos = float(langevin_function(setting.x))
    return np.array([mean_cos] if setting.inertia is None else [mean_cos, 1.0, 1.0, 1.0])
