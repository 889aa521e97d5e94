r"""A fast free rotor: the torque-free rigid body by the preprocessed discrete Moser–Veselov method.

`free_rotor` has the contract of `jaxrot.analytic.free_motion` (the exact solution by elliptic
functions), at about 1.2× the cost of one torque-free `"zhao"` step in float64 (3× in float32)
instead of ~120× (N = 10⁴ bodies, 2 CPU cores, XLA's YNN fusions off, `benchmarks/rotor.py`), for
splitting schemes that call a rotor many times per step.

Method (Hairer & Vilmart 2006). One step of length ``h`` of the discrete Moser–Veselov (DMV)
algorithm, written with the body-frame angular momentum ``m`` and the quaternion, is
``q ← q ⊗ (1, c)/√(1 + |c|²)``, ``m ← m + (h / (1 + |c|²)) (Ĩ₂ − Ĩ₃, Ĩ₃ − Ĩ₁, Ĩ₁ − Ĩ₂) ⊙ (b₂b₃, b₁b₃, b₁b₂)``
with ``c = (h/2) b`` the solution of the implicit equations

    b_i = (1 + |c|²) m_i / Ĩ_i + (h/2) ((Ĩ_j − Ĩ_k) / Ĩ_i) b_j b_k      (i, j, k cyclic).

It maps ``m`` by the rotation ``(1, c)*``, so the world angular momentum ``q m q*`` is conserved
exactly, and it conserves ``|m|`` and ``Σ m_i² / Ĩ_i``. Hairer and Vilmart replace the moments by
the modified moments ``1/Ĩ_j = (1/I_j) S(x, y) + D(x, y)``, where ``S = 1 + …`` and ``D`` are
polynomials in ``x = h²|m|²/2`` and ``y = h² E`` (``E = Σ m_j²/(2 I_j)`` the kinetic energy) whose
coefficients are rational functions of ``I₁, I₂, I₃``; with the terms to degree 4 (their DMV10)
the step approximates the exact flow to order 10, in ``m`` and in the orientation. ``S`` and ``D``
depend on conserved quantities only, so ``Ĩ`` is fixed during a step, and since ``S ≠ 0`` the
exact energy ``E`` is conserved too.

Here the time ``t`` is covered by ``n = ⌈|ω| |t| / a⌉`` equal DMV10 steps, chosen per body
(`substeps_for`: ``a = 0.2`` rad in float64, 0.5 in float32, at least 2, at most 64): local
error ``O(a¹¹)`` per step, so round-off at any ``|ω| |t|`` up to 10 rad. The steps use the
scaling symmetry of the flow and of the DMV map (both functions of ``h m``): ``n`` steps of
``t/n`` with the momentum ``m`` are computed as ``n`` steps of ``t/2`` with ``(2/n) m``, so the
step length stays one scalar. The steps run in one while loop (traced for a GPU, the first two in a
static loop before it), which a body in the common range leaves after two iterations (under
`jax.vmap`, one loop over the batch with a scalar counter, by a batching rule of our own), whose
derivative rule carries the steps' Jacobian (JAX cannot reverse-differentiate a while loop):
`jaxrot._free_body._rotor_loop`. Traced for a GPU, the loop takes 4 steps per iteration and each
body's count past the first two is rounded up to a multiple of 4 (`_rotor_loop.LOOP_BATCH`): there
every iteration waits on a host read of its condition. The map itself is `jaxrot._free_body._dmv`.
Measured against `free_motion`
(largest orientation error in rad, or ω error relative to ``|ω|``; float64; bodies ``(1, 2,
3)``, ``(2, 2, 2)``, ``(1, 1, 1.9)``, ``(0.1, 1, 1.05)``)::

    |ω| |t|                    0.01    0.3     1       3       10
    (1, 2, 3)                  6e-16   8e-16   2e-14   6e-14   2e-13
    sphere (2, 2, 2)           2e-16   3e-16   1e-15   3e-15   1e-14
    (1, 1, 1.9)                3e-16   2e-16   3e-15   7e-15   2e-14
    flat (0.1, 1, 1.05)        1e-15   8e-16   5e-14   1e-13   4e-13

With a fixed count (``substeps=2``, the default before) the error was 7e-13 at 0.5, 1e-9 at
1, 3e-6 at 1.9 and NaN from 2. The choice costs 3-6% per call in the common range
(|ω| t = 0.3, N = 10⁴, 2 CPU cores, float64 and float32, the rotor and the ``"splitting"`` step,
median of 31 interleaved rounds: `benchmarks/rotor.py`, the closing note of issue 32 has the
table); with JAX's own batching of the while loop it cost 10-14%.

Scale. The moments are divided by a power of two near their largest (exact, and the flow of
``ω`` depends on their ratios only): a body of any size, ``I ~ 1e-12`` as ``1e6``, runs on moments of
order 1 (measured: without it float32 overflowed from ``I ~ 1e-4``, float64 from ``I ~ 1e-25``).

Limits, where the result is NaN rather than wrong: one DMV step may turn by at most 1 rad
(near π/2 the DMV equation has no solution any more: ``|ω| |t| > 64`` by default, ``> n`` with
a fixed ``substeps``), and the rounding error of the modified moments, whose polynomial's terms cancel
for a needle (``I₁ ≪ I₂ ≈ I₃``), estimated from the terms' sizes, must stay below 1e-12 or 100 ulp,
whichever is more (measured with ``n = 2``, float64: ``I = (1e-2, 1, 1)`` valid to ``|ω| t = 1.5``;
``(1e-3, 1, 1)`` exact to 1e-13 up to 0.3, 7e-13 at 0.5 and NaN from 0.7; ``(1e-4, 1, 1)`` NaN from
0.3, ``(1e-6, 1, 1)`` from 0.05; float32: ``(1e-3, 1, 1)`` NaN from 0.4). A stable form of the
modified moments for needles (the coefficients rewritten without the cancellation) would lift
this limit.

Round-off. ``q`` and ``ω`` are converted between frames with ``q`` normalised and its residual
``δ = |q|² − 1`` (computed without the rounding at 1) taken out to first order, so a conversion
has no bias from how ``q`` was normalised (measured: the usual normalise-then-rotate biases the
float32 energy by ~0.3 ulp per call, which over 10⁴ calls drifted ``|L|`` by 1e-3). The output
``ω`` is then corrected, by a few ulp, so that the invariants ``|L|`` and ``E`` measured from it
equal those measured from the input: what is left is an unbiased random walk (measured over 10⁴
calls of ``|ω| t = 0.05``, 64 bodies, with the principal-frame round trip of a splitting between
calls: float32 max 5e-5 in ``|L|``, 1e-4 in ``E``, against 1e-3 and 2e-3 for `free_motion`;
float64 1.6e-13 and 3e-13, against 3e-12 and 6e-12).

Derivatives are those of the DMV map: the Newton iterations run on stop-gradient copies and
only the last Newton step is differentiated, which gives the implicit-function derivative of
the converged solution; the round-off correction has no derivative. They are finite at
``ω = 0``, ``t = 0``, for symmetric bodies and the sphere (no branch anywhere), and agree with
central differences and with `free_motion`'s derivatives.

Reference:
    E. Hairer and G. Vilmart, "Preprocessed discrete Moser–Veselov algorithm for the full
    dynamics of a rigid body", J. Phys. A: Math. Gen. 39, 13225–13235 (2006),
    doi:10.1088/0305-4470/39/42/003.
"""

import functools

import jax
import jax.numpy as jnp
from jax import lax

from .._core._fusion import stage, stage_stacked
from ._dmv import (
    _MAX_ROUNDING,
    _MAX_ROUNDING_ULP,
    _dmv_step,
    _invariants,
    _modification,
    _round_off_correction,
    _turn,
    _unit_residual,
)
from ._rotor_loop import _MIN_SUBSTEPS, _dmv_steps, _loop_batch, _per_body, _split


__all__ = ["free_rotor", "free_rotor_momentum"]

# DMV10 steps per call. By default each body takes its own number, n = ceil(|ω| |t| / a) with the
# largest angle per DMV step a below, at least 2 (_MIN_SUBSTEPS) and at most _MAX_SUBSTEPS. Two is
# the least: the common range |ω| t <= 0.3 (float64) then costs what a fixed two did; the first two
# steps are computed whatever the count, the rest only where a body needs them.
_MAX_SUBSTEPS = 64
# Largest angle of one DMV step chosen by the rule, per dtype: the local error grows like a¹¹, so
# 0.2 keeps float64 within ~1e-13 of the exact flow at any |ω| t (measured: 2 steps at 0.5 rad
# gave 7e-13, 3 at 0.6 gave 1e-13), and 0.5 keeps float32 ~100× below its resolution (1e-9 for
# two steps of 0.5 rad, in float64 arithmetic). Both leave |ω| t <= 0.3 on two steps.
_STEP_ANGLE = {8: 0.2, 4: 0.5}
# Largest angle |ω| |t| / n of one DMV step: near π/2 the DMV equation has no solution any more.
# Reached only past _MAX_SUBSTEPS steps (|ω| t > 64) or with a fixed `substeps`.
_MAX_ANGLE = 1.0
_SCAN = True


def substeps_for(angle, dtype):
    """DMV10 steps the rotor takes for a flow of ``angle = |ω| |t|`` rad (per body) in ``dtype``."""
    per_step = _STEP_ANGLE[jnp.dtype(dtype).itemsize]
    n = jnp.ceil(angle / per_step)
    return jnp.clip(jnp.where(jnp.isfinite(n), n, _MAX_SUBSTEPS), _MIN_SUBSTEPS, _MAX_SUBSTEPS).astype(
        jnp.int32
    )


def _unit_scale(moments):
    """A power of two ``c`` per body with ``max_k I_k / c`` in ``[1/2, 1)``: the flow of ``ω`` is the same
    for the moments ``I/c`` (it depends on their ratios only), and dividing by a power of two is exact,
    so the rotor runs on moments of order 1 whatever the body's scale. Without it the modified moments'
    coefficients, of degree up to 12 in ``1/I`` (``det⁴``), overflow in float32 from ``I ~ 1e-4``."""
    _, exponent = jnp.frexp(lax.stop_gradient(jnp.max(moments, axis=-1)))
    return lax.stop_gradient(jnp.ldexp(jnp.ones_like(moments[..., 0]), exponent))


def _dmv_flow(q, m, inertia, inverse, targets, total_angle, t, substeps, dtype):
    """The DMV10 flow over ``t`` of one body's unit ``q`` (4 components, principal → world) and body
    momentum ``m`` (3): ``(q, m, valid, targets)``, ``q`` normalised, ``targets`` (``(|m|², 2E)``)
    behind the flow's first stage barrier; ``valid`` False where the result must be NaN."""
    if substeps is None:
        # n steps of t/n for the momentum m are 2 steps' worth of t/2 for the momentum (2/n) m, then
        # scaled back: the flow, and the DMV map (a function of h m), are invariant under h → h/k,
        # m → k m. So h stays a scalar and only m and its invariants are scaled, per body.
        count = substeps_for(total_angle, dtype)
        k = _loop_batch()
        if k > 1:  # the while loop's steps a multiple of the steps per iteration (never fewer)
            count = _MIN_SUBSTEPS + (count - _MIN_SUBSTEPS + k - 1) // k * k
        n_ref = _MIN_SUBSTEPS
        scale = n_ref / count.astype(dtype)
        m = tuple(mi * scale for mi in m)
        sizes = (targets[0] * scale * scale, targets[1] * scale * scale)
    else:
        count, n_ref, sizes = substeps, substeps, targets
    h = t / n_ref
    g = 0.5 * h
    g2 = g * g
    angle = total_angle / jnp.asarray(count).astype(dtype)  # of one DMV step
    # Stage boundaries (`jaxrot._core._fusion`): without them XLA recomputes the earlier stages inside
    # every later one (measured 8x slower), and in the derivative programs too.
    staged = stage(*q, *m, *targets, *sizes, angle)
    q, m, targets, sizes, angle = staged[:4], staged[4:7], staged[7:9], staged[9:11], staged[11]
    valid = angle <= _MAX_ANGLE

    scale_s, shift_d, size_s, size_d = _modification(
        inertia, (0.5 * h * h) * sizes[0], (0.5 * h * h) * sizes[1]
    )
    # One loop for the four sums (XLA:CPU otherwise recomputed them in each of six consumers).
    scale_s, shift_d, size_s, size_d = stage_stacked(scale_s, shift_d, size_s, size_d)
    p = tuple(scale_s * v + shift_d for v in inverse)  # modified inverse moments 1/Ĩ
    # The terms of S and D can be far larger than their sums: for a needle (I₁ ≪ I₂ ≈ I₃) they grow
    # like (h²|m|²/I₁²…)^k and cancel to O(1), so 1/Ĩ_j keeps only ~eps · cond of relative accuracy,
    # and the result ~eps · cond · angle. Beyond the bound the result is NaN, not noise.
    eps = float(jnp.finfo(dtype).eps)
    max_cond = max(_MAX_ROUNDING_ULP, _MAX_ROUNDING / eps)
    for pj, v in zip(p, inverse, strict=True):
        cond = (size_s * v + size_d) / jnp.abs(pj)
        valid = valid & (cond * angle <= max_cond)
    e1, e2, e3 = (1 / pi for pi in p)
    fad = (e2 - e3, e3 - e1, e1 - e2)
    f = tuple(g * fi * pi for fi, pi in zip(fad, p, strict=True))
    staged = stage(*p, *fad, *f)
    p, fad, f = staged[:3], staged[3:6], staged[6:]

    def substep(_, carry):
        q, m = _dmv_step(_split(carry[0]), _split(carry[1]), p, fad, f, g, g2, h)
        return jnp.stack(q, axis=-1), jnp.stack(m, axis=-1)

    # The loop carries q and m as (…, 4) and (…, 3) arrays: XLA:CPU then updates each in one loop,
    # where seven separate arrays took seven loops and seven copies per substep (measured: the
    # "splitting" step 10% faster, float64, N = 10⁴).
    if substeps is None:
        batch = jnp.broadcast_shapes(count.shape, jnp.shape(h))
        q, m = _per_body(_dmv_steps, batch, q, m, p, fad, h, count)
    else:
        carry = (jnp.stack(q, axis=-1), jnp.stack(m, axis=-1))
        if _SCAN:
            carry = lax.fori_loop(0, substeps, substep, carry)
        else:
            for i in range(substeps):
                carry = substep(i, carry)
        q, m = _split(carry[0]), _split(carry[1])
    if substeps is None:
        m = tuple(mi / scale for mi in m)

    norm = lax.rsqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return tuple(c * norm for c in q), m, valid, targets


# Jitted so that an eager call compiles once, not primitive by primitive (inlined under an outer jit).
@functools.partial(jax.jit, static_argnames="substeps")
def free_rotor(q_principal, omega, moments, t, *, substeps=None):
    """Torque-free motion of one body over a time ``t``, in its principal frame: DMV10, near-exact.

    The contract of `jaxrot.analytic.free_motion`, at a fraction of its cost (see the module
    docstring for the method, the measured error and the limits).

    Args:
        q_principal: ``(4,)`` unit quaternion, scalar first, principal frame → world
            (renormalised on the way in).
        omega: ``(3,)`` world-frame angular velocity (rad per unit time).
        moments: ``(3,)`` principal moments of inertia (mass × length²), ascending as
            `jaxrot.analytic.principal_axes` returns them (any order works here).
        t: scalar time elapsed, any sign (``t = 0`` returns the input, renormalised).
        substeps: DMV10 steps covering ``t`` (a Python int), or None (default): each body
            takes ``ceil(|ω| |t| / a)`` steps, at least 2 and at most 64, with ``a = 0.2`` rad
            in float64 and 0.5 in float32 (`substeps_for`; traced for a GPU, the steps past
            the first two rounded up to a multiple of 4, `LOOP_BATCH`). A fixed count is valid while
            ``|ω| |t| / substeps <= 1``; beyond, the result is NaN.

    Returns:
        ``(q_principal(t), omega(t))``, shapes ``(4,)`` and ``(3,)``, in the dtype of
        ``q_principal``. Leading axes of the arguments broadcast, as under `jax.vmap`.

    Example:
        >>> import jax.numpy as jnp
        >>> from jaxrot import quaternion as quat
        >>> from jaxrot._free_body._rotor import free_rotor
        >>> q0, w0 = jnp.array([1.0, 0.0, 0.0, 0.0]), jnp.array([0.3, 1.0, 0.2])
        >>> moments = jnp.array([1.0, 2.0, 3.0])
        >>> q1, w1 = free_rotor(q0, w0, moments, 0.4)  # exact: ω(0.4) = (0.221306, 1.017589, 0.180718)
        >>> print(q1.shape, w1.shape, ", ".join(f"{x:.6f}" for x in w1))
        (4,) (3,) 0.221306, 1.017589, 0.180718
        >>> energy = lambda q, w: jnp.sum(moments * quat.rotate(quat.conjugate(q), w) ** 2)
        >>> print(bool(jnp.abs(energy(q1, w1) / energy(q0, w0) - 1) < 1e-6))
        True
        >>> q2, w2 = free_rotor(q0, jnp.array([300.0, -230.0, 80.0]), jnp.ones(3), 0.03)  # 11.6 rad
        >>> print(bool(jnp.all(jnp.isfinite(q2))))
        True
    """
    dtype = jnp.asarray(q_principal).dtype
    if substeps is not None and (not isinstance(substeps, int) or substeps < 1):
        raise ValueError(f"`substeps` must be None or a Python int >= 1; got {substeps!r}.")
    q_principal = jnp.asarray(q_principal, dtype)
    omega = jnp.asarray(omega).astype(dtype)
    moments = jnp.asarray(moments).astype(dtype)
    moments = moments / _unit_scale(moments)[..., None]  # ω's flow is invariant: exact, in range
    t = jnp.asarray(t).astype(dtype)
    fixed = lax.stop_gradient

    inertia = tuple(moments[..., k] for k in range(3))
    inverse = tuple(1 / i for i in inertia)
    q = tuple(q_principal[..., k] for k in range(4))
    norm = lax.rsqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    q = tuple(c * norm for c in q)
    w_body = _turn(q, _unit_residual(q), tuple(omega[..., k] for k in range(3)), inverse=True)
    targets = _invariants(w_body, inertia)
    m = tuple(i * w for i, w in zip(inertia, w_body, strict=True))
    # |ω| from the world frame (a rotation keeps it): from w_body, XLA:CPU recomputed the rotation
    # in one more pass over the bodies, for the step count alone.
    w_world = tuple(omega[..., k] for k in range(3))
    total_angle = fixed(jnp.abs(t) * jnp.sqrt(w_world[0] ** 2 + w_world[1] ** 2 + w_world[2] ** 2))
    q, m, valid, targets = _dmv_flow(q, m, inertia, inverse, targets, total_angle, t, substeps, dtype)
    residual = _unit_residual(q)
    omega_t = _turn(q, residual, tuple(mi * vi for mi, vi in zip(m, inverse, strict=True)))
    staged = stage(*q, residual, *omega_t)
    q, residual, omega_t = staged[:4], staged[4], staged[5:]
    correction = _round_off_correction(q, residual, omega_t, inertia, targets)
    omega_t = tuple(o + fixed(c) for o, c in zip(omega_t, correction, strict=True))

    nan = jnp.asarray(jnp.nan, dtype)
    q_out = jnp.where(valid[..., None], jnp.stack(q, axis=-1), nan)
    omega_out = jnp.where(valid[..., None], jnp.stack(omega_t, axis=-1), nan)
    return q_out, omega_out


@functools.partial(jax.jit, static_argnames="substeps")
def free_rotor_momentum(q_principal, momentum, moments, t, *, substeps=None):
    """`free_rotor` on the principal-frame angular momentum ``m = I ω_p`` instead of the world ``ω``.

    No frame conversion: the flow of ``(q, m)`` itself, so a scheme that carries ``m`` between
    calls adds no conversion round-off to it (`free_rotor` turns ``ω`` into the body frame and back
    in each call, each a rounding of ``|ω|`` relative size: in float32 a random walk of the
    world angular momentum that tilts the precession axis). Round-off left: that of the DMV steps,
    whose momentum update is of size ``|ω| t |m|``, and of ``q``, which only rotates the whole
    state rigidly (a symmetry of the free motion: it does not grow).

    Args:
        q_principal: ``(4,)`` unit quaternion, principal frame → world (renormalised on the way in).
        momentum: ``(3,)`` angular momentum in the principal frame (``I ω_p``).
        moments, t, substeps: as for `free_rotor`.

    Returns:
        ``(q_principal(t), momentum(t))``, shapes ``(4,)`` and ``(3,)``; NaN where `free_rotor`'s
        would be.

    Example:
        >>> import jax.numpy as jnp
        >>> from jaxrot import quaternion as quat
        >>> from jaxrot._free_body._rotor import free_rotor, free_rotor_momentum
        >>> q0, w0 = jnp.array([1.0, 0, 0, 0]), jnp.array([0.3, 1.0, 0.2])  # q0 = 1: body = world
        >>> moments = jnp.array([1.0, 2.0, 3.0])
        >>> q1, m1 = free_rotor_momentum(q0, moments * w0, moments, 0.4)
        >>> q2, w2 = free_rotor(q0, w0, moments, 0.4)
        >>> w2_body = quat.rotate(quat.conjugate(q2), w2)
        >>> print(bool(jnp.allclose(q1, q2)), bool(jnp.allclose(m1 / moments, w2_body)))
        True True
    """
    dtype = jnp.asarray(q_principal).dtype
    if substeps is not None and (not isinstance(substeps, int) or substeps < 1):
        raise ValueError(f"`substeps` must be None or a Python int >= 1; got {substeps!r}.")
    moments = jnp.asarray(moments).astype(dtype)
    scale = _unit_scale(moments)[..., None]  # (I/c, m/c) has the flow of (I, m), scaled by c: exact
    moments = moments / scale
    momentum = jnp.asarray(momentum).astype(dtype) / scale
    t = jnp.asarray(t).astype(dtype)
    inertia = tuple(moments[..., k] for k in range(3))
    inverse = tuple(1 / i for i in inertia)
    q = tuple(jnp.asarray(q_principal, dtype)[..., k] for k in range(4))
    norm = lax.rsqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    q = tuple(c * norm for c in q)
    m = tuple(momentum[..., k] for k in range(3))
    w = tuple(mi * v for mi, v in zip(m, inverse, strict=True))
    targets = (m[0] * m[0] + m[1] * m[1] + m[2] * m[2], m[0] * w[0] + m[1] * w[1] + m[2] * w[2])
    total_angle = lax.stop_gradient(jnp.abs(t) * jnp.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]))
    q, m, valid, _ = _dmv_flow(q, m, inertia, inverse, targets, total_angle, t, substeps, dtype)
    nan = jnp.asarray(jnp.nan, dtype)
    return (
        jnp.where(valid[..., None], jnp.stack(q, axis=-1), nan),
        jnp.where(valid[..., None], jnp.stack(m, axis=-1) * scale, nan),
    )
