"""The overdamped (inertia-free) model's schemes: Runge–Kutta–Munthe-Kaas on the orientation alone.

Without inertia the torques on a body balance at every instant, and its orientation obeys

    q̇ = ½ (0, ω(t, q)) ⊗ q,    ω = ω_f(q) + R (ζ⁻¹ ⊙ Rᵀ τ(t, q, ω_f, args)),

(world frame; `jaxrot._fluid._flow`): four numbers per body, nothing stiff. A scheme takes
``q = ψ(Θ) ⊗ q_n`` with ``Θ̇ = dψ⁻¹_Θ(ω)`` in the chart ψ (the exponential, or the Cayley map) and
applies a Butcher tableau to ``Θ``: Lie–Euler (order 1), the Lie midpoint rule (2) and RKMK4 (4,
with ``dψ⁻¹``), Munthe-Kaas, BIT 38, 92 (1998). Each carries ``ω`` at its state: the next step's
first stage and the angular velocity the rollout saves (first same as last).
"""

from collections.abc import Callable
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp

from .. import quaternion as quat
from .._core._fusion import stage
from .._state import RotState
from ._lie_runge_kutta import CHARTS


class AbstractOverdampedScheme(eqx.Module):
    """A Runge–Kutta–Munthe-Kaas scheme for the overdamped model (see the module), one body.

    Class attributes: ``name``, ``order`` (measured by the tests), ``nodes`` (the stages' ``c``
    after the first), ``rows`` (their ``a``), ``weights`` (``b``); ``velocity_evals_per_step``
    follows (one per stage: the first is the last step's end). ``chart`` (static): ``"exp"``
    (default) or ``"cayley"``. With the exponential, a rotation at a constant angular velocity (a
    sphere in a flow) is exact to round-off, as every stage slope is then that velocity; the Cayley
    map's coordinates are not linear in time there (RKMK4: 1e-9 rad after 200 steps of 0.025 rad).
    The Cayley map has no trigonometry: RKMK4's step takes 806 operations (XLA's count, float64)
    with it and 1618 with the exponential, against 1079 for a ``"zhao"`` step of the same body under
    the fluid's torque (the Lie midpoint rule: 711 with the exponential); on Jeffery orbits its
    errors are 0.6–0.8 times the exponential's (aspect ratios 0.2 to 10, 2000 steps a period).
    """

    chart: str = eqx.field(default="exp", static=True)
    name: eqx.AbstractClassVar[str]
    order: eqx.AbstractClassVar[int]
    models: ClassVar[frozenset[str]] = frozenset({"overdamped"})
    nodes: eqx.AbstractClassVar[tuple[float, ...]]
    rows: eqx.AbstractClassVar[tuple[tuple[float, ...], ...]]
    weights: eqx.AbstractClassVar[tuple[float, ...]]

    def __check_init__(self):
        if self.chart not in CHARTS:
            raise ValueError(f"`chart` must be one of {sorted(CHARTS)}; got {self.chart!r}.")

    def overdamped(self) -> "AbstractOverdampedScheme":
        """The stepper `jaxrot.overdamped_rollout` drives: the scheme itself."""
        return self

    @property
    def velocity_evals_per_step(self) -> int:
        return len(self.weights)

    def init(self, q, t0, velocity: Callable) -> RotState:
        """The carry at ``t0``: ``q`` and its angular velocity."""
        return RotState(q, velocity(t0, q))

    def step(self, carry: RotState, t, dt, velocity: Callable) -> RotState:
        """From ``(q_n, ω(t, q_n))`` to ``(q_{n+1}, ω(t + Δt, q_{n+1}))``; ``velocity(t, q) -> (3,)``."""
        chart, inverse_differential = CHARTS[self.chart]
        q0, omega0 = carry
        slopes = [omega0]
        for node, row in zip(self.nodes, self.rows, strict=True):
            theta = _combination(dt, row, slopes)
            rotation, scalar = stage(*chart(theta))
            q_i = stage(quat.multiply(rotation, q0))
            slopes.append(stage(inverse_differential(theta, scalar, velocity(t + node * dt, q_i))))
        rotation, _ = chart(_combination(dt, self.weights, slopes))
        q1 = stage(quat.normalize(quat.multiply(rotation, q0)))
        return RotState(q1, stage(velocity(t + dt, q1)))


def _combination(dt, weights, slopes):
    total = None
    for w, k in zip(weights, slopes, strict=False):
        if w != 0:
            total = (w * dt) * k if total is None else total + (w * dt) * k
    return jnp.zeros_like(slopes[0]) if total is None else total


class LieEuler(AbstractOverdampedScheme):
    """Lie–Euler: ``q_{n+1} = ψ(Δt ω_n) ⊗ q_n``; order 1, one velocity evaluation per step."""

    name: ClassVar[str] = "lie_euler"
    order: ClassVar[int] = 1
    models: ClassVar[frozenset[str]] = frozenset({"overdamped"})
    nodes: ClassVar[tuple] = ()
    rows: ClassVar[tuple] = ()
    weights: ClassVar[tuple] = (1.0,)


class LieMidpoint(AbstractOverdampedScheme):
    """The Lie midpoint rule (RKMK with the midpoint tableau): order 2, two evaluations per step."""

    name: ClassVar[str] = "lie_midpoint"
    order: ClassVar[int] = 2
    models: ClassVar[frozenset[str]] = frozenset({"overdamped"})
    nodes: ClassVar[tuple] = (0.5,)
    rows: ClassVar[tuple] = ((0.5,),)
    weights: ClassVar[tuple] = (0.0, 1.0)


class OverdampedRKMK4(AbstractOverdampedScheme):
    """RKMK4: the classical fourth-order tableau in Munthe-Kaas coordinates; four evaluations per step.

    The overdamped form of `jaxrot.schemes.RKMK4` (``RKMK4().overdamped()``), which is registered
    once as ``"rkmk4"`` for both models; the default of `jaxrot.overdamped_rollout` without a key."""

    name: ClassVar[str] = "rkmk4"
    order: ClassVar[int] = 4
    models: ClassVar[frozenset[str]] = frozenset({"overdamped"})
    nodes: ClassVar[tuple] = (0.5, 0.5, 1.0)
    rows: ClassVar[tuple] = ((0.5,), (0.0, 0.5), (0.0, 0.0, 1.0))
    weights: ClassVar[tuple] = (1 / 6, 1 / 3, 1 / 3, 1 / 6)
