"""A fixed-step loop that saves every few steps: `jaxrot.overdamped_rollout`'s, and the comparison's.

``dt`` and the steps between saves may be runtime values: a ladder of time steps
(`jaxrot.comparison`) runs one scheme at many ``(dt, steps)`` pairs and compiles once per scheme.
The times come from the step index, as in `jaxrot.rollout` (``t = t0 + (k · steps + j) Δt``), so
that late times keep full precision. (`jaxrot.rollout`'s own loop, `jaxrot._integrate._run`, adds
chunks, cache blocking and the runtime check.)
"""

import jax
import jax.numpy as jnp


def saved_steps(carry, step, read, dt, steps_per_save, n_saves, t0=None):
    """``read(carry)`` after each of ``n_saves`` saves of ``steps_per_save`` steps (stacked, the
    initial carry not included).

    Args:
        carry: the scheme's carry at ``t0`` (any pytree; bodies vmapped inside ``step`` or outside).
        step: ``step(carry, t, index) -> carry``, step ``index`` (from 0) of ``dt`` from time ``t``.
        read: what to save of a carry (a `RotState`, or the carry itself).
        dt: the step (a scalar array); steps_per_save: steps between saves (an int, or a traced one);
        n_saves: the number of saves (a Python int); t0: the start time, or None for 0.
    """

    def save(carry, k):
        def one_step(j, c):
            index = k * steps_per_save + j
            t = index.astype(dt.dtype) * dt
            return step(c, t if t0 is None else t0 + t, index)

        carry = jax.lax.fori_loop(0, steps_per_save, one_step, carry)
        return carry, read(carry)

    return jax.lax.scan(save, carry, jnp.arange(n_saves, dtype=jnp.int32))[1]
