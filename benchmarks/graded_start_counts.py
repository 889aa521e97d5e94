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

from jaxrot.schemes import ExpRK4  # noqa: E402


STEPS = [40, 80, 160, 320, 640]


def main(rates):
    with probe.counting_substeps() as counts:  # substeps, graded steps
        for rate in rates:
            run = probe.runner(ExpRK4(), rate)
            for kind in ("off", "spin", "on"):
                state = probe.start(kind, rate)
                reference = run(state, jnp.asarray(probe.T_END / (16 * STEPS[-1])), 16 * STEPS[-1])
                errors, extra = [], []
                for n in STEPS:
                    counts[:] = [0, 0]
                    q = jax.block_until_ready(run(state, jnp.asarray(probe.T_END / n), n))
                    errors.append(float(probe.quat.angle_between(q, reference)))
                    extra.append(f"{counts[0] - counts[1]}/{counts[1]}")
                slope = np.polyfit(np.log([probe.T_END / n for n in STEPS]), np.log(errors), 1)[0]
                shown = " ".join(f"{e:.2e}" for e in errors)
                row = f"ζ/I = {rate:g} {kind:4s} slope {slope:.3f}; errors {shown}"
                print(f"{row}; extra substeps/graded steps {' '.join(extra)}", flush=True)


if __name__ == "__main__":
    main([float(r) for r in sys.argv[1:]] or [10.0, 1e3, 1e5])
