"""Torque models: small composable pieces for `jaxrot.scenes` and your own scenes.

A model is a callable ``model(t, q, omega, args) -> (3,)`` (world frame, one
body), so it goes wherever a torque function goes. Each model reads its
parameters from ``args[model.key]`` (a dict), so one ``args`` dict carries a
sum of models. A parameter that differs per body is wrapped in
`jaxrot.per_body`: `jaxrot.rollout` hands each body its own row.

Models add up with ``+``. ``model.energy(t, q, args)`` is the total potential
energy of all bodies ``q`` ``(N, 4)`` for conservative models (None for the
others), for energy checks.

A **coupled** model sees every body at once (``coupled = True``, here
`DipoleInteraction`). `jaxrot.rollout` and `jaxrot.reference_rollout` vmap
bodies over the named axis `PARTICLES`; a coupled model gathers the other
bodies' stage states with ``jax.lax.all_gather`` and finds its own row with
`body_index`. Every scheme works unchanged: all bodies run the same stages in
lockstep, so each gather sees the other bodies at the same stage. All bodies
of one rollout interact; call a coupled model only inside those two functions.

Example:
    >>> import jax.numpy as jnp, jaxrot
    >>> from jaxrot import torques
    >>> model = torques.Gravity() + torques.ViscousDrag()
    >>> args = {"gravity": {"offset_body": jnp.array([0.0, 0, 0.3]), "weight": jnp.array([0.0, 0, -9.81])},
    ...         "drag": {"coefficient": jaxrot.per_body(jnp.array([0.1, 0.5]))}}
    >>> s = jaxrot.RotState(jnp.array([[1.0, 0, 0, 0]] * 2), jnp.array([[0.0, 1, 5]] * 2))
    >>> jaxrot.rollout("zhao", s, jnp.array([1.0, 1, 0.5]), 0.01, 10, torque=model, args=args).q.shape
    (11, 2, 4)
"""

import math
from collections.abc import Callable
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp

from . import quaternion as quat
from ._particles import PARTICLES, is_per_body, unwrap_per_body


def body_index():
    """Index of the current body along the particle axis (inside `rollout` / `reference_rollout` only)."""
    return jax.lax.axis_index(PARTICLES)


class TorqueModel(eqx.Module):
    """Base class: a world-frame torque on one body with its parameters in ``args[key]``.

    Class attributes:
        coupled: True when the torque on one body depends on the others.
        conservative: True when `energy` is defined.
    """

    coupled: ClassVar[bool] = False
    conservative: ClassVar[bool] = False

    def __call__(self, t, q, omega, args):
        raise NotImplementedError

    def energy(self, t, q, args):
        """Total potential energy (J) of bodies ``q`` ``(N, 4)`` at time ``t``; None if not conservative."""
        return None

    def __add__(self, other):
        mine = self.terms if isinstance(self, Sum) else (self,)
        theirs = other.terms if isinstance(other, Sum) else (other,)
        return Sum(mine + theirs)


class Sum(TorqueModel):
    """The sum of several models (build it with ``a + b``)."""

    terms: tuple

    @property
    def coupled(self):
        return any(term.coupled for term in self.terms)

    @property
    def conservative(self):
        return all(term.conservative for term in self.terms)

    def __call__(self, t, q, omega, args):
        return sum(term(t, q, omega, args) for term in self.terms)

    def energy(self, t, q, args):
        if not self.conservative:
            return None
        return sum(term.energy(t, q, args) for term in self.terms)


def _per_body_energy(fn, t, q, params):
    """Sum over bodies ``q`` ``(N, 4)`` of a one-body potential ``fn(t, q_i, params_i)``.

    A `per_body` leaf's leading particle axes (any number, ``N`` values in all) are
    flattened to one; its trailing axes reach ``fn`` as they are.
    """

    def rows(x):
        value = x.value
        n_axes = next(k for k in range(1, value.ndim + 1) if math.prod(value.shape[:k]) == q.shape[0])
        return value.reshape(q.shape[0], *value.shape[n_axes:])

    axes = jax.tree_util.tree_map(lambda x: 0 if is_per_body(x) else None, params, is_leaf=is_per_body)
    values = jax.tree_util.tree_map(lambda x: rows(x) if is_per_body(x) else x, params, is_leaf=is_per_body)
    return jnp.sum(jax.vmap(fn, in_axes=(None, 0, axes))(t, q, values))


class Gravity(TorqueModel):
    """Weight on a centre of mass offset from a fixed pivot: ``τ = r × F``, ``U = −F·r``.

    ``args[key]``: ``offset_body`` ``(3,)`` m (pivot → centre of mass, body frame),
    ``weight`` ``(3,)`` N (world frame, ``m g``).

    The rollout's ``inertia`` is then the inertia about the pivot, which exceeds the central one
    by the parallel-axis term ``m(|r|²𝟙 − r rᵀ)``: build it with `jaxrot.pivot_inertia(central,
    mass, offset_body)`, or check one with `jaxrot.central_inertia(pivot, mass, offset_body)`
    (a ``ValueError`` if no body has it). The torque itself cannot check: it knows the weight,
    not the mass (``g`` is yours).
    """

    key: str = eqx.field(static=True, default="gravity")
    conservative: ClassVar[bool] = True

    def __call__(self, t, q, omega, args):
        p = args[self.key]
        return jnp.cross(quat.rotate(q, p["offset_body"]), p["weight"])

    def energy(self, t, q, args):
        def one(t, q, p):
            return -jnp.dot(p["weight"], quat.rotate(q, p["offset_body"]))

        return _per_body_energy(one, t, q, args[self.key])


class UniformField(TorqueModel):
    """A magnetic dipole in a uniform field: ``τ = m × B``, ``U = −m·B``.

    ``args[key]``: ``moment_body`` ``(3,)`` A m² (body frame), ``field`` ``(3,)`` T (world).
    """

    key: str = eqx.field(static=True, default="field")
    conservative: ClassVar[bool] = True

    def __call__(self, t, q, omega, args):
        p = args[self.key]
        return jnp.cross(quat.rotate(q, p["moment_body"]), p["field"])

    def energy(self, t, q, args):
        def one(t, q, p):
            return -jnp.dot(quat.rotate(q, p["moment_body"]), p["field"])

        return _per_body_energy(one, t, q, args[self.key])


class RotatingField(TorqueModel):
    """A magnetic dipole in a field rotating in the world xy plane: ``B(t) = B₀ (cos Ωt, sin Ωt, 0)``.

    ``args[key]``: ``moment_body`` ``(3,)`` A m², ``amplitude`` T, ``angular_frequency``
    Ω rad/s. Time-dependent, so energy is not conserved (the field does work).
    """

    key: str = eqx.field(static=True, default="rotating_field")

    def field(self, t, p):
        phase = p["angular_frequency"] * t
        zero = jnp.zeros_like(phase)
        return p["amplitude"] * jnp.stack([jnp.cos(phase), jnp.sin(phase), zero])

    def __call__(self, t, q, omega, args):
        p = args[self.key]
        return jnp.cross(quat.rotate(q, p["moment_body"]), self.field(t, p))


class ViscousDrag(TorqueModel):
    """Rotational drag ``τ = −c ω`` (world frame): energy decays at ``dE/dt = −c |ω|²``.

    ``args[key]``: ``coefficient`` c ≥ 0, N m s. Velocity-dependent: each scheme
    calls it with its own stage velocity.
    """

    key: str = eqx.field(static=True, default="drag")

    def __call__(self, t, q, omega, args):
        return -args[self.key]["coefficient"] * omega


class DipoleInteraction(TorqueModel):
    """Point magnetic dipoles at fixed positions, each turned by the field of all the others.

    Coupled: the torque on body i is ``m_i × Σ_{j≠i} B_j(r_i)`` with the dipole field
    ``B_j(r) = k (3 (m_j·r̂) r̂ − m_j) / |r|³``, ``r = r_i − r_j``, ``m_i = q_i m_body``;
    the energy is ``U = −½ Σ_i m_i·Σ_{j≠i} B_j(r_i)``. ``args[key]``: ``positions``
    ``(N, 3)`` m (all bodies, fixed), ``moment_body`` ``(3,)`` A m² (or per body,
    ``per_body((N, 3))``), ``strength`` k = μ₀/4π (1e-7 T m/A in SI; 1 in reduced units).

    The positions are pinned, so the pins take up momentum: the mutual torques
    do not cancel (``Σ_i τ_i = −Σ_i r_i × F_i``, with ``F_i = −∂U/∂r_i``) and the
    bodies' total spin angular momentum is not conserved by the interaction
    alone; `pinning_torque` gives that balance. Energy is conserved.
    """

    key: str = eqx.field(static=True, default="dipoles")
    coupled: ClassVar[bool] = True
    conservative: ClassVar[bool] = True

    @staticmethod
    def _field_at(r_i, positions, moments, strength, self_index):
        """Field at ``r_i`` of all dipoles except ``self_index``; NaN-free for the excluded self term."""
        d = r_i[None, :] - positions
        dist2 = jnp.sum(d * d, axis=-1)
        others = jnp.arange(positions.shape[0], dtype=jnp.asarray(self_index).dtype) != self_index
        safe = jnp.where(others, dist2, 1.0)
        inv_r = jax.lax.rsqrt(safe)
        r_hat = d * inv_r[:, None]
        m_dot_r = jnp.sum(moments * r_hat, axis=-1)
        b = strength * (3 * m_dot_r[:, None] * r_hat - moments) * (inv_r**3)[:, None]
        return jnp.sum(jnp.where(others[:, None], b, 0), axis=0)

    def __call__(self, t, q, omega, args):
        p = args[self.key]
        i = body_index()
        moment = quat.rotate(q, p["moment_body"])
        moments = jax.lax.all_gather(moment, PARTICLES)
        b = self._field_at(p["positions"][i], p["positions"], moments, p["strength"], i)
        return jnp.cross(moment, b)

    def _moments(self, q, p):
        m_body = jnp.broadcast_to(p["moment_body"], q.shape[:-1] + (3,))
        return quat.rotate(q, m_body)

    def energy(self, t, q, args, positions=None):
        p = unwrap_per_body(args[self.key])
        positions = p["positions"] if positions is None else positions
        moments = self._moments(q, p)
        idx = jnp.arange(q.shape[0])
        fields = jax.vmap(self._field_at, in_axes=(0, None, None, None, 0))(
            positions, positions, moments, p["strength"], idx
        )
        return -0.5 * jnp.sum(moments * fields)

    def pinning_torque(self, t, q, args):
        """``Σ_i r_i × F_i`` (world, ``(3,)``): the torque the pins must absorb; ``Σ_i τ_i = −`` this."""
        p = unwrap_per_body(args[self.key])
        forces = -jax.grad(lambda r: self.energy(t, q, args, positions=r))(p["positions"])
        return jnp.sum(jnp.cross(p["positions"], forces), axis=0)


class Potential(TorqueModel):
    """The torque of a potential energy ``energy(t, q, args) -> scalar`` of one body, by differentiation.

    ``q`` is the body's orientation ``(4,)`` (scalar first, body → world) and
    ``args`` its parameters: ``args[key]``, or the whole ``args`` when ``key`` is
    None (the default); `jaxrot.per_body` leaves arrive as this body's row. A
    world-frame rotation ``δθ`` of the body, ``q → exp(δθ) ⊗ q``, changes the
    energy by ``−τ·δθ``, so the world-frame torque is

        ``τ = −∂/∂δθ energy(t, exp(δθ) ⊗ q, args)`` at ``δθ = 0``,

    one reverse-mode pass through ``energy`` (``exp`` has an exact, finite
    derivative at 0, so ``τ`` is finite wherever ``energy``'s gradient is). Only
    the rotation of ``q`` counts: a change of ``|q|`` does nothing. Works under
    ``jit``, ``vmap`` and ``grad`` (of the torque or a rollout through it, with
    respect to ``args``: fits). ``energy`` may be any callable, an
    ``equinox.Module`` with array fields included (those are traced, not
    baked in).

    ``model.energy(t, q, args)`` is the total over bodies ``q`` ``(N, 4)``, for
    energy checks; with an explicitly time-dependent ``energy`` the total
    changes at the rate ``∂energy/∂t``. One body's energy only: an interaction
    of several bodies is a coupled model (`DipoleInteraction`). Same numbers as
    the built-in models: `Gravity` is ``Potential(lambda t, q, p: -p["weight"] @
    rotate(q, p["offset_body"]), key="gravity")`` (``tests/test_potential.py``).

    Example:
        >>> import jax.numpy as jnp, jaxrot
        >>> from jaxrot import quaternion as quat, torques
        >>> def nematic(t, q, p):  # −k (n·u)²: the body axis u = body z pulled to ±n, either way
        ...     return -p["k"] * jnp.dot(p["n"], quat.rotate(q, jnp.array([0.0, 0, 1]))) ** 2
        >>> model = torques.Potential(nematic, key="nematic") + torques.ViscousDrag()
        >>> args = {"nematic": {"k": 2.0, "n": jnp.array([1.0, 0, 0])}, "drag": {"coefficient": 0.5}}
        >>> q = quat.from_axis_angle(jnp.array([0.0, 1, 0]), jnp.pi / 4)  # body z halfway to world x
        >>> print(model(0.0, q, jnp.zeros(3), args).round(6).tolist())  # 2k (n·u) u × n
        [0.0, 2.0, 0.0]
    """

    energy_fn: Callable
    key: str | None = eqx.field(static=True)
    conservative: ClassVar[bool] = True

    def __init__(self, energy: Callable, key: str | None = None):
        if not callable(energy):
            raise ValueError(
                f"`energy` must be a callable energy(t, q, args) -> scalar; got {type(energy).__name__}."
            )
        self.energy_fn = energy
        self.key = key

    def _params(self, args):
        return args if self.key is None else args[self.key]

    def __call__(self, t, q, omega, args):
        params = self._params(args)

        def turned(delta):
            return self.energy_fn(t, quat.multiply(quat.exp(delta), q), params)

        return -jax.grad(turned)(jnp.zeros_like(q[..., 1:]))

    def energy(self, t, q, args):
        return _per_body_energy(self.energy_fn, t, q, self._params(args))
