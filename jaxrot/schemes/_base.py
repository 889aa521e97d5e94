"""The contract every scheme implements.

A scheme advances **one body**; `jaxrot.rollout` vmaps it over particles and
scans it over time. A scheme may carry more than `RotState` between steps (a
momentum, a reused torque, a frame): `init` builds that carry, `step` advances
it and `state` reads the `RotState` back out. The carry plays the role of
diffrax's ``(y, solver_state)`` pair: the `RotState` is the ``y`` a user sees,
the rest is the scheme's own.
"""

import abc
from collections.abc import Callable
from typing import Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp

from .. import quaternion as quat
from .._core._fusion import stage
from .._inertia import BodyInertia
from .._state import RotState


Torque = Callable[[jax.Array, jax.Array, jax.Array, Any], jax.Array]


class AbstractScheme(eqx.Module):
    """Base class of the integrators in `jaxrot.SCHEMES`.

    Every method acts on **one body**; `jaxrot.rollout` vmaps over particles and
    scans over time. The arguments shared by the methods, documented here once:

    - ``state``: `RotState` ``(q (4,), omega (3,))``; ``q`` a unit quaternion,
      scalar first, mapping body-frame vectors to the world frame; ``omega`` the
      angular velocity in the **world** frame [rad / time].
    - ``carry``: what `init` returns and `step` advances: the `RotState` itself
      for a scheme that needs nothing more (the default), else a scheme-specific
      NamedTuple holding it (read it back with `state`).
    - ``t``: scalar time at the start of the step; ``dt``: scalar step > 0.
    - ``inertia``: body-frame inertia about the centre of mass, principal
      moments ``(3,)`` (fast path) or a symmetric tensor ``(3, 3)``, or a
      `jaxrot.BodyInertia` [mass · length²].
    - ``torque``: ``torque(t, q, omega, args) -> (3,)`` in the world frame for
      one body, or None for a torque-free body (then never called).
    - ``args``: any pytree, passed to ``torque`` unchanged.

    Class attributes (required of every concrete scheme, checked by equinox):
        name: the scheme's one name, registered once (`jaxrot.schemes_for`).
        order: global order of accuracy in ``dt``, as measured by the test suite (the weak
            order for a scheme of the thermal model).
        models: the models the scheme integrates, a frozenset of ``"vacuum"`` (`jaxrot.rollout`
            without ``fluid``), ``"fluid"`` (with a `jaxrot.Fluid` at ``kT = 0``), ``"thermal"``
            (at ``kT > 0``, with a key), ``"overdamped"`` and ``"brownian"``
            (`jaxrot.overdamped_rollout` at ``kT = 0`` and ``kT > 0``): what `jaxrot.rollout`'s
            binder checks once, as diffrax checks a solver's ``term_structure``;
            ``{"vacuum"}`` unless a scheme declares more.
        torque_evals_per_step: calls of the torque callable per step (0 when
            ``torque=None``).
        torque_evals_at_init: extra calls made once by `init` (schemes that
            reuse the end-of-step torque evaluate the first one there); 0 unless set.

    Required method: `step`. A scheme whose carry is not the plain `RotState`
    overrides `init`, `state` and `with_state` together.
    """

    name: eqx.AbstractClassVar[str]
    order: eqx.AbstractClassVar[int]
    models: ClassVar[frozenset[str]] = frozenset({"vacuum"})  # a new inertial scheme: vacuum by default
    torque_evals_per_step: eqx.AbstractClassVar[int]
    torque_evals_at_init: ClassVar[int] = 0

    def init(self, state: RotState, t0, inertia: BodyInertia, torque: Torque | None, args) -> Any:
        """Carry for the first step at time ``t0``; the plain ``state`` unless the scheme needs more."""
        return state

    @abc.abstractmethod
    def step(self, carry, t, dt, inertia: BodyInertia, torque: Torque | None, args) -> Any:
        """Advance one body's ``carry`` from time ``t`` to ``t + dt``; returns the new carry."""

    @property
    def start_steps(self) -> int:
        """How many steps from a run's start `start_step` takes instead of `step` (0: none), as the
        default `starting` reads it; a scheme that overrides `starting` returns any positive number."""
        return 0

    def start_step(self, carry, t, dt, t0, inertia: BodyInertia, torque: Torque | None, args) -> Any:
        """A step of a run's start (where `starting` holds); `step` unless overridden."""
        return self.step(carry, t, dt, inertia, torque, args)

    def starting(self, carry, index, t, t0, dt, inertia: BodyInertia, args):
        """Whether step ``index`` (from 0, at ``t``, of a run begun at ``t0``) is a `start_step`:
        a boolean scalar that does not depend on the body (under `jax.vmap` the choice must stay one
        branch); the first `start_steps` steps unless overridden."""
        return index < self.start_steps

    def state(self, carry) -> RotState:
        """The `RotState` held in a carry."""
        return carry

    def with_state(self, carry, state: RotState, inertia: BodyInertia) -> Any:
        """``carry`` with its orientation and angular velocity replaced by ``state``.

        Used for velocity-driven bodies; schemes that carry derived quantities
        (a momentum) recompute them here without calling the torque.
        """
        if isinstance(carry, RotState):
            return state
        raise NotImplementedError(
            f"{type(self).__name__} carries {type(carry).__name__}: override with_state to support drives."
        )

    def driven_rotation(self, q, omega, dt):
        """Orientation after ``dt`` at imposed world angular velocity ``omega``: exactly ``exp(ω Δt) ⊗ q``."""
        return quat.multiply(quat.exp(dt * omega), q)

    def summarize(self, carry):
        """What `report` needs of a final carry, reduced over the particles (traceable), or None.

        Small, so that a rollout that does not return its carry need not keep it."""
        return None

    def report(self, summary) -> str | None:
        """A warning about a finished rollout, from its concrete `summarize` output, or None."""
        return None


def world_torque(torque: Torque, t, q, omega, args):
    """The torque callable's world-frame torque ``(3,)``, in the dtype of ``q``, shape-checked."""
    tau = jnp.asarray(torque(t, q, omega, args)).astype(q.dtype)
    if tau.shape != (3,):
        raise ValueError(
            f"`torque` must return a world-frame torque of shape (3,) for one body; got {tau.shape}."
        )
    return tau


def body_torque(torque: Torque | None, t, q, omega, args):
    """Torque in the body frame of ``q``; None when the scene is torque-free."""
    if torque is None:
        return None
    return stage(quat.rotate(quat.conjugate(q), world_torque(torque, t, q, omega, args)))


def advance(
    scheme: AbstractScheme, carry, index, t, t0, dt, inertia: BodyInertia, torque: Torque | None, args
):
    """Step ``index`` (from 0) of a run begun at ``t0``: `AbstractScheme.start_step` where
    `AbstractScheme.starting` holds (the first ``scheme.start_steps`` by default), `AbstractScheme.step`
    elsewhere.

    ``index`` must not depend on the body (a loop counter): under `jax.vmap` the choice stays one
    branch, not a select that would compute both.
    """
    if scheme.start_steps == 0:
        return scheme.step(carry, t, dt, inertia, torque, args)
    return jax.lax.cond(
        scheme.starting(carry, index, t, t0, dt, inertia, args),
        lambda c: scheme.start_step(c, t, dt, t0, inertia, torque, args),
        lambda c: scheme.step(c, t, dt, inertia, torque, args),
        carry,
    )
