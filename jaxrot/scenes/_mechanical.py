"""Scenes of bodies in vacuum: free, under gravity about a pivot, slowed by drag, a free cloud."""

import jax
import jax.numpy as jnp

from .. import quaternion as quat
from .._state import RotState
from ..torques import Gravity, ViscousDrag
from ._scene import Scene, _f


def gravity_torque(t, q, omega, args):
    """``r × F`` for ``args = {"offset_body": r_b, "weight": F}``: `torques.Gravity` as a plain function."""
    return jnp.cross(quat.rotate(q, args["offset_body"]), args["weight"])


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
    """1 kg (weight 9.81 N down the world z) at ``offset`` (m, body frame) from the pivot."""
    return {"gravity": {"offset_body": _f(offset, dtype), "weight": _f([0.0, 0.0, -9.81], dtype)}}


def _checked(scene):
    scene.central_inertia()  # ValueError unless the pivot inertia, mass and offset are a body that can exist
    return scene


def heavy_top(dtype=jnp.float64) -> Scene:
    """Asymmetric heavy top: gravity on a centre of mass offset from a fixed pivot.

    Inertia ``(1.25, 2, 3)`` kg m² about the pivot (its principal axes = body axes), mass 1 kg,
    centre of mass at ``(0.1, 0.05, 0.3)`` m in the body, weight ``(0, 0, −9.81)`` N, spun mostly
    about the body z axis (``ω_b = (0.3, 1, 6)`` rad/s) and tilted by about 0.37 rad. The
    orientation-dependent torque makes the motion nutate and precess chaotically. Energy is conserved.

    Why these numbers: the moments about a pivot exceed the central ones by the parallel-axis term
    ``m(|r|²𝟙 − r rᵀ)``. Until 2026-11 the scene had ``(1, 2, 3)`` about the pivot: a planar body
    (``I₁ + I₂ = I₃``) whose centre of mass lies 0.3 m off its plane, which no body is (central moments
    ``(0.907, 1.900, 2.988)``, ``I₁ + I₂ < I₃``). Raising the smallest moment to 1.25 is the smallest
    round change that makes it physical (from about 1.18 on) while keeping the offset, mass, spin,
    step and horizon: central moments ``(1.157, 1.900, 2.988)`` (``I₁ + I₂ − I₃ = 0.069 = 2m⟨z²⟩``,
    an rms extent of 0.19 m along the largest-moment axis). The scene stays in the pivot tensor's
    principal axes, so its inertia is the diagonal fast path, and the motion about a fixed pivot
    depends on the pivot tensor alone; the central tensor, `Scene.central_inertia`, then has the
    small products ``m r_i r_j`` (≤ 0.03 kg m²): its principal axes are turned by 0.9–1.2° from the
    body axes, as for any body whose centre of mass lies off the pivot tensor's axes. Moving the
    centre of mass onto an axis instead would have made both tensors diagonal but changed the torque
    the scene is about.
    """
    q0 = quat.exp(_f([0.1, 0.2, 0.3], dtype))
    return _checked(
        Scene(
            "heavy_top",
            "asymmetric heavy top, I=(1.25,2,3) about the pivot, gravity on an offset centre of mass",
            RotState(q0, quat.rotate(q0, _f([0.3, 1.0, 6.0], dtype))),
            _f([1.25, 2.0, 3.0], dtype),
            Gravity(),
            _gravity_args([0.1, 0.05, 0.3], dtype),
            dt=0.005,
            t_end=5.0,
            mass=1.0,
        )
    )


def lagrange_top(dtype=jnp.float64) -> Scene:
    """Symmetric heavy (Lagrange) top: a fast spinning top precessing and nutating under gravity.

    Inertia ``(2, 2, 1)`` kg m² about the pivot, mass 1 kg, centre of mass 0.25 m up the
    symmetry axis (central moments ``(1.9375, 1.9375, 1)``: a body that can exist), weight 9.81 N,
    tilted 0.3 rad, spin 25 rad/s about the axis.
    Energy and the angular momentum components about the vertical and about the
    symmetry axis are conserved.
    """
    q0 = quat.from_axis_angle(_f([1.0, 0.0, 0.0], dtype), _f(0.3, dtype))
    return _checked(
        Scene(
            "lagrange_top",
            "symmetric heavy top, I=(2,2,1), spin 25 rad/s, tilted 0.3 rad",
            RotState(q0, quat.rotate(q0, _f([0.0, 0.0, 25.0], dtype))),
            _f([2.0, 2.0, 1.0], dtype),
            Gravity(),
            _gravity_args([0.0, 0.0, 0.25], dtype),
            dt=0.002,
            t_end=3.0,
            mass=1.0,
        )
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
