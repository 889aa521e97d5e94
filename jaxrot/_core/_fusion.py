"""Stage boundaries inside a step: values XLA must compute once and keep.

XLA fuses a cheap elementwise producer into every consumer and recomputes it
there. In a step, where each stage reads all earlier ones, that duplication
compounds: the component-by-component Zhao step compiled to 15 cosines instead
of 2 and about 1600 multiplies instead of about 500, and ran at 6.7 million
particle-steps per second on 2 CPU cores (N = 10⁴, float64, heavy top). Marking
the stage results with `stage` (an ``optimization_barrier``, which XLA does not
fuse through) made the same step run at 20 M/s and compile in half the time.
Values, gradients and batching are unchanged: the barrier is the identity.
"""

import jax


BARRIERS = None
"""Where `stage` places its barrier: ``None`` (default) when tracing for CPU only, else always
(``True``) or never (``False``). Private: benchmarks set it before anything is traced, in a process
of their own; compiled programs keep what they were traced with. On an H100 (jax 0.11.2, float32,
heavy top, 10⁶ bodies) the steps ran up to 1.33× faster without them (zhao 3.2 → 4.3 G
particle-steps/s, rkmk4 1.9 → 2.4, srkn14a 0.135 → 0.170; no_squish and rozmanov unchanged): there
fusion wins (docs/performance.md, "On a GPU")."""


def tracing_for_cpu() -> bool:
    """Whether the program being traced is taken to run on CPU: JAX's default backend.

    Where XLA:CPU and a GPU want different programs (these barriers; the free rotor's loop,
    `jaxrot._free_body._rotor_loop.LOOP_BATCH`), the choice is made when tracing, by this one rule.
    """
    return jax.default_backend() == "cpu"


def _barriers() -> bool:
    return tracing_for_cpu() if BARRIERS is None else BARRIERS


def stage(*values):
    """The identity on a value (or several), computed once and materialised.

    Example:
        >>> import jax.numpy as jnp
        >>> from jaxrot._core._fusion import stage
        >>> stage(jnp.arange(3.0)).tolist()
        [0.0, 1.0, 2.0]
    """
    kept = jax.lax.optimization_barrier(values) if _barriers() else values
    return kept[0] if len(values) == 1 else kept


def stage_stacked(*values):
    """`stage` of several same-shaped arrays computed in one loop: as one ``(…, k)`` array.

    XLA:CPU compiles each materialised array to its own loop over the bodies, and a value that
    several of them read is recomputed in each; stacked, the values come out of one loop (measured
    on the free rotor's four modified-moment sums, which six loops recomputed: the ``"splitting"``
    step ~2% faster, float64, N = 10⁴; the same idea in the rotor's loop carry gave 10%). Returns
    the values, unstacked.

    Example:
        >>> import jax.numpy as jnp
        >>> from jaxrot._core._fusion import stage_stacked
        >>> [v.tolist() for v in stage_stacked(jnp.arange(2.0), jnp.ones(2))]
        [[0.0, 1.0], [1.0, 1.0]]
    """
    stacked = stage(jax.numpy.stack(values, axis=-1))
    return tuple(stacked[..., k] for k in range(len(values)))
