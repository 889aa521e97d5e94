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

On a GPU each iteration of a `while_loop` (the steps of a run, the free rotor's DMV
steps) is a few kernel launches and a host read of the loop's condition. XLA's command
buffers (CUDA graphs) can hold whole loops and conditionals, their conditions staying on
the device; XLA:GPU leaves loops out of them by default. On an H100 (jax 0.11.2) the
race's fixed-step runs of the three rotor schemes (12 cells: 8 to 256 steps) took 0.64 to
1.06 of their time without them, with the GPU's four DMV steps per loop iteration (the
long srkn6b runs were the slower ones), and the option passed to one program timed as the
process-wide flag ``--xla_gpu_enable_command_buffer=+WHILE,+CONDITIONAL`` did (0.97-1.14;
`docs/performance.md`, "On a GPU").
"""

import functools

import equinox as eqx
import jax
import jax.numpy as jnp


_CPU_OPTIONS = {"xla_cpu_experimental_ynn_fusion_type": ""}

# A compiler option replaces a repeated field with the names it lists (the flag's ``+WHILE`` adds
# to the defaults; the option has no such syntax), so each list names XLA's default command types
# too (jaxlib 0.11.2's XLA:GPU defaults first, then without DYNAMIC_SLICE_FUSION, a name older
# XLAs lack). The first list this jaxlib accepts is used; an unknown name fails at compile time.
_COMMAND_BUFFER_TYPES = (
    "FUSION,CUBLAS,CUBLASLT,CUSTOM_CALL,CUDNN,DYNAMIC_SLICE_FUSION,WHILE,CONDITIONAL",
    "FUSION,CUBLAS,CUBLASLT,CUSTOM_CALL,CUDNN,WHILE,CONDITIONAL",
)


def _accepted(options: dict[str, str]) -> bool:
    try:
        one_op = jax.jit(lambda x: x + 1).lower(jax.ShapeDtypeStruct((), jnp.float32))
        one_op.compile(compiler_options=options)
    except Exception:  # noqa: BLE001 - an unknown name is a backend error whose type varies
        return False
    return True


@functools.cache
def _gpu_options() -> dict[str, str]:
    for types in _COMMAND_BUFFER_TYPES:
        options = {"xla_gpu_enable_command_buffer": types}
        if _accepted(options):
            return options
    return {}


def compiler_options(backend: str | None = None) -> dict[str, str]:
    """XLA options for programs that run jaxrot's steps: ``jax.jit(f, compiler_options=...)``.

    ``backend`` defaults to JAX's default backend. On CPU they turn XLA:CPU's YNN
    fusions off (see `docs/performance.md`, "An XLA:CPU trap"); on a GPU they put while
    loops and conditionals into XLA's command buffers, XLA's default command types
    included (none if this jaxlib knows none of jaxrot's lists); elsewhere there are none.
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
    if backend == "cpu":
        return dict(_CPU_OPTIONS)
    if backend in ("gpu", "cuda", "rocm"):
        return dict(_gpu_options())
    return {}


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
