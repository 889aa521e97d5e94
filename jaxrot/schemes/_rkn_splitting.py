"""Splittings of kicks and exact free rotations, driven by their coefficient arrays.

With ``H = T(L) + V(q, t)`` the flow splits into a **kick** ``L += x h τ(t, q)`` (exact
when the torque does not depend on ω) and a **rotor** flow, the exact torque-free
motion for a time ``x h``. A palindromic sequence of the two, with the coefficients
of a Runge–Kutta–Nyström splitting, reaches high order with few torque calls.
Time advances in the rotor flows only, so a time-dependent torque keeps the order.

A torque that depends on ω makes the kick inexact and the RKN order conditions
fail; `uses_omega` reads the torque's jaxpr and the schemes refuse such a torque.
"""

from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.extend import core as jex_core

from .. import quaternion as quat
from .._state import RotState
from ._base import world_torque
from .splitting import AbstractRotorSplitting, SplittingCarry, _kick, _world_omega


def uses_omega(torque, t, q, omega, args) -> bool:
    """Whether ``torque(t, q, omega, args)`` can depend on ``omega``, read from its jaxpr.

    Conservative: a primitive with ``omega`` among its inputs makes all its outputs
    depend on it (calls of sub-jaxprs, such as ``jit``, are followed inside). Works
    on traced ``t, q, args`` and inside `jaxrot.rollout`'s particle axis.

    Example:
        >>> import jax.numpy as jnp
        >>> q, w = jnp.array([1.0, 0, 0, 0]), jnp.zeros(3)
        >>> uses_omega(lambda t, q, w, a: -0.1 * w, 0.0, q, w, None)
        True
        >>> uses_omega(lambda t, q, w, a: q[1:] * t, 0.0, q, w, None)
        False
    """
    closed = jax.make_jaxpr(lambda w: torque(t, q, w, args))(jax.ShapeDtypeStruct(omega.shape, omega.dtype))
    return any(_dependent_outputs(closed.jaxpr, [True]))


def _dependent_outputs(jaxpr, dependent_inputs):
    dependent = {v for v, d in zip(jaxpr.invars, dependent_inputs, strict=True) if d}
    for eqn in jaxpr.eqns:
        flags = [not isinstance(v, jex_core.Literal) and v in dependent for v in eqn.invars]
        if not any(flags):
            continue
        inner = _sub_jaxpr(eqn)
        if inner is not None:
            outs = _dependent_outputs(inner, flags)
        else:
            outs = [True] * len(eqn.outvars)
        dependent.update(v for v, d in zip(eqn.outvars, outs, strict=True) if d)
    return [not isinstance(v, jex_core.Literal) and v in dependent for v in jaxpr.outvars]


def _sub_jaxpr(eqn):
    """The jaxpr that a call-like primitive runs on exactly its inputs, or None."""
    for value in eqn.params.values():
        inner = getattr(value, "jaxpr", value)
        if isinstance(inner, jex_core.Jaxpr) and (len(inner.invars), len(inner.outvars)) == (
            len(eqn.invars),
            len(eqn.outvars),
        ):
            return inner
    return None


def palindrome(half, middle=()):
    """``half + middle + reversed(half)`` as a tuple of floats."""
    return tuple(half) + tuple(middle) + tuple(reversed(half))


class AbstractRKNSplitting(AbstractRotorSplitting):
    """A palindromic kick/rotor splitting given by its coefficients.

    Subclasses set ``kick_weights`` ``(b_1, …)`` and ``rotor_weights`` ``(a_1, …)``
    in the order they are applied, alternating and starting with the longer one:
    ``len(kicks) = len(rotors) + 1`` is a BAB method (kick first; its last kick's
    torque is reused by the next step's first, so it costs ``len(kicks) − 1`` torque
    calls per step and one in `init`), ``len(rotors) = len(kicks) + 1`` an ABA
    method. Both arrays are checked when the class is defined: each sums to 1 and
    reads the same backwards. ``rotor`` picks the free-rotor flow as in
    `jaxrot.schemes.Splitting`: ``"dmv"`` (default, fast, exact to round-off while
    ``|ω| a_i Δt <= 0.5``) or ``"exact"`` (elliptic functions, any step, ~50× the cost).
    """

    kick_weights: eqx.AbstractClassVar[tuple[float, ...]]
    rotor_weights: eqx.AbstractClassVar[tuple[float, ...]]
    kick_first: ClassVar[bool]

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        kicks, rotors = cls.__dict__.get("kick_weights"), cls.__dict__.get("rotor_weights")
        if kicks is None or rotors is None:
            return
        for label, weights in (("kick_weights", kicks), ("rotor_weights", rotors)):
            if abs(sum(weights) - 1) > 1e-14:
                raise TypeError(f"{cls.__name__}.{label} must sum to 1; they sum to {sum(weights)!r}.")
            if not np.array_equal(weights, weights[::-1]):
                raise TypeError(f"{cls.__name__}.{label} must be palindromic.")
        if abs(len(kicks) - len(rotors)) != 1:
            raise TypeError(f"{cls.__name__}: kicks and rotors must alternate (lengths differ by one).")
        cls.kick_first = len(kicks) > len(rotors)
        cls.torque_evals_per_step = len(kicks) - 1 if cls.kick_first else len(kicks)
        cls.torque_evals_at_init = 1 if cls.kick_first else 0

    def _check_torque(self, torque, t, q, omega, args):
        if torque is not None and uses_omega(torque, t, q, omega, args):
            raise ValueError(
                f"`torque` depends on the angular velocity, which breaks the order of the {self.name!r} "
                "splitting (its kicks are exact only for torques of (t, q)). Use a scheme that handles "
                "velocity-dependent torques: 'rkmk4', 'rkmk_dopri5', 'rkmk_dopri8' "
                "(any order), or 'zhao', 'splitting' (second order)."
            )

    def init(self, state, t0, inertia, torque, args):
        q, omega = state
        self._check_torque(torque, t0, q, omega, args)
        tau = world_torque(torque, t0, q, omega, args) if torque is not None and self.kick_first else None
        return self.principal_carry(state, inertia, tau)

    def step(self, carry, t, dt, inertia, torque, args):
        (q, _), tau, moments, principal, momentum = carry
        dtype = q.dtype
        to_body = quat.conjugate(principal)
        kicks, rotors = np.asarray(self.kick_weights), np.asarray(self.rotor_weights)

        # The rotors and kicks advance the principal-frame momentum (`SplittingCarry.momentum`); the
        # world ω is formed for the torque's argument and the output only.
        def rotor(q_p, momentum, weight):
            return self.flow(q_p, momentum, moments, weight * dt)

        def kick(q_p, momentum, weight, elapsed):
            omega = _world_omega(q_p, momentum, moments)
            tau = world_torque(torque, t + elapsed * dt, quat.multiply(q_p, to_body), omega, args)
            return momentum + _kick(q_p, (weight * dt) * tau), tau

        # One (rotor, kick) pair per scan iteration: the step compiles one rotor, not fifteen.
        q_p = quat.multiply(q, principal)
        if tau is None and torque is not None:
            tau = jnp.zeros_like(momentum)
        if self.kick_first:
            if torque is not None:
                momentum = momentum + _kick(q_p, (float(kicks[0]) * dt) * tau)
            # Row i: rotor a_i, then kick b_{i+1} at the fraction of the step elapsed (time advances
            # in the rotor flows only).
            rows = np.stack([rotors, kicks[1:], np.cumsum(rotors), np.ones_like(rotors)], axis=1)
        else:
            # Row i: rotor a_i, then kick b_i, except after the last rotor (no kick: its torque is
            # skipped by a `lax.cond` on the row, which the particles share, so it stays a branch
            # under `vmap`). All fifteen rotors of SRKN14a in the loop: the first one outside it
            # was a second rotor program (docs/performance.md, "One rotor program per RKN splitting").
            rows = np.stack(
                [rotors, np.append(kicks, 0.0), np.cumsum(rotors), np.append(np.ones_like(kicks), 0.0)],
                axis=1,
            )

        def pair(loop, row):
            q_p, momentum, tau = loop
            q_p, momentum = rotor(q_p, momentum, row[0])
            if torque is not None:
                if self.kick_first:
                    momentum, tau = kick(q_p, momentum, row[1], row[2])
                else:
                    momentum, tau = jax.lax.cond(
                        row[3] > 0,
                        lambda q_p, momentum, tau: kick(q_p, momentum, row[1], row[2]),
                        lambda q_p, momentum, tau: (momentum, tau),
                        q_p,
                        momentum,
                        tau,
                    )
            return (q_p, momentum, tau), None

        (q_p, momentum, tau), _ = jax.lax.scan(pair, (q_p, momentum, tau), jnp.asarray(rows, dtype))
        q1 = quat.multiply(q_p, to_body)
        state = RotState(q1, _world_omega(q_p, momentum, moments))
        return SplittingCarry(state, tau if self.kick_first else None, moments, principal, momentum)
