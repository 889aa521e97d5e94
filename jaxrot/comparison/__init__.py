"""Measuring the speed/accuracy trade: ``python -m jaxrot compare`` and what the benchmarks share.

The deterministic ladder (`compare`: every scheme at a ladder of steps, diffrax's adaptive solvers
at a ladder of tolerances, against a tight reference), the fluid race's runners and the thermal
comparison's weak errors, the weak-error ladder and its problems, and the timing, provenance and
report of the rows. Private modules, one concept each; this face lists the public names.

Example:
    >>> import jax; jax.config.update("jax_enable_x64", True)
    >>> from jaxrot import comparison
    >>> rows = comparison.compare(t_end=0.5, particles=2, coarse_steps=10, levels=2, schemes=["zhao"],
    ...                           solvers=["diffrax_tsit5"], tolerances=(1e-6,), repeats=1, progress=False)
    >>> [(r["method"], r["n_steps"]) for r in rows]
    [('zhao', 10), ('zhao', 20), ('diffrax_tsit5', 8)]
    >>> print(comparison.format_recommendation(rows))  # doctest: +ELLIPSIS
    fastest within error budget [rad] ...
"""

from ._ladder import (
    ADAPTIVE_SOLVERS as ADAPTIVE_SOLVERS,
    DTYPES as DTYPES,
    LADDER_FLOOR as LADDER_FLOOR,
    MAX_RUN_S as MAX_RUN_S,
    MAX_SATURATED_RUNGS as MAX_SATURATED_RUNGS,
    REFERENCE_TOL as REFERENCE_TOL,
    TOLERANCES as TOLERANCES,
    compare as compare,
    orientation_error as orientation_error,
    relative_energy_drift as relative_energy_drift,
)
from ._provenance import (
    RESULTS_SCHEMA as RESULTS_SCHEMA,
    machine_info as machine_info,
)
from ._report import (
    ASYMPTOTIC_ERROR as ASYMPTOTIC_ERROR,
    budget_table as budget_table,
    fit_order as fit_order,
    format_budget_table as format_budget_table,
    format_recommendation as format_recommendation,
    format_table as format_table,
    measured_orders as measured_orders,
    plot_work_precision as plot_work_precision,
    recommend as recommend,
    setting_label as setting_label,
    stalled as stalled,
    write_outputs as write_outputs,
)
from ._timing import (
    MIN_TIMED_S as MIN_TIMED_S,
    compile_timed as compile_timed,
    time_compiled as time_compiled,
    time_runs as time_runs,
)


__all__ = [
    "ADAPTIVE_SOLVERS",
    "ASYMPTOTIC_ERROR",
    "DTYPES",
    "LADDER_FLOOR",
    "MAX_RUN_S",
    "MAX_SATURATED_RUNGS",
    "MIN_TIMED_S",
    "REFERENCE_TOL",
    "RESULTS_SCHEMA",
    "TOLERANCES",
    "budget_table",
    "compare",
    "compile_timed",
    "fit_order",
    "format_budget_table",
    "format_recommendation",
    "format_table",
    "machine_info",
    "measured_orders",
    "orientation_error",
    "plot_work_precision",
    "recommend",
    "relative_energy_drift",
    "setting_label",
    "stalled",
    "time_compiled",
    "time_runs",
    "write_outputs",
]
