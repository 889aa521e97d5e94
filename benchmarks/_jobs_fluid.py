"""The jobs of `regenerate.py` that measure bodies in a fluid (docs/fluid.md)."""

from _job import BASE, DIFFRAX, FLUID, SCENES, VACUUM, Job


FLUID_JOBS = {
    # Bodies in a fluid (docs/fluid.md): the orders (accuracy only) and the race against diffrax.
    "fluid_orders": Job(
        ("fluid_orders.json",),
        ("benchmarks/fluid_orders.py",),
        # One program per scheme and torque for all seven Stokes numbers, one Dopri8 reference per
        # Stokes number and torque for all schemes: 45 CPU-s in all (2026-11-29, load ~18), under a
        # minute on 2 quiet cores.
        0.5,
        quick=("benchmarks/fluid_orders.py", "--quick", "--out", "{tmp}/fluid_orders.json"),
        quick_minutes=0.5,
        tables=("fluid_orders_table",),
        sources=(*BASE, *VACUUM, *FLUID, *SCENES, "benchmarks/fluid_orders.py"),  # row "none": heavy_top
        timed=False,
    ),
    "fluid_layer": Job(
        ("fluid_layer.json",),
        ("benchmarks/fluid_layer.py",),
        # 12 programs (scheme, start rule, rate), each reference once: 58 CPU-s (2026-11-29, load ~18).
        0.7,
        sources=(*BASE, *FLUID, "benchmarks/fluid_layer.py", "benchmarks/_fluid_probe.py"),
        timed=False,
    ),
    "overdamped_cost": Job(
        ("overdamped_cost_cpu.json",),
        ("benchmarks/overdamped_cost.py", "--json", "docs/overdamped_cost_cpu.json"),
        0.4,
        sources=(*BASE, *VACUUM, *FLUID, *SCENES, "benchmarks/overdamped_cost.py"),
    ),
    "fluid_race": Job(
        ("fluid_race_cpu.json", "fluid_race_cpu.png"),
        # One run per rung; a ladder ends past 2 s a run (8 s diffrax's) or 2x a row of its side that
        # meets 1e-8; the rows that can win a budget are re-timed round-robin, up to 7 rounds and 2 s
        # each; diffrax's step budget is its default, 4096. Replayed on the 2026-11-27 file's rows,
        # these rules keep every budget's fastest row on both sides and leave 6.4 min of runs (46.6
        # before: 4 runs a rung, 7 rounds of ~19-30 finalists, Kvaerno5 failing at 16384 steps), plus
        # ~3.5 min of compilation (St = 0.1 measured: 195 CPU-s with the runs, 2026-11-29, load ~17).
        ("benchmarks/fluid_race.py", "--repeats", "1", "--time-cap", "2", "--max-steps", "4096"),
        6.7,
        quick=(
            "benchmarks/fluid_race.py",
            "--n",
            "200",
            "--repeats",
            "1",
            "--rounds",
            "3",
            "--stokes",
            "0.1",
            "--out",
            "{tmp}",
        ),
        quick_minutes=3,
        tables=("fluid_race_table",),
        sources=(
            *BASE,
            *VACUUM,
            *FLUID,
            *DIFFRAX,
            *SCENES,
            "benchmarks/fluid_race.py",
            "benchmarks/_fluid_race_runners.py",
            "benchmarks/_fluid_race_tables.py",
            "benchmarks/race.py",
            "benchmarks/_race_tables.py",
        ),
    ),
    # One exponential step in the race's fluid against a Lie-group Runge-Kutta step with the same physics
    # as a torque (docs/fluid.md).
    "fluid_step_cost": Job(
        ("fluid_step_cost_cpu.json",),
        ("benchmarks/fluid_step_cost.py", "--json", "docs/fluid_step_cost_cpu.json"),
        0.5,
        quick=(
            "benchmarks/fluid_step_cost.py",
            "--n",
            "200",
            "--steps",
            "50",
            "--rounds",
            "3",
            "--json",
            "{tmp}/fluid_step_cost_cpu.json",
        ),
        quick_minutes=1,
        sources=(*BASE, *VACUUM, *FLUID, *SCENES, "benchmarks/fluid_step_cost.py"),
    ),
}
