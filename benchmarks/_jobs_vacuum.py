"""The jobs of `regenerate.py` that measure bodies in vacuum: the races against diffrax, compile and
first-call times, throughput, memory, stability, the orders, and MuJoCo's and MJX's free body."""

from _job import BASE, DIFFRAX, FIT, FLUID, ROTOR, SCENES, THERMAL, VACUUM, Job


# The race's scenes: each draws its work-precision figure beside the race's results file.
RACE_SCENES = ("heavy_top", "viscous_drag", "dipole_rotating_field")
# The race's settings, both dtypes (see race64).
RACE = (
    "benchmarks/race.py",
    "--repeats",
    "1",
    "--time-cap",
    "0.5",
    "--adaptive-cap",
    "4",
    "--out",
    "docs/race_cpu",
)


VACUUM_JOBS = {
    "compare": Job(
        ("compare_heavy_top.json", "compare_heavy_top.png"),
        ("-m", "jaxrot", "compare", "--out", "{tmp}"),
        0.8,
        copies=(("compare.json", "compare_heavy_top.json"), ("compare.png", "compare_heavy_top.png")),
        sources=(*BASE, *VACUUM, *DIFFRAX, *SCENES, "jaxrot/comparison/_ladder.py", "jaxrot/__main__.py"),
    ),
    # One timed run per rung (the ratios come from the side-by-side re-timing), fixed-step ladders cut
    # past 0.5 s a run, tolerance ladders past 4 s. Replayed on the published file of 2026-11-27 (its
    # first-pass and re-timed seconds), these settings and race.FINALIST_WITHIN give the same 27
    # cells, ratios included, from 8.5 quiet minutes of ladders, compiles and re-timing (31.8 before);
    # with the reference solves, imports and figures about 9.5 (estimated; not measured quiet).
    # race32 stays its own job: the dtypes share no program, reference or state, only the scenes.
    "race64": Job(
        ("race_cpu/race_float64.json", *(f"race_cpu/race_{scene}_float64.png" for scene in RACE_SCENES)),
        RACE,
        7.7,
        # Compiles are most of it at N = 200 (about 100 s of the full run's).
        quick=("benchmarks/race.py", "--n", "200", "--repeats", "1", "--time-cap", "0.5", "--out", "{tmp}"),
        quick_minutes=3,
        tables=("race_table_float64",),
        sources=(*BASE, *VACUUM, *DIFFRAX, *SCENES, "benchmarks/race.py", "benchmarks/_race_tables.py"),
    ),
    # Draws only: the headline figure of README and the home page, from race64's results.
    "headline": Job(("headline.png",), ("benchmarks/headline.py",), 0.1, timed=False),
    # Replayed as race64 (2026-11-26 file): the same 12 cells from 3.7 quiet minutes (13.1 before),
    # about 4.5 with the reference solves and imports (estimated).
    "race32": Job(
        ("race_cpu/race_float32.json", *(f"race_cpu/race_{scene}_float32.png" for scene in RACE_SCENES)),
        (*RACE, "--dtype", "float32"),
        3.1,
        quick=(
            "benchmarks/race.py",
            "--dtype",
            "float32",
            "--n",
            "200",
            "--repeats",
            "1",
            "--time-cap",
            "0.5",
            "--out",
            "{tmp}",
        ),
        quick_minutes=3,
        tables=("race_table_float32",),
        sources=(*BASE, *VACUUM, *DIFFRAX, *SCENES, "benchmarks/race.py", "benchmarks/_race_tables.py"),
    ),
    "compile": Job(
        ("compile_cpu.json",),
        ("benchmarks/compile.py",),
        4.6,
        sources=(*BASE, *VACUUM, *SCENES, "benchmarks/compile.py"),
    ),
    # The first call of jaxrot's public entries and their peers, split into JAX's stages, each cell in a
    # fresh process, and again with the persistent compilation cache cold and warm (issue 72).
    "first_call": Job(
        ("first_call_cpu.json",),
        ("benchmarks/first_call.py", "--out", "docs/first_call_cpu.json"),
        7,  # measured: 6.8 min on quiet cores (commit 2e7770d)
        quick=("benchmarks/first_call.py", "--quick", "--out", "{tmp}/first_call_cpu.json"),
        quick_minutes=7,
        tables=("first_call_table",),
        sources=(
            *BASE,
            *VACUUM,
            *FLUID,
            *THERMAL,
            *DIFFRAX,
            *FIT,
            *SCENES,
            "jaxrot/comparison",
            "jaxrot/__main__.py",
            "benchmarks/first_call.py",
            "benchmarks/_first_call_problems.py",
            "benchmarks/compile.py",
            "benchmarks/identify_speed.py",
            "tests/_mujoco_telemetry.py",
            "tests/_mujoco_sysid.py",
        ),
    ),
    "throughput": Job(
        ("throughput_cpu.json",),
        (
            "benchmarks/throughput.py",
            "--n",
            "1000,10000,100000,1000000",
            "--json",
            "docs/throughput_cpu.json",
        ),
        # From the published file's own figures: 136 s of compiles and 83 s of one run of every row,
        # each row run 4 times (a warm run and 3 timed; the 10⁶-body rows 53 s of the 83), so about
        # 8 min on quiet cores. Its 10⁶-body rows keep their 10 steps: at 2 steps a run's fixed cost
        # made euler and zhao 2.4-2.6x slower per step (measured under load, interleaved).
        6.2,
        quick=(
            "benchmarks/throughput.py",
            "--n",
            "1000,10000",
            "--repeats",
            "1",
            "--json",
            "{tmp}/throughput_cpu.json",
        ),
        quick_minutes=3,
        tables=("throughput_table",),
        sources=(*BASE, *VACUUM, *SCENES, "benchmarks/throughput.py"),
        peers=True,
    ),
    # jax 0.10.2 (the default install of Python 3.11) beside the newest jax of the throughput job.
    "throughput_jax010": Job(
        ("throughput_cpu_jax010.json",),
        (
            "benchmarks/throughput.py",
            "--n",
            "1000,10000,100000",
            "--dtype",
            "float32,float64",
            "--no-peer",
            "--json",
            "docs/throughput_cpu_jax010.json",
        ),  # fmt: skip
        # Without the 10⁶-body rows (about half of the throughput job's run time, by its file): the
        # question here is the jax version's ratio, which 10³…10⁵ bodies answer; 10⁶ is the newest
        # jax's (the throughput job's) alone.
        4,
        sources=(*BASE, *VACUUM, *SCENES, "benchmarks/throughput.py"),
    ),
    # The same with XLA's default options instead of jaxrot.compiler_options(): the YNN trap.
    "throughput_jax010_xla_defaults": Job(
        ("throughput_cpu_jax010_xla_defaults.json",),
        (
            "benchmarks/throughput.py",
            "--n",
            "1000,10000,100000",
            "--dtype",
            "float64",
            "--schemes",
            "zhao,rozmanov,no_squish",
            "--no-peer",
            "--xla-defaults",
            "--json",
            "docs/throughput_cpu_jax010_xla_defaults.json",
        ),  # fmt: skip
        0.6,
        sources=(*BASE, *VACUUM, *SCENES, "benchmarks/throughput.py"),
    ),
    # XLA:CPU's 512-bit vectors against its default 256 (measured, not kept: docs/performance.md).
    "cpu_vector_width": Job(
        ("cpu_vector_width.json",),
        (
            "benchmarks/cpu_options.py",
            "--cells",
            "float64:10000,float64:100000,float32:10000",
            "--rounds",
            "5",
            "--json",
            "docs/cpu_vector_width.json",
        ),  # fmt: skip
        # Compiling dominates (two programs per scheme and cell; a timed run is ~0.1 s): three of the
        # first file's four cells (10³ bodies, float64, dropped: the 26-Nov file's ratios there,
        # 0.81-1.14x, lay inside its whole range, 0.79-1.16x), five rounds: a steadier median, cheap.
        # Measured quiet on b4c11bd, after the whole run: 6.8 min (135 s a cell).
        6.8,
        sources=(*BASE, *VACUUM, *SCENES, "benchmarks/cpu_options.py", "benchmarks/throughput.py"),
    ),
    "memory": Job(
        ("memory_cpu.json",),
        ("benchmarks/memory.py", "--json", "docs/memory_cpu.json"),
        4.3,
        # the heavy_top scene's bodies (throughput.bodies)
        sources=(*BASE, *VACUUM, *SCENES, "benchmarks/memory.py", "benchmarks/throughput.py"),
    ),
    # Accuracy only: the largest safe step, blow-up and long-run drift of every scheme.
    "stability": Job(
        ("stability_cpu.json",),
        ("benchmarks/stability.py", "--json", "docs/stability_cpu.json"),
        2.7,
        sources=(
            *BASE,
            *VACUUM,
            *SCENES,
            "jaxrot/stability.py",
            "jaxrot/diagnostics.py",
            "benchmarks/stability.py",
        ),
        timed=False,
    ),
    # Accuracy only: energy and momentum against |ω|Δt over 1e5 steps, every vacuum scheme and MJX's
    # integrators (MJX's rows need `pip install -e ".[mjx]"`; without it they are left out, saying so).
    "energy_growth": Job(
        ("energy_growth.json",),
        ("benchmarks/energy_growth.py", "--json", "docs/energy_growth.json"),
        # 10.1 min at 0.39 of a core beside 1.61 cores of other work (2026-11-29): 237 core-seconds,
        # so about 4 min on 2 quiet cores (estimated; its programs use one core at a time)
        3.1,
        tables=("energy_limits_table",),
        sources=(
            *BASE,
            *VACUUM,
            *SCENES,
            "jaxrot/diagnostics.py",
            "jaxrot/_pivot.py",
            "benchmarks/energy_growth.py",
            "benchmarks/mjx_peer.py",
            "benchmarks/mujoco_free_body.py",
            "benchmarks/_mujoco_paths.py",
        ),
        timed=False,
    ),
    # Accuracy only: the fourth-order Lie-group methods (MuJoCo's row needs `pip install mujoco`).
    "order4": Job(
        ("order4.json",),
        ("benchmarks/order4.py", "--json", "docs/order4.json"),
        1.8,
        sources=(*BASE, *VACUUM, *DIFFRAX, *SCENES, "benchmarks/order4.py"),
        timed=False,
    ),
    # Accuracy only: each scheme's float32 run against its float64 run (docs/stability.md).
    "float32": Job(
        ("float32_horizon.json",),
        ("benchmarks/float32.py", "--json", "docs/float32_horizon.json"),
        # 106 CPU-s (user+sys) in a run under heavy load (2026-11-29): 0.9 min on 2 quiet cores,
        # 1.8 if it used one core at a time (mostly compiles).
        1.2,
        quick=("benchmarks/float32.py", "--steps", "20000", "--json", "{tmp}/float32_horizon.json"),
        quick_minutes=1,
        tables=("float32_horizon_table",),
        sources=(*BASE, *VACUUM, *DIFFRAX, *SCENES, "benchmarks/float32.py"),
        timed=False,
    ),
    "identify_speed": Job(
        ("identify_speed_cpu.json",),
        ("benchmarks/identify_speed.py", "--json", "docs/identify_speed_cpu.json"),
        # (user+sys)/2: the quiet run of 11:09 (1.67 cores x 303 s) plus the real-sensor rows (4 seeds:
        # at most twice the 169 CPU s that 2 seeds and jaxrot's first call took under load)
        8.2,
        quick=("benchmarks/identify_speed.py", "--quick", "--json", "{tmp}/identify_speed_cpu.json"),
        quick_minutes=4,
        tables=("identify_speed_table", "identify_sysid_table", "identify_sysid_sensors_table"),
        sources=(
            *BASE,
            *VACUUM,
            *DIFFRAX,
            *FIT,
            "benchmarks/identify_speed.py",
            "benchmarks/identify_mujoco.py",
            "benchmarks/_identify_capabilities.py",
            "tests/_mujoco_telemetry.py",
            "tests/_mujoco_sysid.py",
            "tests/_mujoco_sysid_sensors.py",
        ),
    ),
    # MuJoCo 4.0 against jaxrot on the free body (needs `pip install -e ".[mujoco]"`; without it the
    # benchmark says so and writes nothing).
    "mujoco_free_body": Job(
        ("mujoco_free_body_cpu.json", "mujoco_free_body_cpu.png"),
        (
            "benchmarks/mujoco_free_body.py",
            "--json",
            "docs/mujoco_free_body_cpu.json",
            "--png",
            "docs/mujoco_free_body_cpu.png",
        ),
        # 581 CPU-s (user+sys) in a full run under heavy load (2026-11-29): its MuJoCo ladders ~340 (on
        # both cores: ~3 min quiet), the paths ~50, jaxrot ~180 with 14 rungs past the 1 s cap that
        # quiet cores would time (3 runs more each); about 7 min quiet, estimated. Its MuJoCo errors
        # equal the published file's at every rung.
        6.3,
        quick=(
            "benchmarks/mujoco_free_body.py",
            "--n",
            "200",
            "--max-steps",
            "8192",
            "--repeats",
            "2",
            "--json",
            "{tmp}/mujoco_free_body_cpu.json",
        ),
        quick_minutes=3,  # jaxrot's ~90 compiles are most of it
        tables=("mujoco_free_body_speed",),
        sources=(
            *BASE,
            *VACUUM,
            "jaxrot/analytic.py",
            "benchmarks/mujoco_free_body.py",
            "benchmarks/_mujoco_paths.py",
        ),
    ),
    # MuJoCo XLA against jaxrot (needs `pip install -e ".[mjx]"`; without it the benchmark says so and
    # writes nothing): orders, cost at equal error (1000 bodies), the gradient's cost and its value at rest.
    "mjx": Job(
        ("mjx_cpu.json",),
        ("benchmarks/mjx_peer.py", "--json", "docs/mjx_cpu.json"),
        3,  # measured: 3.0 min on 2 quiet cores, 2026-11-29
        quick=("benchmarks/mjx_peer.py", "--quick", "--json", "{tmp}/mjx_cpu.json"),
        quick_minutes=5,
        tables=("mjx_orders_table", "mjx_cost_table", "mjx_gradient_table"),
        sources=(
            *BASE,
            *VACUUM,
            *DIFFRAX,
            *SCENES,
            "jaxrot/_pivot.py",
            "benchmarks/mujoco_free_body.py",
            "benchmarks/_mujoco_paths.py",
            "benchmarks/mjx_peer.py",
        ),
    ),
}


# The free rotor's step-count choice: apart, to keep its place in `regenerate.py --list`.
ROTOR_JOBS = {
    "rotor_choice": Job(
        ("rotor_choice_cpu.json",),
        ("benchmarks/rotor.py", "--choice-only", "--rounds", "61", "--json", "docs/rotor_choice_cpu.json"),
        1.5,
        sources=(
            *BASE,
            *ROTOR,
            "jaxrot/schemes/splitting.py",
            "jaxrot/schemes/_rkn_splitting.py",
            "benchmarks/rotor.py",
        ),
    ),
}
