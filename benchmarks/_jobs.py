"""The jobs of `regenerate.py`: each benchmark's command, the results files it writes, its expected
time (full and quick) and the sources its numbers depend on.

The jobs are grouped by where the bodies are (one module each); JOBS keeps the order `--list` prints."""

from _job import Job  # noqa: F401  (regenerate.py imports it from here)
from _jobs_fluid import FLUID_JOBS
from _jobs_thermal import THERMAL_JOBS
from _jobs_vacuum import RACE, ROTOR_JOBS, VACUUM_JOBS  # noqa: F401  (RACE: tests/test_regenerate.py)


JOBS = {**VACUUM_JOBS, **THERMAL_JOBS, **ROTOR_JOBS, **FLUID_JOBS}
