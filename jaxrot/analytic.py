r"""Exact torque-free rigid-body motion (Euler–Poinsot), for tests and splitting schemes.

`free_top` returns the exact orientation and angular velocity of a torque-free
rigid body with any inertia, at any times, to round-off: the symmetric top in
closed form, the asymmetric top with Jacobi elliptic functions and the
incomplete elliptic integral of the third kind (`jaxrot._free_body._elliptic`).
`free_motion` is the single-body core, in the principal frame, that
`jaxrot.schemes.splitting.Splitting` calls once per step.

Conventions are those of jaxrot: ``q`` scalar first ``[w, x, y, z]``, body →
world; ``omega`` in the world frame (rad per unit time); inertia in the body
frame, principal moments ``(3,)`` or a symmetric tensor ``(3, 3)`` (mass ×
length²). A tensor is diagonalised, ``I = R diag(I₁, I₂, I₃) Rᵀ`` with ``R`` a
proper rotation (``r`` its quaternion, principal → body), and the motion is
solved for the principal-frame orientation ``q ⊗ r``.

Cases (principal moments sorted ``I₁ <= I₂ <= I₃``, ``L_i = I_i ω_i``,
``L² = Σ L_i²``, ``2E = Σ I_i ω_i²``, body-frame ``ω``):

- **steady rotation** — spherical body, ``ω = 0``, or ``ω`` along a principal
  axis (``ω × Iω = 0``, including pure spin about the *intermediate* axis, an
  unstable but exact equilibrium): ``ω`` constant, ``q(t) = exp(ω t) ⊗ q₀``.
- **symmetric top** (``I₁ = I₂`` or ``I₂ = I₃`` exactly; symmetry axis ``a``,
  ``I⊥ = I₂``): ``q(t) = exp(L_w t / I⊥) ⊗ q₀ ⊗ exp(−λ t a)`` with
  ``λ = (I_a − I⊥) (ω·a) / I⊥`` (Landau & Lifshitz §33).
- **asymmetric, case A** ``L² > 2E I₂`` (the angular momentum circulates about
  body axis 3) and **case B** ``L² < 2E I₂`` (about axis 1): case B is solved as
  case A in the principal frame rotated so that its axes are ``(3, 2, −1)``,
  i.e. with the moments reversed. With ``u = ν t + u₀``,
  ``ω₁ = σ₁ A cn(u|m)``, ``ω₂ = ε σ₁ σ₃ B sn(u|m)``, ``ω₃ = σ₃ C dn(u|m)``, and the
  orientation as Euler angles ``R = R_z(φ) R_x(θ) R_z(ψ)`` of body → (frame with
  ``e_z ∥ L``), ``ψ = atan2(L₁, L₂)``, ``θ = atan2(√(L₁² + L₂²), L₃)``,
  ``σ₁ = sign ω₁(0)``, ``σ₃ = sign ω₃``, ``ε = sign(I₃ − I₂)`` (−1 in case B),
  ``φ(t) = |L| t / I₃ + |L| (I₃ − I₁) / (I₁ I₃ ν) [Π(n; am u|m) − Π(n; am u₀|m)]``,
  ``n = −I₃ (I₂ − I₁) / (I₁ (I₃ − I₂)) < 0`` (Landau & Lifshitz §37; the formulas
  of ``notes/peers.md`` §6, checked there against DOP853).
- **separatrix** ``L² = 2E I₂`` exactly (with ``ω₁ ω₃ ≠ 0``, ``I₁ < I₂ < I₃``):
  the ``m → 1`` limit, ``cn = dn = sech``, ``sn = tanh`` and the elementary
  integral ``∫ du / (1 − n tanh² u) = (u + a atan(a tanh u)) / (1 − n)``,
  ``a = √−n``: the body approaches pure spin about the intermediate axis
  asymptotically. In floating point this branch is taken only when
  ``L² − 2E I₂``, computed without cancellation from the body-frame ``ω``, is
  exactly zero. Near it the elliptic formulas are used with ``1 − m`` computed
  without cancellation, as ``(I₃ − I₁)(L² − 2E I₂) / ((I₃ − I₂)(L² − 2E I₁))``,
  and with ``cn u₀`` (not ``am u₀``) taken from the data, so a state close to the
  unstable intermediate axis keeps its small components' relative precision;
  the motion there is exponentially sensitive to the initial state, and the
  result is as accurate as the input's round-off allows.

The returned ``q(t)`` is the continuous path on the unit quaternions that
starts at ``q₀`` (``ψ`` is unwrapped), so it has no ``q → −q`` jumps in time or
between the cases as the inputs vary.

Gradients: every branch is evaluated, with safe stand-in inputs where it cannot
apply, and selected, so values *and* gradients are finite everywhere. They are
the true derivatives (checked against central differences to 1e-6), also where
those of the elliptic formulas are not (near ``ω = 0`` and near steady rotation,
whose amplitude/phase form makes them lose ~eps/ε relative, up to 1e17 x wrong):

- **short flights**, ``θ = max(1, κ) |ω| |t| < 5e-3`` (``κ = max |I_j − I_k| / I_i``,
  ``<= 1`` for a physical body), ``ω = 0`` included: the Taylor series of
  ``ω_b(t)`` and of ``q₀* ⊗ q(t)`` in ``t`` from Euler's equations, to order 8
  (truncation below eps·θ), a polynomial with exact derivatives;
- **symmetric top**: the closed form, written with ``I⊥`` the mean of the two
  equal moments (derivatives in ``q``, ``ω``, ``t`` and the symmetric inertia
  changes), plus the derivative along the inertia change that breaks the symmetry,
  from the motion linearised in it (an 8×8 matrix exponential, evaluated only when
  differentiating); the sphere and steady symmetric rotation included;
- **asymmetric body near steady rotation**, ``|ω⊥| / |ω| <= 1e-8`` (``5e-6`` about
  the intermediate axis), exact steady rotation included: derivatives in ``q``,
  ``ω``, ``t`` of the motion linearised about the steady rotation (a 6×6 matrix
  exponential, only when differentiating; exact at ``ω⊥ = 0``, relative error
  ``O(|ω⊥| / |ω|)``), the value and the inertia derivative from the elliptic formulas.

Not the true derivatives: the exact separatrix. Known limit of the *values*: within
``ε = |ω⊥| / |ω|`` of the intermediate axis the elliptic orientation is off by
~1e-17/ε for t ~ 1 (2e-4 rad at ε = 1e-13), so a finite difference there sees that
noise. Derivatives with respect to a full ``(3, 3)`` tensor go
through ``eigh`` and are not finite when two principal moments are equal; pass
principal moments ``(3,)`` to differentiate a symmetric body's inertia.

References:
    L. D. Landau and E. M. Lifshitz, *Mechanics*, 3rd ed., §§33, 35–37.
    E. Celledoni, F. Fassò, N. Säfström and A. Zanna, "The exact computation of
    the free rigid body motion and its use in splitting methods", SIAM J. Sci.
    Comput. 30(4), 2084–2112 (2008), doi:10.1137/070704393.
"""

import equinox as eqx
import jax
import jax.numpy as jnp

from . import quaternion as quat
from ._free_body._free_motion import free_motion as free_motion
from ._free_body._principal_axes import principal_axes as principal_axes
from ._particles import flatten_particles, unflatten_trajectory
from ._state import RotState, Trajectory
from ._validation import check_bodies, check_times


__all__ = ["free_motion", "free_top", "principal_axes"]


# Up to this many (particle, time) pairs are evaluated one after the other (`lax.map`), which
# compiles about twice as fast as the batched (`vmap`) form; larger batches are vectorised.
_SEQUENTIAL_MAX = 4096


@eqx.filter_jit
def _free_top_flat(q, omega, inertia, per_particle, ts):
    """``(N, 4)``, ``(N, 3)`` states and ``(n,)`` times → ``(n, N, 4)``, ``(n, N, 3)``."""
    moments, r = jax.vmap(principal_axes)(inertia) if per_particle else principal_axes(inertia)
    r = jnp.broadcast_to(r, q.shape)
    moments = jnp.broadcast_to(moments, omega.shape)
    q_p = quat.multiply(q, r)
    elapsed = ts - ts[0]
    n_particles, n_times = q.shape[0], ts.shape[0]
    if n_particles * n_times <= _SEQUENTIAL_MAX:

        def repeat(x):
            return jnp.repeat(x, n_times, axis=0)

        pairs = (repeat(q_p), repeat(omega), repeat(moments), jnp.tile(elapsed, n_particles))
        q_t, omega_t = jax.lax.map(lambda args: free_motion(*args), pairs)
        q_t = q_t.reshape(n_particles, n_times, 4)
        omega_t = omega_t.reshape(n_particles, n_times, 3)
    else:
        at_times = jax.vmap(free_motion, in_axes=(None, None, None, 0))
        q_t, omega_t = jax.vmap(at_times, in_axes=(0, 0, 0, None))(q_p, omega, moments, elapsed)
    q_t = quat.multiply(q_t, quat.conjugate(r)[:, None, :])
    return jnp.swapaxes(q_t, 0, 1), jnp.swapaxes(omega_t, 0, 1)


def free_top(state: RotState, inertia, ts, *, normalize: bool = False) -> Trajectory:
    """Exact motion of torque-free rigid bodies at the times ``ts``.

    The state is given at ``ts[0]``, as in `jaxrot.reference_rollout`; since the
    solution is exact, ``ts`` may be in any order and steps of any size.

    Args:
        state: `jaxrot.RotState` with ``q`` ``(..., 4)`` (unit, scalar first, body
            → world) and world-frame ``omega`` ``(..., 3)`` (rad per unit time).
            Leading axes are particles.
        inertia: body-frame inertia (mass × length²): principal moments ``(3,)``
            or a symmetric tensor ``(3, 3)``, shared, or one per particle with the
            particle axes in front (as in `jaxrot.rollout`).
        ts: 1-D array of times ``(n,)``.
        normalize: normalise ``state.q`` instead of rejecting a non-unit one.

    Returns:
        `jaxrot.Trajectory` with ``t = ts`` ``(n,)``, ``q`` ``(n, ..., 4)`` and
        ``omega`` ``(n, ..., 3)``, in the dtype of ``state``.

    Raises:
        ValueError: wrong shapes, non-finite values, a non-unit ``q``, a
            non-physical inertia (checked as in `jaxrot.rollout`), or ``ts`` not
            a finite 1-D array of at least one time.

    Example:
        >>> import jax.numpy as jnp, jaxrot
        >>> from jaxrot import analytic, diagnostics
        >>> inertia = jnp.array([1.0, 2.0, 3.0])
        >>> state = jaxrot.RotState(jnp.array([1.0, 0, 0, 0]), jnp.array([0.3, 1.0, 0.2]))
        >>> traj = analytic.free_top(state, inertia, jnp.linspace(0.0, 10.0, 5))
        >>> traj.q.shape, traj.omega.shape
        ((5, 4), (5, 3))
        >>> print(traj.omega[-1].round(3).tolist())
        [0.352, 1.004, 0.162]
        >>> energy = diagnostics.kinetic_energy(traj.q, traj.omega, inertia)
        >>> print(bool(jnp.allclose(energy, energy[0], rtol=1e-5)))
        True
    """
    state, inertia, per_particle = check_bodies(state, inertia, normalize=normalize)
    ts = check_times(ts, state.q.dtype, ordered=False)
    flat, inertia = flatten_particles(state, inertia, per_particle)
    q_t, omega_t = _free_top_flat(flat.q, flat.omega, inertia, per_particle, ts)
    return unflatten_trajectory(Trajectory(ts, q_t, omega_t), state.q.shape[:-1])
