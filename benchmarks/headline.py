"""The headline figure: jaxrot's best rows against diffrax's best, on every scene of the race.

Reads a race results file (``docs/race_cpu/race_float64.json``, written by `benchmarks/race.py`)
and draws, per scene, the lower envelope of error against wall time (the rows no faster row
beats in error) of three families: jaxrot's fixed-step schemes, jaxrot's adaptive Lie-group pairs
(``jaxrot_*_pid``) and diffrax's Tsit5, Dopri5 and Dopri8. Each envelope point is labelled by the
method that gives it. Draws only: nothing is timed here.

    python benchmarks/headline.py                  # docs/race_cpu/race_float64.json -> docs/headline.png
"""

import argparse
import json
import math
from pathlib import Path

import matplotlib


matplotlib.use("Agg")
import matplotlib.pyplot as plt


ROOT = Path(__file__).resolve().parents[1]
FAMILIES = {  # label -> (is a member, line style)
    "jaxrot, fixed step": (lambda r: r["kind"] == "fixed", dict(color="C0", marker="o", ls="-")),
    "jaxrot, adaptive (jaxrot.solver)": (
        lambda r: r["kind"] == "adaptive" and r["method"].startswith("jaxrot_"),
        dict(color="C2", marker="^", ls="-"),
    ),
    "diffrax Tsit5 / Dopri5 / Dopri8": (
        lambda r: r["method"].startswith("diffrax_"),
        dict(color="0.45", marker="s", ls="--"),
    ),
}


def envelope(rows):
    """The rows that no faster row beats in error, fastest first."""
    front, best = [], math.inf
    for r in sorted(rows, key=lambda r: r["seconds"]):
        e = r["max_orientation_error_rad"]
        if math.isfinite(e) and e < best:
            front.append(r)
            best = e
    return front


def draw(race, path):
    scenes = list(race["scenes"])
    fig, axes = plt.subplots(
        1, len(scenes), figsize=(4.6 * len(scenes), 4.0), constrained_layout=True, squeeze=False
    )
    axes = axes[0]
    for ax, scene in zip(axes, scenes, strict=True):
        rows = [r for r in race["scenes"][scene]["rows"] if r["max_orientation_error_rad"] <= 1e-1]
        for label, (member, style) in FAMILIES.items():
            front = envelope([r for r in rows if member(r)])
            if front:
                ax.loglog(
                    [r["seconds"] * 1e3 for r in front],
                    [r["max_orientation_error_rad"] for r in front],
                    label=label,
                    ms=4,
                    **style,
                )
        ax.set_title(scene)
        ax.set_xlabel(f"wall time, {rows[0]['particles']} bodies [ms]")
        ax.grid(True, which="major", alpha=0.3)
    axes[0].set_ylabel("largest orientation error [rad]")
    axes[-1].legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), frameon=False)
    m = race["machine"]
    fig.suptitle(
        f"Best rows of each side ({race['options']['dtype']}, {m['cpus']} CPU cores, jax {m['jax']}, "
        f"commit {m['commit']}); lower-left is better",
        fontsize=10,
    )
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--race", default=str(ROOT / "docs" / "race_cpu" / "race_float64.json"))
    parser.add_argument("--out", default=str(ROOT / "docs" / "headline.png"))
    opts = parser.parse_args(argv)
    print(draw(json.loads(Path(opts.race).read_text()), opts.out))


if __name__ == "__main__":
    main()
