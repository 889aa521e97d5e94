"""Timing a compiled program: compile time alone, then the median of enough runs."""

import statistics
import time

import jax


MIN_TIMED_S = 0.2  # a cheap run is repeated until this much time is sampled (at most 100 runs)


def time_compiled(fn, arg, repeats, compiler_options=None):
    """Compile ``fn`` for ``arg``, then time it: (output, compile s, median run s).

    ``compiler_options`` go to ``jax.jit`` (`jaxrot.compiler_options` for jaxrot's programs).
    Compilation is timed alone (``lower().compile()``); the runs are timed by `time_runs`.
    """
    compiled, compile_s = compile_timed(fn, arg, compiler_options=compiler_options)
    out, seconds = time_runs(compiled, (arg,), repeats)
    return out, compile_s, seconds


def compile_timed(fn, *example, compiler_options=None):
    """``(compiled, compile s)``: ``fn`` lowered and compiled alone for the ``example`` arguments."""
    start = time.perf_counter()
    compiled = jax.jit(fn, compiler_options=compiler_options).lower(*example).compile()
    return compiled, time.perf_counter() - start


def time_runs(compiled, args, repeats):
    """``(output, median run s)`` of a compiled program on ``args``.

    One untimed run first. Then at least ``repeats`` runs, and more until `MIN_TIMED_S`
    is sampled: a run of a millisecond is at the mercy of the scheduler, and its median
    over a few samples moved 2× between neighbouring rungs.
    """
    out = jax.block_until_ready(compiled(*args))
    samples = []
    while len(samples) < repeats or (sum(samples) < MIN_TIMED_S and len(samples) < 100):
        start = time.perf_counter()
        jax.block_until_ready(compiled(*args))
        samples.append(time.perf_counter() - start)
    return out, statistics.median(samples)
