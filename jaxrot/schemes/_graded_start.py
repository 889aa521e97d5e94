"""The exponential schemes' graded start: a run that begins in a boundary layer, without an error floor.

A body started off its slow manifold (at rest in a shear or a field, spinning, or at the slow
velocity ``S``) relaxes within ``1/L`` (``L = ζ/I``), and while it does the forcing ``N`` of
`jaxrot.schemes._exponential`'s equation (1) varies on that time scale, not the step's: the stiff
orders assume a smooth ``N`` and fail there (a dipole in a rotating field at ``ζ/I = 1000`` from rest:
order 1.2–1.5 over ``hL`` from 60 to 8). So a run that starts in a layer takes its first steps in
substeps.

The mesh. Model: the layer's part of ``N`` is ``B e^{−Lτ}``; a substep ``s`` at ``τ`` into it errs
by ``∝ B s (sL)⁴ e^{−Lτ}`` for ``sL ≲ 3`` (by ``∝ B s e^{−Lτ}`` beyond: the plain start's error
measured linear in ``h`` at ``hL`` 400–3000). The mesh with the fewest substeps for a given sum is
geometric, ``s(τ) = s₀ e^{Lτ/5}``, that sum is ``≈ 5 (L s₀)⁴ B/L²`` and the count ``≈ 5/(L s₀)``.
For the start's error to fall at order 4 as ``h`` falls at a fixed ``L`` the whole mesh must scale
with ``h`` (``L s₀ ∝ h``; a fixed least growth ratio, or a fixed ``s₀``, leaves a floor
``∝ B/L²``), and its constant need only keep the layer's error below the smooth steps' own,
``∝ (ωh)⁴`` with ``ω = |S| + |N|^{1/2}`` (the slow motion's rate). ``B/L²`` is the turn the layer
adds to the slow motion's (``∫∫ B e^{−Lτ}``): with ``B ≈ ω |v − N/L|`` it is ``λ = ω |v − N/L|_∞ /
L_min²`` (`layer_turn`, at `init`), so

    s₀ = h · min(1/3, (ω/L_max) · max(1, (θ/λ)^{1/4})),     θ = 1e-3 rad,

each next substep ``e^{L_min s/5}`` times the last, capped at the step, for as long as that
schedule is below ``h``. Then ``L s₀ = ωh · max(1, (θ/λ)^{1/4})``: the layer's error is
``≈ 5 (ωh)⁴ max(λ, θ)``, of the smooth steps' own order, and its cost about
``5 (L_max/L_min)/(ωh max(1, (θ/λ)^{1/4}))`` substeps once per run. Where the layer turns the body
by more than ``θ`` (``ζ/I = 10`` on the probe: ``λ`` 0.02–1.3) this is the last session's mesh,
``L s₀ = ωh``; in a stiff layer ``λ`` falls as ``1/L²`` and the substeps coarsen as ``L^{1/2}``.
Measured on `benchmarks/_fluid_probe.py` (`benchmarks/graded_start_counts.py`, dt over a factor 16; from
rest ``λ = 2.1e-5`` at ``ζ/I = 1e3``, 2.1e-9 at 1e5, spinning 1.2e-4 and 1.2e-8): slopes 4.03–4.10
at ``ζ/I`` 10, 1e3, 1e5 from rest, spinning and on the manifold (as with ``L s₀ = ωh``, whose slopes
were 4.03–4.10), errors within 6% of the manifold start's; the extra substeps per run from rest, at
40, 160 and 640 steps over ``t = 4``, 7, 24, 89 at ``ζ/I = 1e3`` (17, 60, 235 with ``L s₀ = ωh``)
and 2, 4, 11 at 1e5 (17, 61, 233); spinning 6, 18, 92 and 2, 4, 9. ``θ = 1e-2`` still passed
(slopes 4.04–4.11, errors within 16%); a coarsening by a factor blind to ``λ`` did not (4× ``ωh``:
slope 3.71 spinning at ``ζ/I = 1e3``; 64×: 3.77 at 1e5). On `benchmarks/fluid_step_cost.py`'s
bodies (``St = 0.1``, ``hL`` 1–2; 200 of them at ``S``: ``λ`` 1e-7–8e-4, median 9e-5) the first 7
steps took at most 75 substeps per body, median 46 (565 and 79 with ``L s₀ = ωh``: a body with a
small ``ω`` set the batch's count); from rest (``λ`` median 2e-3, above ``θ``) the median is
unchanged, 91, the most 296 (was 633: the bodies with the smallest ``ω`` have the smallest ``λ``).
``s₀`` is floored so that the substeps fit the loop's cap (1024): only the probe's
reference runs (10240 steps) reach it.

The decision, once per run at `init` (``FluidCarry.layer``: ``λ``, 0 for a body on its manifold) and
per body; a vmapped batch takes the graded branch when any body does (`eqxi.unvmap_any`), each body on
its own schedule (one substep for a body whose schedule is done: a body's run in a batch is its run
alone). On the slow manifold
``v = N/L − Ṅ/L² + …``, so a body on it has ``|v − N/L| ≈ (|Ṅ|/(L|N|)) |N/L|``, small where the
problem is stiff, while one at rest, spinning or at ``u = S`` is off by at least ``|N/L|``. The start
runs iff ``|v − N/L|_∞ > ½ |N/L|_∞`` (+ round-off). Measured on the probe: the ratio is 0.008 on the
manifold at ``ζ/I = 1e3``, 0.08 at 100, 0.8 at 10 (there ``N`` turns at ``ζ/I``'s own rate, no
manifold is separated, and the start runs), and ≥ 1 off it. (An earlier threshold at round-off
fired wrongly both ways; decided at every step instead, the start stopped once the layer fell below
``½ |N/L|`` and left that rest to plain steps: 7.5e-10 rad spinning at ``ζ/I = 1e3``, a floor.)
``graded_start=False`` turns it off.
"""

import equinox.internal as eqxi
import jax.numpy as jnp

from .. import quaternion as quat


# The graded start (this module's docstring): the first substep h min(r, c ω / L_max · max(1, (θ/λ)^{1/4})),
# each next one e^{L_min s / 5} times the last; on where the layer's deviation from the manifold exceeds
# κ |N/L|.
_STEP_FRACTION = 1 / 3  # r
_GROWTH_EXPONENT = 1 / 5  # the cost-optimal grading for a local error ∝ s⁵ e^{−L t}
_LAYER_TOLERANCE = 0.5  # κ
_MAX_SUBSTEPS = 1024
_SLOW_FRACTION = 1.0  # c
_LAYER_TURN = 1e-3  # θ (rad): 10× below a value that still kept the slopes (the docstring)
_COARSEST = 1e4  # the largest (θ/λ)^{1/4}: keeps λ → 0 finite, and its gradient
_LAYER_DECAYED = 36.0  # e^-36 = 2e-16


def _rates(rate):
    """``(L_min, L_max)`` of one body.

    Differentiated like the rest of the step: the substeps are functions of ``L`` (and of the carry),
    so the gradient is the derivative of the discrete map a run computes, which central differences
    of a parameter in ``ζ`` or ``I`` check (`tests/test_fluid.py`); only the substeps' count is flat."""
    return jnp.min(rate), jnp.max(rate)


def _root(x, power):
    """``|x|^power`` with finite gradients at ``x = 0`` (a body at rest in a fluid at rest)."""
    square = jnp.sum(x * x)
    positive = square > 0
    return jnp.where(positive, jnp.where(positive, square, 1.0) ** (power / 2), 0.0)


def _slow_rate(carry):
    """``ω = |S| + |N|^{1/2}``: the slow motion's rate, which sets the smooth steps' error ``∝ (ωh)⁴``."""
    return _root(carry.slow, 1.0) + _root(carry.forcing, 0.5)


def _first_substep(carry, dt, rate_min, rate_max):
    """``h min(r, c (ω/L_max) max(1, (θ/λ)^{1/4}))``: in proportion to the step at every ``L`` (no kink
    in ``h``); ``ω`` the slow motion's rate, ``|S| + |N|^{1/2}``, and ``λ`` the layer's turn
    (``carry.layer``, from `layer_turn` at `init`). Floored where the geometric mesh,
    ``5 L_max/(L_min L_max s₀)`` substeps, would not fit the loop's cap (with room for its tail)."""
    omega = _slow_rate(carry)
    turn = jnp.maximum(carry.layer, _LAYER_TURN / _COARSEST**4)
    coarsening = jnp.maximum(1.0, (_LAYER_TURN / turn) ** 0.25)
    floor = (1 / _GROWTH_EXPONENT) * (rate_max / rate_min) / (_MAX_SUBSTEPS - 64)
    fraction = jnp.maximum(_SLOW_FRACTION * coarsening * omega / rate_max, floor / (dt * rate_max))
    return dt * jnp.minimum(_STEP_FRACTION, fraction)


def _deviation(carry, rate):
    """``(v − N/L, N/L)`` ``(3,)`` each, body frame: one body's distance from its slow manifold."""
    (q, omega), slow, forcing, _ = carry
    manifold = forcing / rate
    return quat.rotate(quat.conjugate(q), omega) - slow - manifold, manifold


def off_manifold(carry, rate):
    """``|v − N/L|_∞ > κ |N/L|_∞`` (plus round-off) for one body's `FluidCarry`: in a boundary layer."""
    layer, manifold = _deviation(carry, rate)
    eps = jnp.finfo(carry.state.q.dtype).eps
    noise = 64 * eps * (jnp.abs(carry.slow).max() + jnp.abs(carry.state.omega).max())
    return jnp.abs(layer).max() > _LAYER_TOLERANCE * jnp.abs(manifold).max() + noise


def layer_turn(carry, rate):
    """``λ = ω |v − N/L|_∞ / L_min²`` (rad) where the body is `off_manifold`, else 0: the turn the layer
    adds to the slow motion's, of a forcing that changes by ``B ≈ ω |v − N/L|`` across it (``ω``, as
    in `_first_substep`, standing for ``|∂N/∂u|``) and decays within ``1/L``: ``∫∫ B e^{−Lτ} = B/L²``."""
    layer, _ = _deviation(carry, rate)
    omega = _slow_rate(carry)
    turn = omega * jnp.abs(layer).max() / jnp.min(rate) ** 2
    return jnp.where(off_manifold(carry, rate), turn, jnp.zeros_like(turn))


def _graded(carry, t, t0, dt, rate):
    """Whether one body's step at ``t`` is graded: it began off its manifold (``carry.layer``) and its
    schedule has not reached ``dt``."""
    rate_min, rate_max = _rates(rate)
    dtype = carry.state.q.dtype
    dt = jnp.asarray(dt, dtype)
    elapsed = jnp.asarray(t - t0, dtype)
    substep = _first_substep(carry, dt, rate_min, rate_max) * jnp.exp(_GROWTH_EXPONENT * rate_min * elapsed)
    return (carry.layer > 0) & (substep < dt) & (elapsed * rate_min < _LAYER_DECAYED)


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
