"""The scheme guide's first table (docs/schemes/index.md): which call and which schemes for which body.

Rendered from the package itself, not from a results file: the schemes of each model are
`jaxrot.schemes_for(model)` in registry order, the defaults those of the binder
(`jaxrot._integrate._bind`), so a scheme registered, moved to another model or made a default
shows here on the next build. A model without a row here, a view that disagrees with
`jaxrot.schemes_for`, or a scheme without its page under docs/schemes/ fails the build.
"""

from _tables_format import _table


# The models in the guide's words, by the call that runs them; `scheme` stands for a name of the row.
_ROWS = {
    "vacuum": ("a body in vacuum", "jaxrot.rollout(scheme, state, inertia, dt, n_steps)", "SCHEMES"),
    "fluid": (
        "in a fluid (friction, a flow; kT = 0)",
        "jaxrot.rollout(scheme, ..., fluid=jaxrot.Fluid(friction))",
        "FLUID_SCHEMES",
    ),
    "thermal": (
        "in a fluid at a temperature (Langevin)",
        "jaxrot.rollout(scheme, ..., fluid=jaxrot.Fluid(friction, kT=kT), key=key)",
        "THERMAL_SCHEMES",
    ),
    "overdamped": (
        "no inertia, in a fluid (overdamped; kT = 0)",
        "jaxrot.overdamped_rollout(q, fluid, dt, n_steps, scheme=scheme)",
        "OVERDAMPED_SCHEMES",
    ),
    "brownian": (
        "no inertia, at a temperature (Brownian)",
        "jaxrot.overdamped_rollout(q, jaxrot.Fluid(friction, kT=kT), dt, n_steps, scheme=scheme, key=key)",
        "BROWNIAN_SCHEMES",
    ),
}


def scheme_models_table(docs):
    """One row per model of `jaxrot.schemes.MODELS`: the body, the call, its schemes (each linking to
    its page, with its order) and the default scheme of the call where it has one."""
    import jaxrot
    from jaxrot._integrate._bind import DEFAULT_BROWNIAN, DEFAULT_OVERDAMPED
    from jaxrot.schemes import MODELS, THERMAL_MODELS

    if tuple(_ROWS) != tuple(MODELS):
        raise ValueError(f"_tables_schemes.py describes the models {list(_ROWS)}; jaxrot has {MODELS}")
    defaults = {"overdamped": DEFAULT_OVERDAMPED, "brownian": DEFAULT_BROWNIAN}
    rows = []
    for model, (body, call, view) in _ROWS.items():
        schemes = jaxrot.schemes_for(model)
        if list(getattr(jaxrot, view)) != list(schemes):
            raise ValueError(f"jaxrot.{view} disagrees with jaxrot.schemes_for({model!r})")
        missing = [name for name in schemes if not (docs / "schemes" / f"{name}.md").is_file()]
        if missing:
            raise ValueError(f"schemes without a page under docs/schemes/: {missing}")
        kind = "weak order" if model in THERMAL_MODELS else "order"
        cells = [f"[`{name}`]({name}.md) ({kind} {scheme.order})" for name, scheme in schemes.items()]
        default = defaults.get(model)
        rows.append(
            [
                f'{body}<br>`"{model}"`, `jaxrot.{view}`',
                f"`{call}`",
                ", ".join(cells),
                "—" if default is None else f"[`{default}`]({default}.md)",
            ]
        )
    return _table(["body (model)", "call", "schemes", "default"], rows)
