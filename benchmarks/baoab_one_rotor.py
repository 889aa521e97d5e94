"""A/B of the smaller BAOAB program against the one before, in one process.

Both A steps of a BAOAB step run the free rotor: traced once in a loop of two iterations
(`jaxrot.schemes.baoab._ONE_ROTOR`), not twice; and the rotor's first two DMV steps run in its while
loop (`jaxrot._free_body._rotor_loop._MERGED`), not in a static loop before it. "before" has both
switches off, "after" both on. This measures, for jaxrot.jax_md's ``nvt_langevin`` (float64, dt 1/16
free bodies, 1/64 tetrahedra, kT 1, gamma 10): the compiled size (HLO instructions) and compile time of
`benchmarks/first_call.py`'s 1000-step loop on 40 tetrahedra, then the step's speed (a 100-step loop
on 10⁴ free bodies and on 128 interacting tetrahedra), the variants interleaved, wall and CPU time,
median over the rounds. Needs jax_md (Python 3.12)::

    python benchmarks/baoab_one_rotor.py --rounds 11
"""

import argparse
import os
import statistics
import sys
import time
from pathlib import Path


HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE.parent), str(HERE)]

import jax  # noqa: E402


jax.config.update("jax_enable_x64", True)

from jax_md import rigid_body  # noqa: E402
from jax_md_systems import free_system, shape, tetrahedra  # noqa: E402

import jaxrot.jax_md as jm  # noqa: E402
from jaxrot._free_body import _rotor_loop  # noqa: E402
from jaxrot.schemes import baoab  # noqa: E402


def _ops(compiled):
    return sum(
        1 for line in compiled.as_text().splitlines() if " = " in line and not line.lstrip().startswith("//")
    )


def _switch(after):
    baoab._ONE_ROTOR = _rotor_loop._MERGED = after
    jax.clear_caches()  # free_rotor is jitted: its trace would be reused across the switch


def _loop(system, dt, steps):
    energy_fn, shift, body = system
    init_fn, apply_fn = jm.nvt_langevin(energy_fn, shift, dt, 1.0, rigid_body.RigidBody(10.0, 10.0))
    state = init_fn(jax.random.key(3), body, mass=shape().mass())
    return jax.jit(lambda s: jax.lax.fori_loop(0, steps, lambda i, s_: apply_fn(s_), s)), state


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--rounds", type=int, default=11)
    rounds = parser.parse_args(argv).rounds
    for after in (False, True):
        _switch(after)
        loop, state = _loop(tetrahedra(40), 1 / 64, 1000)
        start = time.perf_counter()
        compiled = loop.lower(state).compile()
        seconds = time.perf_counter() - start
        name = ("before", "after")[after]
        print(f"first-call loop, {name}: compile {seconds:.1f} s, {_ops(compiled)} HLO ops")
    runs = {}
    for label, (system, dt) in {
        "free": (free_system(10_000), 1 / 16),
        "tetrahedra": (tetrahedra(128), 1 / 64),
    }.items():
        for after in (False, True):
            _switch(after)
            loop, state = _loop(system, dt, 100)
            compiled = loop.lower(state).compile()
            jax.block_until_ready(compiled(state))
            runs[label, after] = (compiled, state, [], [])
    for _ in range(rounds):
        for compiled, state, wall, cpu in runs.values():
            start, start_cpu = time.perf_counter(), time.process_time()
            jax.block_until_ready(compiled(state))
            wall.append(time.perf_counter() - start)
            cpu.append(time.process_time() - start_cpu)
    load = os.getloadavg()[0]
    print(f"load average {load:.1f} on {os.cpu_count()} cores; {rounds} interleaved rounds, medians")
    for label in ("free", "tetrahedra"):
        (_, _, w0, c0), (_, _, w1, c1) = runs[label, False], runs[label, True]
        w0, w1, c0, c1 = map(statistics.median, (w0, w1, c0, c1))
        print(f"{label:10s} before {w0 * 1e3:7.0f} ms (cpu {c0 * 1e3:6.0f}), after {w1 * 1e3:7.0f} ms "
              f"(cpu {c1 * 1e3:6.0f}): wall {w1 / w0:.3f}x, cpu {c1 / c0:.3f}x")  # fmt: skip


if __name__ == "__main__":
    main()
