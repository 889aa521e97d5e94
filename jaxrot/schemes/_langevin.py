"""What the Langevin schemes share: their arguments in a rollout, their carry, and the noise per step.

In the body frame, with ``u = ω_b``, a body in a fluid at a temperature obeys (the underdamped
rotational Langevin equation; Davidchack, Ouldridge & Tretyakov, J. Chem. Phys. 142, 144114 (2015))

    I du = [τ_b − u × I u + ζ ⊙ (g(q) − u)] dt + √(2 kT ζ) ⊙ dW,     q̇ = ½ q ⊗ (0, u),

with ``g`` the flow's rotation in the body frame (`jaxrot._fluid._flow`), ``ζ`` the principal
frictions and ``W`` a standard Wiener process in the body frame. Its stationary law is the Boltzmann
distribution: the Maxwell law ``u_k ~ N(0, kT/I_k)`` on each axis (equipartition) and
``exp(−U(q)/kT)`` over orientations for a torque ``τ = −∇U``. A scheme advances one body with
``advance``, given the step's standard normals (``normals_per_step`` of them; None: no noise);
`step` draws them from the body's key and the step counter it carries (`jaxrot.schemes._noise`).
"""

import abc
import dataclasses
from typing import Any, ClassVar, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp

from .. import quaternion as quat
from .._fluid._flow import flow_rotation
from .._state import RotState
from ._base import AbstractScheme
from ._noise import step_normals


class ThermalArgs(NamedTuple):
    """A Langevin scheme's ``args`` in a rollout at a temperature (the ``"thermal"`` model): the
    torque's own, one body's `jaxrot.Fluid` values and its key data (``uint32``). At ``kT = 0`` the
    args are a `FluidArgs`, which has no key (`_unpack`)."""

    args: Any
    fluid: Any
    key_data: Any


class LangevinCarry(NamedTuple):
    """What a Langevin scheme carries between steps (one body).

    Attributes:
        state: the `RotState` ``(q (4,), omega (3,))``, world ω.
        torque: the applied world torque ``(3,)`` at the state (reused by the next step's first
            kick), or None (torque-free, or a scheme that does not reuse it).
        step: the global index of the next step (``int32``): the noise's counter.
    """

    state: RotState
    torque: Any
    step: jax.Array


class AbstractLangevinScheme(AbstractScheme):
    """A scheme for the underdamped Langevin equation of the module; `jaxrot.rollout` with ``fluid=``.

    Class attributes besides `jaxrot.schemes.AbstractScheme`'s: ``normals_per_step`` (standard normals
    per body and step). ``order`` is the weak order (bias of ensemble averages), measured by the
    tests; at ``kT = 0`` it is also the scheme's deterministic order. The static field ``key_impl``
    (the PRNG implementation of the run's key, None without noise) is set by the rollout, which gives
    ``args`` as a `ThermalArgs` at a temperature (``"thermal"``); a Langevin scheme also runs the
    ``"fluid"`` model (``kT = 0``), as `in_fluid` with ``args`` a `FluidArgs` and no noise
    (`jaxrot._integrate._bind` decides which).
    """

    key_impl: str | None = eqx.field(default=None, static=True)
    normals_per_step: eqx.AbstractClassVar[int]
    models: ClassVar[frozenset[str]] = frozenset({"fluid", "thermal"})

    def bind(self, key_impl: str | None) -> "AbstractLangevinScheme":
        """This scheme for a rollout in a fluid whose noise comes from keys of ``key_impl``."""
        return dataclasses.replace(self, key_impl=key_impl)

    def in_fluid(self) -> "AbstractLangevinScheme":
        """This scheme for the ``"fluid"`` model (``kT = 0``): ``args`` a `FluidArgs`, no noise."""
        return self.bind(None)

    def state(self, carry):
        return carry.state

    def with_state(self, carry, state, inertia):
        raise NotImplementedError("drives are not supported in a fluid")

    def init(self, state, t0, inertia, torque, args):
        args, fluid, _ = _unpack(args)
        return LangevinCarry(RotState(*state), self.initial_torque(t0, state, torque, args), jnp.int32(0))

    def initial_torque(self, t0, state, torque, args):
        """The torque the first step reuses (None unless the scheme reuses it)."""
        return None

    def step(self, carry, t, dt, inertia, torque, args):
        args, fluid, key_data = _unpack(args)
        normals = None
        if key_data is not None:
            normals = step_normals(key_data, self.key_impl, carry.step, self.normals_per_step, dt.dtype)
        return self.advance(carry, t, dt, inertia, torque, args, fluid, normals)

    @abc.abstractmethod
    def advance(self, carry, t, dt, inertia, torque, args, fluid, normals) -> LangevinCarry:
        """One step of one body from ``carry`` at ``t`` with the given standard normals
        ``(normals_per_step,)`` (None: no noise); ``fluid`` one body's `jaxrot.Fluid` values,
        ``inertia`` a diagonal `jaxrot.BodyInertia`, ``args`` the torque's own."""


def _unpack(args):
    """``(torque's args, fluid, key data)`` of a `ThermalArgs`, or of a `FluidArgs` (no key: kT = 0)."""
    return args.args, args.fluid, getattr(args, "key_data", None)


def body_flow_rotation(q, fluid):
    """The flow's rotation in the body frame ``(3,)`` at ``q`` (zeros for a fluid at rest)."""
    if fluid.velocity_gradient is None:
        return jnp.zeros(3, q.dtype)
    return quat.rotate(quat.conjugate(q), flow_rotation(q, fluid.velocity_gradient, fluid.bretherton))


def kick(q, weights, impulse):
    """World ``ω`` change ``R (weights ⊙ Rᵀ ΔL)`` of a world angular impulse ``ΔL`` ``(3,)``;
    ``weights`` ``(3,)`` per body axis (``1/I``: the impulse's own velocity change)."""
    return quat.rotate(q, weights * quat.rotate(quat.conjugate(q), impulse))
