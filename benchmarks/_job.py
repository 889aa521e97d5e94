"""What a job of `regenerate.py` is (its command, the results files it writes, its expected time, full
and quick, and the sources its numbers depend on), and the package code behind the numbers, by concept."""

from typing import NamedTuple


class Job(NamedTuple):
    files: tuple[str, ...]  # under docs/
    argv: tuple[str, ...]  # after the interpreter
    # on this project's 2-core CPU, quiet: each job's time in the whole run of 2026-11-29 (a0834c9, 85.6 min
    # in all; the comments beside them record how each was sized)
    minutes: float
    long: bool = False  # past the 10 minutes a rerun during development may take
    # (file in the job's scratch folder ``{tmp}``, file under docs/) copied once the job has run
    copies: tuple[tuple[str, str], ...] = ()
    # The same benchmark at reduced sizes (its outputs in the scratch folder ``{tmp}``, which
    # ``--quick`` keeps under quick/), for a rerun within 10 minutes; the full run stays for docs/.
    quick: tuple[str, ...] | None = None
    quick_minutes: float | None = None
    # Repository paths (files or folders) its numbers depend on: a change there makes it stale.
    sources: tuple[str, ...] = ()
    timed: bool = True  # its figures are timings: refused unless measured on quiet cores
    # The docs tables (names in docs/_hooks/tables.py's TABLES) that carry its headline figures:
    # a quick run prints each from its own files beside the published one.
    tables: tuple[str, ...] = ()
    # Runs under the peers' interpreter (``--peers-python``: Python 3.12 with the newest jax and
    # jax_md, which excludes jax 0.10.2): its results compare with jax_md or record the newest jax.
    peers: bool = False


# The package code behind the numbers, by concept (see README's layout); each job names the groups
# it measures and its own script.
BASE = (
    "jaxrot/_core",
    "jaxrot/quaternion.py",
    "jaxrot/_state.py",
    "jaxrot/_inertia.py",
    "jaxrot/_particles.py",
    "jaxrot/_validation.py",
    "jaxrot/torques.py",
    "jaxrot/_integrate",
    "jaxrot/schemes/__init__.py",
    "jaxrot/schemes/_base.py",
    "jaxrot/comparison/_timing.py",
)
ROTOR = ("jaxrot/_free_body",)
VACUUM = (
    *ROTOR,
    *(
        f"jaxrot/schemes/{name}.py"
        for name in (
            "_charts _lie_runge_kutta _rkn_splitting zhao rozmanov euler no_squish splitting rkmk4 "
            "rkmk_dopri5 rkmk_dopri8 srkn6b srkn14a"
        ).split()
    ),
)
FLUID = (
    "jaxrot/_fluid",
    "jaxrot/comparison/_fluid.py",
    *(
        f"jaxrot/schemes/{name}.py"
        for name in "_exponential _phi _overdamped exp_midpoint exp_rk4 exp_rk5".split()
    ),
)
THERMAL = (
    *ROTOR,
    "jaxrot/comparison/_thermal.py",
    "jaxrot/comparison/_thermal_problems.py",
    "jaxrot/comparison/_weak.py",
    *(
        f"jaxrot/schemes/{name}.py"
        for name in "_langevin _ou _noise _brownian _heat_kernel baoab exp_euler".split()
    ),
)
DIFFRAX = ("jaxrot/_diffrax",)
SCENES = ("jaxrot/scenes", "jaxrot/analytic.py")
FIT = ("jaxrot/_fit", "tests/_telemetry.py")
JAX_MD = (*BASE, *VACUUM, *THERMAL, *FLUID, "jaxrot/jax_md", "benchmarks/jax_md_systems.py")
