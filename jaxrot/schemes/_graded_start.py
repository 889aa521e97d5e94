"""The exponential schemes' graded start: a run that begins in a boundary layer, without an error floor.

The start of a run: a body started off the slow manifold (at rest in a shear or a field, say)
relaxes within ``I/ζ``, and while it does ``N`` varies on that time scale, not on the step's: the
stiff orders assume a smooth ``N`` and fail there (measured on a dipole in a rotating field at
``ζ/I = 1000`` started at rest: the error fell at order 1.2–1.5 over ``hL`` from 60 to 8). So a run
that starts in such a layer takes its first steps in substeps of a graded mesh. Model: the layer's
part of ``N`` is ``B e^{−Lτ}``; a substep ``s`` at ``τ`` into it errs by ``∝ B s (sL)⁴ e^{−Lτ}``
(``sL ≲ 3``; by ``∝ B s e^{−Lτ}`` beyond, measured: linear in ``h`` at ``hL`` 400–3000). The mesh
with the fewest substeps for a given sum of these is geometric, ``s(τ) = s₀ e^{Lτ/5}``, and sums
to ``≈ 5 (L s₀)⁴ B/L²``. So the substeps are ``s₀ e^{L_min (t − t₀)/5}`` (capped at the step), from

    s₀ = min(h/3, 1/(16 L_max)):

while ``hL_max < 3/16`` the mesh is a fixed fraction of the step and the layer's error a fixed
fraction (≈ 5/3⁴) of the plain start's, which is ``O(h⁴)``: no floor as ``h → 0`` (the earlier
mesh, ``1/(16 L) + 0.15 (t − t₀)``, did not shrink with ``h``: its error stopped falling where the
plain start's caught up with it, local order 1.3 at ``ζ/I = 10``). Above, ``s₀ = 1/(16 L_max)`` and
the layer's error is ``≈ 5 · 16⁻⁴`` of its unresolved size ``B/L²``, which falls as ``1/L²`` and
is below the smooth steps' error on the probes (`tests/test_fluid_start.py`: slopes 3.9–4.2 over a
16-fold range of ``h`` at ``ζ/I`` 10, 1e3, 1e5, from rest, spinning and on the manifold; spinning
at ``ζ/I = 10`` the fixed part shows: slope 3.56). The start runs while ``s₀ e^{L_min (t − t₀)/5}
< h`` (and ``e^{−L_min (t − t₀)}`` above 2e-16): about ``80 L_max/L_min`` substeps when
``hL ≫ 1``, whatever ``hL``; ``(15 − 5 ln 3)/(h L_min) ≈ 9.5/(h L_min)`` steps' worth more than
plain steps when ``hL ≪ 1`` (24 % of a run of ``ζ/I = 10`` over ``t = 4``; 0.2 % at 1e3).

Whether to start is decided once, at `init`, per batch (`eqxi.unvmap_any`: one schedule for a
vmapped batch, not a select that computes both): on the slow manifold ``v = N/L − Ṅ/L² + …``, so a
body on it has ``|v − N/L| ≈ |Ṅ|/L² = (|Ṅ|/(L|N|)) |N/L|``, small where the problem is stiff,
while one at rest, spinning, or at ``u = S`` (`jaxrot.Fluid.angular_velocity`'s velocity) is off
by at least ``|N/L|``. The start runs iff some body has ``|v − N/L|_∞ > ½ |N/L|_∞`` (+ round-off):
measured on the probe, ``|v − N/L| / |N/L|`` is 0.008 on the manifold at ``ζ/I = 1e3``, 0.08 at
100 and 0.8 at 10 (where ``N`` turns at ``ζ/I``'s own rate and no manifold is separated: there
the start runs, 40–80 substeps), and ≥ 1 off it. An earlier threshold at round-off fired wrongly
both ways; this one is relative to what a body on the manifold must show. Decided at every step
instead, the start stopped once the layer fell below ``½ |N/L|`` and left that rest to plain steps
(a floor, 7.5e-10 rad spinning at ``ζ/I = 1e3``, 400 steps). ``graded_start=False`` turns it off.
"""

import equinox.internal as eqxi
import jax
import jax.numpy as jnp

from .. import quaternion as quat


# The graded start (this module): the first substep min(r h, σ / L_max), each next one e^{L_min s / 5}
# times the last (a geometric mesh over the layer, in proportion to the step while hL < σ / r); on while
# the layer's deviation from the manifold exceeds κ times the manifold's own offset N/L.
_STEP_FRACTION = 1 / 3  # r
_LAYER_RESOLUTION = 1 / 16  # σ
_GROWTH_EXPONENT = 1 / 5  # the cost-optimal grading for a local error ∝ s⁵ e^{−L t}
_LAYER_TOLERANCE = 0.5  # κ
_MAX_SUBSTEPS = 1024
_SLOW_FRACTION = 1.0  # c
_LAYER_DECAYED = 36.0  # e^-36 = 2e-16


def _rates(rate):
    """``(L_min, L_max)`` of one body."""
    # The schedule is a discretisation, like dt: not differentiated.
    rate = jax.lax.stop_gradient(rate)
    return jnp.min(rate), jnp.max(rate)


def _first_substep(carry, dt, rate_min, rate_max):
    """``h min(r, c ω/L_max)``: in proportion to the step at every ``L`` (no kink in ``h``); ``ω``
    the slow motion's rate, ``|S| + |N|^{1/2}``. Floored where the geometric mesh,
    ``5 L_max/(L_min L_max s₀)`` substeps, would not fit the loop's cap (with room for its tail)."""
    omega = jnp.linalg.norm(carry.slow) + jnp.sqrt(jnp.linalg.norm(carry.forcing))
    floor = (1 / _GROWTH_EXPONENT) * (rate_max / rate_min) / (_MAX_SUBSTEPS - 64)
    fraction = jnp.maximum(_SLOW_FRACTION * omega / rate_max, floor / (dt * rate_max))
    return dt * jnp.minimum(_STEP_FRACTION, fraction)


def off_manifold(carry, rate):
    """``|v − N/L|_∞ > κ |N/L|_∞`` (plus round-off) for one body's `FluidCarry`: in a boundary layer."""
    (q, omega), slow, forcing, _ = carry
    manifold = forcing / rate
    layer = quat.rotate(quat.conjugate(q), omega) - slow - manifold
    eps = jnp.finfo(q.dtype).eps
    noise = 64 * eps * (jnp.abs(slow).max() + jnp.abs(omega).max())
    return jnp.abs(layer).max() > _LAYER_TOLERANCE * jnp.abs(manifold).max() + noise


def _graded(carry, t, t0, dt, rate):
    """Whether one body's step at ``t`` is graded: it began off its manifold (``carry.layer``) and its
    schedule has not reached ``dt``."""
    rate_min, rate_max = _rates(rate)
    dtype = carry.state.q.dtype
    dt = jnp.asarray(dt, dtype)
    elapsed = jnp.asarray(t - t0, dtype)
    substep = _first_substep(carry, dt, rate_min, rate_max) * jnp.exp(_GROWTH_EXPONENT * rate_min * elapsed)
    return carry.layer & (substep < dt) & (elapsed * rate_min < _LAYER_DECAYED)


def starting(carry, t, t0, dt, rate):
    """Whether some body of the batch takes a graded step at ``t`` (`eqxi.unvmap_any`: one branch of
    `jaxrot.schemes._base.advance`'s cond for a vmapped batch, not a select that computes both)."""
    return eqxi.unvmap_any(_graded(carry, t, t0, dt, rate))


def graded_step(step, carry, t, dt, t0, rate):
    """The step from ``t`` to ``t + dt`` as ``step(carry, t, size)`` over one body's substeps (one
    substep, the step, for a body whose own schedule is done: its result is its run alone's)."""
    rate_min, rate_max = _rates(rate)
    dt = jnp.asarray(dt, carry.state.q.dtype)
    first = jnp.where(_graded(carry, t, t0, dt, rate), _first_substep(carry, dt, rate_min, rate_max), dt)

    def unfinished(loop):
        done, _, _, _ = loop
        return ~done

    def substep(loop):
        _, count, offset, carry = loop
        elapsed = (t - t0) + offset
        size = first * jnp.exp(_GROWTH_EXPONENT * rate_min * elapsed)
        # Once e^{-L_min (t - t0)} is below float64's resolution, nothing is left to resolve; the
        # loop's last substep takes what is left of the step.
        decayed = elapsed * rate_min >= _LAYER_DECAYED
        last = (size >= dt - offset) | decayed | (count == _MAX_SUBSTEPS - 1)
        size = jnp.where(last, dt - offset, size)
        return last, count + 1, offset + size, step(carry, t + offset, size)

    start = (jnp.zeros((), bool), jnp.zeros((), jnp.int32), jnp.zeros_like(dt), carry)
    return eqxi.while_loop(unfinished, substep, start, max_steps=_MAX_SUBSTEPS, kind="bounded")[3]
