"""The graded start on the probe (`_fluid_probe`): slopes, errors and substeps per run (issue 73).

For each ζ/I given and each start (at rest, spinning, on the manifold): the final orientation errors
at 40 … 640 steps over t = 4 against the same program at 16× the finest step, their least-squares
slope (`tests/test_fluid_start.py`'s measure), and the substeps the start took beyond one per step,
with the number of graded steps (counted by a host callback around each substep: not timed).

    python benchmarks/graded_start_counts.py 10 1e3 1e5    # ~2 minutes on 2 cores
"""

import sys

import jax


jax.config.update("jax_enable_x64", True)

import _fluid_probe as probe  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from jaxrot.schemes import ExpRK4, _graded_start  # noqa: E402


STEPS = [40, 80, 160, 320, 640]
COUNTS = [0, 0]  # substeps, graded steps
_graded_step = _graded_start.graded_step


def _counting(step, *args):
    def counted(*a):
        jax.debug.callback(lambda: COUNTS.__setitem__(0, COUNTS[0] + 1))
        return step(*a)

    jax.debug.callback(lambda: COUNTS.__setitem__(1, COUNTS[1] + 1))
    return _graded_step(counted, *args)


def main(rates):
    _graded_start.graded_step = _counting  # read when `start_step` is traced
    for rate in rates:
        run = probe.runner(ExpRK4(), rate)
        for kind in ("off", "spin", "on"):
            state = probe.start(kind, rate)
            reference = run(state, jnp.asarray(probe.T_END / (16 * STEPS[-1])), 16 * STEPS[-1])
            errors, extra = [], []
            for n in STEPS:
                COUNTS[:] = [0, 0]
                q = jax.block_until_ready(run(state, jnp.asarray(probe.T_END / n), n))
                errors.append(float(probe.quat.angle_between(q, reference)))
                extra.append(f"{COUNTS[0] - COUNTS[1]}/{COUNTS[1]}")
            slope = np.polyfit(np.log([probe.T_END / n for n in STEPS]), np.log(errors), 1)[0]
            shown = " ".join(f"{e:.2e}" for e in errors)
            print(f"ζ/I = {rate:g} {kind:4s} slope {slope:.3f}; errors {shown}; extra substeps/graded steps "
                  + " ".join(extra), flush=True)  # fmt: skip


if __name__ == "__main__":
    main([float(r) for r in sys.argv[1:]] or [10.0, 1e3, 1e5])
