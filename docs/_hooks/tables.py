"""mkdocs hook: the measured tables of the docs, rendered from the data files under docs/.

A page writes ``{{ name }}`` of a table in `TABLES` on a line of its own; the hook replaces it
with a Markdown table built from the results files under docs/ (``throughput_cpu.json``,
``race_cpu/``, ``fluid_race_cpu.json``, the GPU results under ``docs/gpu_h100/`` and
``docs/gpu_h200/`` …), so the pages show exactly what the benchmarks wrote; the scheme guide's
table of models is built from the package's own registry (``_tables_schemes.py``). The tables live
beside this file, one module per page or topic (``_tables_*.py``); mkdocs loads a hook by its path,
so their folder goes on ``sys.path`` first.
"""

import sys
from pathlib import Path


sys.path.insert(0, str(Path(__file__).resolve().parent))

from _tables_accuracy import (  # noqa: E402
    float32_horizon_table,
    float32_rotor_table,
    mujoco_free_body_accuracy,
    mujoco_free_body_speed,
    order4_summary,
    order4_table,
    stability_blow_up_table,
    stability_drift_table,
    stability_limits_table,
)
from _tables_energy import energy_drift_table, energy_limits_table, readme_energy_sentence  # noqa: E402
from _tables_fluid import (  # noqa: E402
    fluid_layer_table,
    fluid_orders_table,
    fluid_race_figure,
    fluid_race_notes,
    fluid_race_table,
    fluid_step_cost_table,
    overdamped_cost_table,
)
from _tables_identify import (  # noqa: E402
    identify_capabilities_table,
    identify_speed_table,
    identify_sysid_sensors_table,
    identify_sysid_table,
)
from _tables_jax_md import (  # noqa: E402
    jax_md_brownian_table,
    jax_md_cost_table,
    jax_md_energy_table,
    jax_md_temperature_table,
)
from _tables_mjx import mjx_cost_table, mjx_gradient_table, mjx_orders_table  # noqa: E402
from _tables_performance import (  # noqa: E402
    compile_table,
    cpu_vector_width_table,
    first_call_table,
    gpu_passes_table,
    gpu_peer_throughput_table,
    gpu_race_table,
    gpu_rotor_loop_table,
    gpu_throughput_ratio_table,
    gpu_throughput_table,
    gradient_compile_summary,
    gradient_compile_table,
    memory_table,
    rotor_choice_table,
    throughput_jax_versions,
    throughput_peer_ratios,
    throughput_table,
    ynn_trap_table,
)
from _tables_race import (  # noqa: E402
    compare_budget_table,
    compare_orders,
    compare_table,
    front_door_speed,
    measured,
    race_ratios,
    race_summary,
    race_table_float32,
    race_table_float64,
)
from _tables_schemes import scheme_models_table  # noqa: E402
from _tables_thermal import (  # noqa: E402
    thermal_jax_md_diagnosis,
    thermal_orders_table,
    thermal_peers_table,
)


# The hook's entry point, its tables, and the race's ratios that tests/test_readme.py reads.
__all__ = ["TABLES", "on_page_markdown", "race_ratios", "readme_energy_sentence"]

TABLES = {
    "scheme_models_table": scheme_models_table,
    "fluid_orders_table": fluid_orders_table,
    "fluid_layer_table": fluid_layer_table,
    "fluid_race_figure": fluid_race_figure,
    "fluid_race_table": fluid_race_table,
    "fluid_step_cost_table": fluid_step_cost_table,
    "fluid_race_notes": fluid_race_notes,
    "thermal_orders_table": thermal_orders_table,
    "thermal_orders_gpu_table": lambda docs: thermal_orders_table(docs, "gpu_h200/thermal_orders.json"),
    "thermal_peers_table": thermal_peers_table,
    "thermal_jax_md_diagnosis": thermal_jax_md_diagnosis,
    "jax_md_temperature_table": jax_md_temperature_table,
    "jax_md_energy_table": jax_md_energy_table,
    "jax_md_cost_table": jax_md_cost_table,
    "jax_md_brownian_table": jax_md_brownian_table,
    "throughput_table": throughput_table,
    "compile_table": compile_table,
    "gradient_compile_table": gradient_compile_table,
    "first_call_table": first_call_table,
    "memory_table": memory_table,
    "compare_table": compare_table,
    "compare_budget_table": compare_budget_table,
    "compare_orders": compare_orders,
    "gpu_throughput_table": gpu_throughput_table,
    "gpu_race_table": gpu_race_table,
    "gpu_peer_throughput_table": gpu_peer_throughput_table,
    "gpu_rotor_loop_table": gpu_rotor_loop_table,
    "gpu_throughput_ratio_table": gpu_throughput_ratio_table,
    "gpu_passes_table": gpu_passes_table,
    "cpu_vector_width_table": cpu_vector_width_table,
    "race_table_float64": race_table_float64,
    "race_table_float32": race_table_float32,
    "race_summary": race_summary,
    "stability_limits_table": stability_limits_table,
    "stability_blow_up_table": stability_blow_up_table,
    "stability_drift_table": stability_drift_table,
    "energy_limits_table": energy_limits_table,
    "energy_drift_table": energy_drift_table,
    "readme_energy_sentence": readme_energy_sentence,
    "identify_speed_table": identify_speed_table,
    "identify_sysid_table": identify_sysid_table,
    "identify_sysid_sensors_table": identify_sysid_sensors_table,
    "identify_capabilities_table": identify_capabilities_table,
    "overdamped_cost_table": overdamped_cost_table,
    "order4_table": order4_table,
    "float32_horizon_table": float32_horizon_table,
    "float32_rotor_table": float32_rotor_table,
    "order4_summary": order4_summary,
    "rotor_choice_table": rotor_choice_table,
    "mujoco_free_body_accuracy": mujoco_free_body_accuracy,
    "mujoco_free_body_speed": mujoco_free_body_speed,
    "mjx_orders_table": mjx_orders_table,
    "mjx_cost_table": mjx_cost_table,
    "mjx_gradient_table": mjx_gradient_table,
    "throughput_peer_ratios": throughput_peer_ratios,
    "throughput_jax_versions": throughput_jax_versions,
    "ynn_trap_table": ynn_trap_table,
    "measured": measured,
    "front_door_speed": front_door_speed,
    "gradient_compile_summary": gradient_compile_summary,
}


def on_page_markdown(markdown, page, config, files):
    """Replace each ``{{ name }}`` (or ``{{ name argument }}``) line naming a table in `TABLES` by
    that table."""
    docs = Path(config["docs_dir"])
    lines = markdown.split("\n")
    for i, line in enumerate(lines):
        stripped = line.strip()
        if stripped.startswith("{{") and stripped.endswith("}}"):
            name, *arguments = stripped[2:-2].split()
            if name not in TABLES:
                raise KeyError(
                    f"{page.file.src_path}: unknown table {{{{ {name} }}}}; known: {sorted(TABLES)}"
                )
            indent = line[: len(line) - len(line.lstrip())]
            lines[i] = "\n".join(indent + row for row in TABLES[name](docs, *arguments).split("\n"))
    return "\n".join(lines)
