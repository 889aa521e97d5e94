"""Command line: ``python -m jaxrot compare``."""

import argparse
import sys
import time


def _names(option):
    """A comma-separated option as a list (``none`` → empty), or None when not given."""
    return None if option is None else [x for x in option.split(",") if x not in ("", "none")]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m jaxrot", description="jaxrot command line")
    sub = parser.add_subparsers(dest="command", required=True)
    cmp = sub.add_parser(
        "compare",
        help="speed/accuracy of every scheme against the diffrax reference on a built-in scene",
    )
    cmp.add_argument("--scene", default="heavy_top", help="built-in scene (default: heavy_top)")
    cmp.add_argument("--list-scenes", action="store_true", help="list the built-in scenes and exit")
    cmp.add_argument("--t-end", type=float, default=None, help="horizon (default: the scene's)")
    cmp.add_argument(
        "--particles",
        type=int,
        default=None,
        help="vmapped bodies each timed run advances (default 100; a thermal scene's ensemble: 4096)",
    )
    cmp.add_argument(
        "--dtype",
        choices=("float32", "float64"),
        default="float64",
        help="dtype of the runs (default float64)",
    )
    cmp.add_argument("--coarse-steps", type=int, default=5, help="steps of the coarsest rung (default 5)")
    cmp.add_argument(
        "--levels",
        type=int,
        default=8,
        help="rungs at or below 0.1 rad of each dt ladder, each halving dt (default 8)",
    )
    cmp.add_argument(
        "--schemes", default=None, help="comma-separated subset of the schemes (default: all registered)"
    )
    cmp.add_argument(
        "--solvers",
        default=None,
        help="subset of diffrax_tsit5,diffrax_dopri5,diffrax_dopri8 (and diffrax_kvaerno5 in a fluid), "
        "or none (default: all)",
    )
    cmp.add_argument(
        "--tolerances",
        default=None,
        help="comma-separated rtol = atol of the adaptive rows (default by dtype)",
    )
    cmp.add_argument("--repeats", type=int, default=3, help="timed repeats per rung (median; default 3)")
    cmp.add_argument("--out", default="jaxrot_compare", help="output folder for CSV/JSON/PNG")
    cmp.add_argument("--no-plot", action="store_true", help="skip the PNG")
    ns = parser.parse_args(argv)

    for name in ("particles", "coarse_steps", "levels", "repeats"):
        if getattr(ns, name) is not None and getattr(ns, name) < 1:
            parser.error(f"--{name.replace('_', '-')} must be >= 1")

    import jax

    jax.config.update("jax_enable_x64", True)
    from .scenes import FLUID_SCENES, SCENES, THERMAL_SCENES

    if ns.list_scenes:
        for name, factory in {**SCENES, **FLUID_SCENES, **THERMAL_SCENES}.items():
            scene = factory()
            print(f"{name:<26} {scene.n_bodies:>4} bodies  {scene.description}")
        return 0
    if ns.scene in THERMAL_SCENES:  # weak errors of ensemble averages: `jaxrot.comparison._thermal`
        from .comparison._thermal import main_thermal

        return main_thermal(ns, parser)
    ns.particles = 100 if ns.particles is None else ns.particles
    from .comparison import compare, format_table, machine_info, write_outputs

    if ns.scene in FLUID_SCENES:  # its own rows: the fluid schemes, the overdamped ones, Kvaerno5
        from .comparison._fluid import compare_fluid as compare

    start = time.perf_counter()
    try:
        rows = compare(
            ns.scene,
            t_end=ns.t_end,
            particles=ns.particles,
            dtype=ns.dtype,
            coarse_steps=ns.coarse_steps,
            levels=ns.levels,
            repeats=ns.repeats,
            schemes=_names(ns.schemes),
            solvers=_names(ns.solvers),
            tolerances=None if ns.tolerances is None else [float(x) for x in _names(ns.tolerances)],
        )
    except ValueError as err:
        parser.error(str(err))
    info = machine_info()
    reference = (
        "a fine float64 run of exp_rk4 (or of the overdamped rkmk4)"
        if ns.scene in FLUID_SCENES
        else "diffrax Dopri8 rtol=atol=1e-13 in float64"
    )
    particles = rows[0]["particles"]
    print(f"jaxrot compare — scene {ns.scene}; {ns.dtype}; {particles} particles; reference {reference}")
    print(", ".join(f"{k} {v}" for k, v in info.items()))
    written = write_outputs(rows, ns.out, plot=not ns.no_plot)  # first: a long run is never lost
    print(format_table(rows))
    for path in written:
        print(f"wrote {path}")
    print(f"total {time.perf_counter() - start:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
