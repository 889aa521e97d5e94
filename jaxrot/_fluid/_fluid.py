"""`Fluid`: the friction, the flow and the temperature a body turns in; its checks for a rollout."""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._core._checks import declared_dtype, is_concrete
from .._particles import PerBody, is_per_body, per_body
from ._flow import fluid_torque, overdamped_velocity
from ._perrin import bretherton_factor, spheroid_friction


# Each field's shape for one body; leading axes beyond it are the particle axes.
_BODY_SHAPES = {"friction": (3,), "velocity_gradient": (3, 3), "bretherton": (), "kT": ()}
# |tr A| allowed relative to the largest |A_ij|: a velocity gradient written with a few digits or
# computed in float32 keeps its trace within ~1e-7 of its size; a compressible flow is off by O(1).
TRACE_TOL = 1e-6


def _unwrap(x):
    return x.value if is_per_body(x) else x


def _concrete_array(x):
    return np.asarray(_unwrap(x), dtype=np.float64) if is_concrete(_unwrap(x)) else None


class Fluid(eqx.Module):
    """A viscous fluid, at rest or in a linear flow, and a body's friction in it (a pytree).

    Args:
        friction: the body's principal rotational frictions ``(3,)`` about its body axes
            (torque per angular velocity, e.g. N m s), or one row per body ``(..., 3)`` (the
            particle axes of the rollout in front, or a `jaxrot.per_body`). Positive. With
            ``bretherton`` nonzero, body z is the symmetry axis. Inertial rollouts need the
            inertia as principal moments about the same axes.
        velocity_gradient: ``A`` ``(3, 3)`` in the world frame, ``A[i, j] = ∂u_i/∂x_j`` of the
            flow ``u = A x`` at the body, traceless (incompressible); shared or ``(..., 3, 3)`` per
            body; None for a fluid at rest (then nothing of the flow is computed).
        bretherton: Jeffery's shape factor ``B`` in ``(−1, 1)``: ``(λ² − 1)/(λ² + 1)`` for a
            spheroid of aspect ratio λ (`Fluid.spheroid`), 0 for a sphere; scalar or per body.
        kT: the thermal energy (≥ 0); ``kT > 0`` adds the thermal torque that balances the
            friction and needs a PRNG ``key`` in the rollout. Scalar or per body. Whether it is 0
            is recorded when the fluid is built (the static field ``temperature``: ``"zero"``,
            ``"positive"``, or ``"traced"`` for a traced value), so a fluid built outside ``jit``
            and passed in keeps its model; build a new `Fluid` to change ``kT``.

    The torque on a body at ``(q, ω)`` (world frame, `torque`) is
    ``τ = R (ζ ⊙ Rᵀ (Ω + B p × (E p) − ω))`` with ``Ω = ½ ∇ × u``, ``E = ½ (A + Aᵀ)``, ``R`` the
    rotation of ``q`` and ``p = R e_z``; without inertia the body turns at `angular_velocity`.

    Raises:
        ValueError: friction not positive, a velocity gradient that is not traceless, a shape
            factor outside (−1, 1), a negative ``kT``, non-finite values or wrong shapes (concrete
            values only; under ``jit`` the value checks are skipped).

    Example:
        >>> import jax.numpy as jnp, jaxrot
        >>> shear = jnp.array([[0.0, 1.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])  # u = (y, 0, 0)
        >>> sphere = jaxrot.Fluid.spheroid(1.0, 1.0, viscosity=1.0, velocity_gradient=shear)
        >>> sphere.angular_velocity(jnp.array([1.0, 0, 0, 0])).tolist()  # half the vorticity
        [0.0, 0.0, -0.5]
    """

    friction: jax.Array | PerBody
    velocity_gradient: jax.Array | PerBody | None
    bretherton: jax.Array | PerBody
    kT: jax.Array | PerBody
    # Whether kT is 0, read where it was given (`temperature_of`): "zero", "positive" or "traced".
    # Static, so that a Fluid passed through `jax.jit` still tells the rollout at trace time which
    # model it asks for (`jaxrot._integrate._bind`).
    temperature: str = eqx.field(static=True)

    def __init__(self, friction, *, velocity_gradient=None, bretherton=0.0, kT=0.0):
        def array(x):
            return per_body(x.value) if is_per_body(x) else jnp.asarray(x)

        self.friction = array(friction)
        self.velocity_gradient = None if velocity_gradient is None else array(velocity_gradient)
        self.bretherton = array(bretherton)
        self.temperature = temperature_of(kT)
        self.kT = array(kT)
        _check_values(self)

    @classmethod
    def spheroid(cls, polar, equatorial, viscosity, *, velocity_gradient=None, kT=0.0) -> "Fluid":
        """A spheroid's fluid: Perrin's frictions and Jeffery's shape factor, symmetry axis body z.

        Args:
            polar: the semi-axis along the symmetry axis (body z).
            equatorial: the semi-axis across it.
            viscosity: the fluid's dynamic viscosity η.
            velocity_gradient, kT: as in `Fluid`.

        Each of ``polar``, ``equatorial``, ``viscosity`` may be an array (or a `jaxrot.per_body`)
        with the particle axes: the frictions ``(..., 3)`` and shape factors follow it. The
        frictions are Perrin's (J. Phys. Radium 5, 497 (1934); see `jaxrot._fluid._perrin`):
        ``8πηa³`` for a sphere of radius ``a``; ``bretherton = (λ² − 1)/(λ² + 1)``,
        ``λ = polar / equatorial``.

        Example:
            >>> import jax.numpy as jnp, jaxrot
            >>> needle = jaxrot.Fluid.spheroid(4.0, 1.0, viscosity=1.0)
            >>> needle.friction.round(3).tolist(), round(float(needle.bretherton), 4)
            ([341.366, 341.366, 72.487], 0.8824)
        """
        marked = any(is_per_body(x) for x in (polar, equatorial, viscosity))
        values = [_unwrap(x) for x in (polar, equatorial, viscosity)]
        for name, value in zip(("polar", "equatorial", "viscosity"), values, strict=True):
            declared_dtype(value, name)
            if is_concrete(value):
                raw = np.asarray(value, dtype=np.float64)
                if not np.all(np.isfinite(raw)) or np.any(raw <= 0):
                    raise ValueError(
                        f"`{name}` must be finite and > 0; got {raw if raw.size < 7 else '...'}."
                    )
        friction = spheroid_friction(*values)
        bretherton = bretherton_factor(*values[:2])
        if marked:
            friction, bretherton = per_body(friction), per_body(bretherton)
        return cls(friction, velocity_gradient=velocity_gradient, bretherton=bretherton, kT=kT)

    def torque(self, q, omega):
        """The fluid's world torque ``(..., 3)`` on bodies at ``q`` ``(..., 4)`` turning at world ``ω``.

        As a plain torque callable: ``lambda t, q, omega, args: fluid.torque(q, omega)`` (for one
        shared fluid; integrated explicitly, such a torque limits the step to about ``ζΔt/I < 2``).
        """
        return fluid_torque(q, omega, jax.tree_util.tree_map(_unwrap, self, is_leaf=is_per_body))

    def angular_velocity(self, q, torque=None):
        """The overdamped world angular velocity ``(..., 3)`` of bodies at ``q``: the flow's rotation
        ``Ω + B p × (E p)`` plus ``R (ζ⁻¹ ⊙ Rᵀ τ)`` for an applied world ``torque`` (or None)."""
        return overdamped_velocity(q, jax.tree_util.tree_map(_unwrap, self, is_leaf=is_per_body), torque)


def temperature_of(kT) -> str:
    """``"zero"``, ``"positive"`` (some body's ``kT > 0``) or ``"traced"``: what a ``kT`` (or a
    `jaxrot.per_body` of it) tells of itself here."""
    value = _unwrap(kT)
    if not is_concrete(value):
        return "traced"
    return "positive" if np.any(np.asarray(value, dtype=np.float64) > 0) else "zero"


def _check_values(fluid):
    """Shapes always; values when concrete."""
    for name, body_shape in _BODY_SHAPES.items():
        value = getattr(fluid, name)
        if value is None:
            continue
        declared_dtype(_unwrap(value), name)
        shape = tuple(jnp.shape(_unwrap(value)))
        if shape[len(shape) - len(body_shape) :] != body_shape or len(shape) < len(body_shape):
            raise ValueError(
                f"`{name}` must have shape {body_shape} for one body, or the particle axes in front "
                f"(..., {', '.join(map(str, body_shape))}); got {shape}."
            )
        raw = _concrete_array(value)
        if raw is not None and not np.all(np.isfinite(raw)):
            raise ValueError(f"`{name}` contains NaN or infinite values.")
    friction = _concrete_array(fluid.friction)
    if friction is not None and np.any(friction <= 0):
        raise ValueError(
            f"`friction` must be > 0 about every axis (torque per angular velocity); the smallest is "
            f"{float(np.min(friction)):.3g}. For a body without a fluid, pass fluid=None; a spheroid's "
            "frictions come from jaxrot.Fluid.spheroid."
        )
    gradient = None if fluid.velocity_gradient is None else _concrete_array(fluid.velocity_gradient)
    if gradient is not None:
        trace = np.abs(np.trace(gradient, axis1=-2, axis2=-1))
        size = np.max(np.abs(gradient), axis=(-2, -1))
        if np.any(trace > TRACE_TOL * size):
            worst = float(np.max(trace))
            raise ValueError(
                f"`velocity_gradient` must be traceless (an incompressible flow, ∇·u = 0); its trace is "
                f"{worst:.3g}. Remove the isotropic part: A - trace(A)/3 * I."
            )
    bretherton = _concrete_array(fluid.bretherton)
    if bretherton is not None and np.any(np.abs(bretherton) >= 1):
        raise ValueError(
            "`bretherton` (Jeffery's shape factor) must lie in (-1, 1): (λ² - 1)/(λ² + 1) for a spheroid of "
            f"aspect ratio λ; got {float(bretherton.flat[np.argmax(np.abs(bretherton))]):.6g}."
        )
    kT = _concrete_array(fluid.kT)
    if kT is not None and np.any(kT < 0):
        raise ValueError(f"`kT` (the thermal energy) must be >= 0; got {float(np.min(kT)):.3g}.")


def check_fluid(fluid, batch_shape, dtype):
    """A rollout's ``fluid`` for its ``(N, ...)`` flattened bodies: ``(values, in_axes)``.

    Each field is cast to ``dtype`` and is shared (its one-body shape) or per body (the particle
    axes ``batch_shape`` in front, or a `jaxrot.per_body`), flattened to one axis. Whether ``kT``
    fits the call's scheme and key is decided before, by `jaxrot._integrate._bind`.
    """
    if not isinstance(fluid, Fluid):
        raise ValueError(f"`fluid` must be None or a jaxrot.Fluid; got {type(fluid).__name__}.")
    batch_shape = tuple(batch_shape)
    n = math.prod(batch_shape)
    values, axes = {}, {}
    for name, body_shape in _BODY_SHAPES.items():
        value = getattr(fluid, name)
        if value is None:
            values[name], axes[name] = None, None
            continue
        marked = is_per_body(value)
        value = jnp.asarray(_unwrap(value)).astype(dtype)
        leading = value.shape[: value.ndim - len(body_shape)]
        if leading == () and not marked:
            values[name], axes[name] = value, None
        elif leading == batch_shape and (batch_shape or marked):
            values[name], axes[name] = value.reshape(n, *body_shape), 0
        else:
            raise ValueError(
                f"`fluid.{name}` has shape {value.shape}: give it as {body_shape} for all bodies, or with "
                f"the particle axes {batch_shape} in front for one value per body."
            )
    treedef = jax.tree_util.tree_structure(jax.tree_util.tree_map(_unwrap, fluid, is_leaf=is_per_body))
    present = [name for name in _BODY_SHAPES if values[name] is not None]
    return (
        jax.tree_util.tree_unflatten(treedef, [values[name] for name in present]),
        jax.tree_util.tree_unflatten(treedef, [axes[name] for name in present]),
    )
