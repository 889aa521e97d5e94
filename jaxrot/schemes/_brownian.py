r"""Brownian rotation: the overdamped model at a temperature, on the rotation group.

Without inertia a body in a fluid at a temperature turns by (Favro, Phys. Rev. 119, 53 (1960);
Höfling & Straube, arXiv:2403.04501)

    q(t + dt) = exp(ω(t, q) dt) ⊗ q ⊗ exp(√(2 D) ⊙ dW),     D_k = kT / ζ_k,

with ``ω`` the deterministic (overdamped) world angular velocity of `jaxrot.overdamped_rollout` and
``W`` a standard Wiener process in the body frame (the friction's axes): the generator is
``ω·∇ + Σ_k D_k L_k²``, ``L_k`` the body-frame derivative about axis ``k``. For a torque
``τ = −∇U`` its stationary law is ``exp(−U/kT)``. The schemes act on the body side with unit
quaternions, so ``|q| = 1`` to round-off. Each carries, per body, its key data, the step counter of
its noise and its diffusion ``D`` ``(3,)``, set by `brownian_start`.
"""

import abc
import dataclasses
from typing import Any, ClassVar, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import quaternion as quat
from .._core._concrete import is_concrete
from .._core._fusion import stage
from .._state import RotState
from ._heat_kernel import SMALL_STEP, heat_kernel_rotation
from ._noise import step_normals


class BrownianStart(NamedTuple):
    """One body's start, as `jaxrot.overdamped_rollout`'s loop hands it to `init`."""

    q: jax.Array
    key_data: Any
    diffusion: jax.Array


class BrownianCarry(NamedTuple):
    """What a Brownian scheme carries (one body): ``q`` ``(4,)``; ``omega`` ``(3,)``, the deterministic
    world angular velocity at ``q`` (the next step's first stage, and what the rollout saves); the
    global ``step`` index (``int32``); the body's ``key_data``; its ``diffusion``
    ``(3,)`` about the body axes."""

    q: jax.Array
    omega: jax.Array
    step: jax.Array
    key_data: Any
    diffusion: jax.Array


class AbstractBrownianScheme(eqx.Module):
    """A scheme of the module's stochastic equation for `jaxrot.overdamped_rollout`, one body.

    Class attributes: ``name``, ``order`` (weak order, measured by the tests), ``normals_per_step``,
    ``velocity_evals_per_step``. ``key_impl`` (static) is set by the rollout. `advance` takes the
    step's standard normals (None: no noise, as `Noiseless` runs it at ``kT = 0``); `step` draws them
    from the carried key and counter (the ``"brownian"`` model always has a key).
    """

    key_impl: str | None = eqx.field(default=None, static=True)
    name: eqx.AbstractClassVar[str]
    order: eqx.AbstractClassVar[int]
    models: ClassVar[frozenset[str]] = frozenset({"overdamped", "brownian"})
    normals_per_step: eqx.AbstractClassVar[int]
    velocity_evals_per_step: eqx.AbstractClassVar[int]

    def bind(self, key_impl):
        return dataclasses.replace(self, key_impl=key_impl)

    def init(self, start: BrownianStart, t0, velocity) -> BrownianCarry:
        q = start.q
        return BrownianCarry(q, velocity(t0, q), jnp.int32(0), start.key_data, start.diffusion)

    def step(self, carry: BrownianCarry, t, dt, velocity) -> BrownianCarry:
        normals = step_normals(carry.key_data, self.key_impl, carry.step, self.normals_per_step, dt.dtype)
        q, omega = self.advance(carry.q, carry.omega, carry.diffusion, t, dt, velocity, normals)
        return carry._replace(q=q, omega=omega, step=carry.step + 1)

    @abc.abstractmethod
    def advance(self, q, omega, diffusion, t, dt, velocity, normals):
        """``(q₁, ω(t + Δt, q₁))`` from ``q`` with ``omega = ω(t, q)``; ``velocity(t, q) -> (3,)`` world."""

    def overdamped(self) -> "Noiseless":
        """The stepper of the ``"overdamped"`` model (``kT = 0``): this scheme without noise."""
        return Noiseless(self)


class Noiseless(eqx.Module):
    """A Brownian scheme at ``kT = 0``, with the interface of
    `jaxrot.schemes.AbstractOverdampedScheme` (carry: a `RotState` ``(q, ω(t, q))``): its `advance`
    without normals, which then needs no key and no diffusion."""

    scheme: AbstractBrownianScheme

    @property
    def name(self) -> str:
        return self.scheme.name

    @property
    def order(self) -> int:
        return self.scheme.order

    @property
    def velocity_evals_per_step(self) -> int:
        return self.scheme.velocity_evals_per_step

    def overdamped(self) -> "Noiseless":
        return self

    def init(self, q, t0, velocity) -> RotState:
        return RotState(q, velocity(t0, q))

    def step(self, carry: RotState, t, dt, velocity) -> RotState:
        return RotState(*self.scheme.advance(carry.q, carry.omega, None, t, dt, velocity, None))


def _body_turn(q, rotvec_body):
    # Stage boundary (`jaxrot._core._fusion`): XLA otherwise copies each product's expression tree into the
    # four components of the next (five chained turns ran 400x slower).
    return stage(quat.multiply(q, quat.exp(rotvec_body)))


def _root(x):
    """``√x`` for ``x ≥ 0``, with a zero (not infinite) derivative at 0."""
    positive = x > 0
    return jnp.where(positive, jnp.sqrt(jnp.where(positive, x, 1.0)), 0.0)


class BrownianEuler(AbstractBrownianScheme):
    r"""Geometric Euler–Maruyama: ``q₁ = q ⊗ exp(Δt Rᵀω + √(2DΔt) ⊙ ξ)``; weak order 1.

    One velocity evaluation per step (the end state's is the next step's first), three normals: the
    Gaussian random rotation of Höfling & Straube (arXiv:2403.04501, section IV; Davidchack,
    Ouldridge & Tretyakov's gradient thermostat, J. Chem. Phys. 142, 144114 (2015), is of the same
    order). For free diffusion of a sphere ``⟨u(Δt)·u(0)⟩`` is ``1/3 + (2/3)(1 − 2DΔt) e^{−DΔt}``
    against the exact ``e^{−2DΔt}``: an error ``D²Δt²/3`` per step.
    """

    name: ClassVar[str] = "brownian_euler"
    order: ClassVar[int] = 1
    models: ClassVar[frozenset[str]] = frozenset({"overdamped", "brownian"})
    normals_per_step: ClassVar[int] = 3
    velocity_evals_per_step: ClassVar[int] = 1

    def advance(self, q, omega, diffusion, t, dt, velocity, normals):
        rotvec = dt * quat.rotate(quat.conjugate(q), omega)
        if normals is not None:
            rotvec = rotvec + _root(2 * diffusion * dt) * normals
        q1 = quat.normalize(_body_turn(q, rotvec))
        return q1, velocity(t + dt, q1)


def free_diffusion(q, diffusion, dt, normals, large_steps=True):
    r"""``q`` turned by free rotational diffusion over ``dt``: exact in law for a sphere and for a body
    with at most one axis of faster diffusion (a prolate spheroid), weak order 2 otherwise.

    The generator splits as ``D_min L² + Σ_k c_k L_k²`` (``c_k = D_k − D_min ≥ 0``; ``L²`` commutes
    with every ``L_k``): the first factor is the heat kernel of SO(3) (`heat_kernel_rotation`,
    normals 0–2), the rest Gaussian turns about single body axes, composed symmetrically
    (``c₁/2, c₂/2, c₃, c₂/2, c₁/2``; normals 3–7), exact when only one ``c_k`` is nonzero."""
    smallest = jnp.min(diffusion)
    q = stage(quat.multiply(q, stage(heat_kernel_rotation(normals[:3], smallest * dt, large_steps))))
    extra = diffusion - smallest
    for i, (axis, fraction) in enumerate(((0, 0.5), (1, 0.5), (2, 1.0), (1, 0.5), (0, 0.5))):
        angle = _root(2 * extra[axis] * fraction * dt) * normals[3 + i]
        q = _body_turn(q, angle * jnp.eye(3, dtype=q.dtype)[axis])
    return q


class BrownianSplitting(AbstractBrownianScheme):
    r"""Strang splitting around the exact free diffusion: weak order 2 with torques; exact in law for
    free diffusion (spheres, prolate spheroids) at any step.

    One step: the deterministic flow over ``Δt/2`` by the Lie midpoint rule (two velocity
    evaluations), free diffusion over ``Δt`` (`free_diffusion`: the heat kernel of SO(3), eight
    normals), the deterministic flow over ``Δt/2``; the end state's velocity is the next step's first
    (four evaluations per step). A symmetric splitting of the generator with each part second order or
    exact, so weak order 2; without torque or flow the step is the free diffusion alone. The
    variant of Höfling & Straube (arXiv:2403.04501) that is exact in law for free diffusion, with the
    torque's flow around it.
    """

    name: ClassVar[str] = "brownian_splitting"
    order: ClassVar[int] = 2
    models: ClassVar[frozenset[str]] = frozenset({"overdamped", "brownian"})
    normals_per_step: ClassVar[int] = 8
    velocity_evals_per_step: ClassVar[int] = 4
    # Static: whether some body's ``D_min Δt`` may exceed `SMALL_STEP` (the heat kernel's spectral
    # branch is then compiled too); `jaxrot.overdamped_rollout` clears it when it sees they cannot.
    large_steps: bool = eqx.field(default=True, static=True)

    def advance(self, q, omega, diffusion, t, dt, velocity, normals):
        quarter, half = 0.25 * dt, 0.5 * dt

        def drift(q, omega, t):  # the Lie midpoint rule over Δt/2 from (q, ω(t, q))
            middle = stage(quat.multiply(quat.exp(quarter * omega), q))
            slope = stage(velocity(t + quarter, middle))
            return stage(quat.normalize(quat.multiply(quat.exp(half * slope), q)))

        q = drift(q, omega, t)
        if normals is not None:
            q = quat.normalize(free_diffusion(q, diffusion, dt, normals, self.large_steps))
        q = drift(q, stage(velocity(t + half, q)), t + half)
        return q, velocity(t + dt, q)


def for_steps(scheme, diffusion, dt):
    """``scheme`` without the heat kernel's spectral branch when concrete ``diffusion`` ``(N, 3)`` and
    ``dt`` show that no body's ``D_min Δt`` reaches `SMALL_STEP`; else ``scheme``."""
    if not isinstance(scheme, BrownianSplitting) or not is_concrete(diffusion, dt):
        return scheme
    largest = float(np.max(np.min(np.asarray(diffusion), axis=-1), initial=0.0) * np.max(np.asarray(dt)))
    return dataclasses.replace(scheme, large_steps=largest > SMALL_STEP)
