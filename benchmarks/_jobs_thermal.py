"""The jobs of `regenerate.py` that measure bodies in a heat bath: the thermal schemes' weak orders,
their biases and cost against jax_md and diffrax, and `jaxrot.jax_md` against jax_md and closed forms."""

from _job import BASE, DIFFRAX, FLUID, JAX_MD, THERMAL, Job


THERMAL_JOBS = {
    # Accuracy only (weak orders of the thermal schemes): no timing, any machine; long on 2 cores.
    "thermal_orders": Job(
        ("thermal_orders.json",),
        # 20000 bodies: at 8000 the splitting's dipole fit and baoab's ⟨I2 ω2²⟩ fits (docs/thermal.md
        # quotes them) fall below noise, and ⟨cos θ⟩'s fits widen to ±0.12-0.13 against the ±0.3 band.
        # CPU time (user + sys), 2026-11-29 under a load of ~15: 64 s at 2000 bodies, 134 s at 8000, so
        # 41 s + 11.6 ms per body: 273 s at 20000, 2.3 min on 2 quiet cores (4.6 on one).
        ("benchmarks/thermal_orders.py", "--bodies", "20000"),
        2.6,
        quick=("benchmarks/thermal_orders.py", "--bodies", "2000", "--out", "{tmp}/thermal_orders.json"),
        quick_minutes=1,
        tables=("thermal_orders_table",),
        sources=(*BASE, *THERMAL, *FLUID, "benchmarks/thermal_orders.py"),
        timed=False,
    ),
    # Biases against dt and, timed, the cost per body-step against jax_md (Python 3.12) and diffrax.
    "thermal_peers": Job(
        ("thermal_peers.json",),
        # Sized as it was: 16384 bodies keep the biases' 2σ (~0.006) inside the cost table's 0.01 budget.
        # Python 3.12 with jax_md, 2026-11-29 (load ~17): 230 CPU-s in all (the 16 bias rows 142), so
        # 2-4 min on 2 quiet cores (25 were listed).
        ("benchmarks/thermal_peers.py", "--timing"),
        3.1,
        quick=(
            "benchmarks/thermal_peers.py",
            "--bodies",
            "2048",
            "--timing",
            "--out",
            "{tmp}/thermal_peers.json",
        ),
        quick_minutes=2,
        tables=("thermal_peers_table",),
        sources=(*BASE, *THERMAL, *FLUID, *DIFFRAX, "benchmarks/thermal_peers.py"),
        peers=True,
    ),
    # jaxrot.jax_md against jax_md's rigid-body nvt_langevin / nve: temperature per axis against dt, energy
    # error, cost per body-step (Python 3.12 with jax_md: --peers-python <venv312>/bin/python).
    "jax_md_rigid": Job(
        ("jax_md_cpu.json", "jax_md_cpu.png"),
        ("benchmarks/jax_md_rigid.py",),
        # 243 CPU-s (user+sys) in a full run under heavy load (2026-11-29; its temperatures and
        # energies equal the published file's to 1e-13): 2.0 min on 2 quiet cores, 4.1 at one core.
        2.7,
        # The cost table alone (free, interacting, first call), printed.
        quick=("benchmarks/jax_md_rigid.py", "--quick", "--out", "{tmp}/jax_md_cpu.json"),
        quick_minutes=4,
        tables=("jax_md_cost_table",),
        sources=JAX_MD + ("benchmarks/jax_md_rigid.py",),
        peers=True,
    ),
    # jaxrot.jax_md.brownian against closed forms (Favro per body axis, 2dDt, the Langevin function):
    # accuracy only (Python 3.12 with jax_md: --peers-python <venv312>/bin/python).
    "jax_md_brownian": Job(
        ("jax_md_brownian.json",),
        ("benchmarks/jax_md_brownian.py",),
        # One program for the three dipole fields (was three): 244 CPU-s in all, 2026-11-29 (load ~17),
        # the file's numbers unchanged to the last digit: 2-4 min on 2 quiet cores.
        2.2,
        quick=("benchmarks/jax_md_brownian.py", "--quick", "--out", "{tmp}/jax_md_brownian.json"),
        quick_minutes=1,
        sources=JAX_MD + ("benchmarks/jax_md_brownian.py",),
        timed=False,
        peers=True,
    ),
}
