"""The XLA options jaxrot compiles its own programs with.

jaxlib 0.10.2's XLA:CPU hands some fusions to YNNPACK depending on the array sizes;
in float64 the quaternion renormalisation's fusion grew, past a few thousand bodies,
to the whole ``(N, 4)`` update, and ``no_squish`` fell from 13.6 to 1.3 million
particle-steps per second between 10³ and 10⁴ bodies (2 CPU cores; `docs/performance.md`).
Without YNN fusions it ran at 25.5 at 10⁴. The process-wide switch is an XLA flag,
read once when JAX starts, and a library must not change its user's flags; a
compiler option applies to one program. `compiler_options` are the options jaxrot
passes when it compiles a program itself (`filter_jit`); a user who wraps jaxrot in
their own `jax.jit` passes them there.
"""

import functools

import equinox as eqx
import jax


_CPU_OPTIONS = {"xla_cpu_experimental_ynn_fusion_type": ""}


def compiler_options(backend: str | None = None) -> dict[str, str]:
    """XLA options for programs that run jaxrot's steps: ``jax.jit(f, compiler_options=...)``.

    ``backend`` defaults to JAX's default backend. On CPU they turn XLA:CPU's YNN
    fusions off (see `docs/performance.md`, "An XLA:CPU trap"); elsewhere there are none.
    `jaxrot.rollout` called outside any ``jax.jit`` already compiles with them.

    Example:
        >>> import jax, jaxrot
        >>> run = jax.jit(
        ...     lambda s: jaxrot.rollout("zhao", s, jax.numpy.ones(3), 0.01, 10).q[-1],
        ...     compiler_options=jaxrot.compiler_options(),
        ... )
        >>> state = jaxrot.RotState(jax.numpy.array([1.0, 0, 0, 0]), jax.numpy.array([0.0, 1, 2]))
        >>> run(state).shape
        (4,)
    """
    backend = jax.default_backend() if backend is None else backend
    return dict(_CPU_OPTIONS) if backend == "cpu" else {}


def _outside_any_trace() -> bool:
    # Compiler options are only accepted by a top-level jit: nested inside a user's jit, grad or
    # vmap, this program becomes part of theirs and compiles with their options.
    clean = getattr(jax._src.core, "trace_state_clean", None)
    return clean is not None and clean()


def filter_jit(fun):
    """`equinox.filter_jit` of ``fun``, compiled with `compiler_options` when called at top level."""
    plain = eqx.filter_jit(fun)
    with_options = {}

    @functools.wraps(fun)
    def call(*args, **kwargs):
        if not _outside_any_trace():
            return plain(*args, **kwargs)
        options = compiler_options()
        key = tuple(sorted(options.items()))  # the options of this call's backend
        if key not in with_options:
            with_options[key] = eqx.filter_jit(fun, compiler_options=options)
        return with_options[key](*args, **kwargs)

    return call
