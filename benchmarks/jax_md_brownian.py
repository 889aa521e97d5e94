"""jaxrot.jax_md.brownian's checks as numbers: free rotational diffusion per body axis against Favro's
closed forms, the centres' spread, and dipoles in a field against the Langevin function (accuracy
only: no timing).

On jax_md's stretched tetrahedra (benchmarks/jax_md_systems.py), free: rotational friction per body
axis ``(1, 2, 4)`` (``rotational_friction=``; ``D = kT/ζ = (1, 1/2, 1/4)``), ``gamma_c = 0.5`` (the
centres' ``D = kT/(m γ) = 1/2``), kT = 1, dt = 0.05: ``⟨P₁⟩``, ``⟨P₂⟩`` of each body axis at t = 0.5, 1,
2 against Favro (Phys. Rev. 119, 53 (1960)), ``⟨|ΔR|²⟩ / (6 D t)``; and dipoles (body x) in a field
along z of ``μB/kT`` = 0.5, 2, 8 with jax_md's gamma convention (G = 1), dt = 0.02: ``⟨cos θ⟩`` against
``L(μB/kT)``. Each with its standard error over the (independent) bodies.

Needs jax_md (Python 3.12)::

    python benchmarks/jax_md_brownian.py            # writes docs/jax_md_brownian.json
    python benchmarks/jax_md_brownian.py --quick    # 1000 bodies, printed, nothing written
    python benchmarks/regenerate.py --only jax_md_brownian --python /path/to/py312/bin/python
"""

import argparse
import importlib.metadata
import json
import sys
from pathlib import Path

import jax


jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from jaxrot import quaternion as quat  # noqa: E402
from jaxrot.comparison import machine_info  # noqa: E402


try:
    from jax_md import rigid_body
    from jax_md_systems import favro, free_energy, free_system, shape

    import jaxrot.jax_md as jm
except ImportError:  # regenerate.py's other jobs run on Python 3.11, where jax_md is not installed
    print(
        "jax_md is not installed: docs/jax_md_brownian.json is left as it is (Python 3.12)", file=sys.stderr
    )
    sys.exit(0)


ROOT = Path(__file__).resolve().parents[1]
KT, FRICTION, GAMMA_CENTRE = 1.0, (1.0, 2.0, 4.0), 0.5
TIMES, FREE_DT = (0.5, 1.0, 2.0), 0.05
FIELDS, DIPOLE_DT = (0.5, 2.0, 8.0), 0.02


def mean_error(x):
    x = np.asarray(x)
    return x.mean(axis=0).tolist(), (x.std(axis=0, ddof=1) / np.sqrt(len(x))).tolist()


def free_rows(n):
    _, shift, body = free_system(n)
    init_fn, apply_fn = jm.brownian(
        free_energy, shift, FREE_DT, KT, rigid_body.RigidBody(GAMMA_CENTRE, 1.0),
        rotational_friction=jnp.asarray(FRICTION),
    )  # fmt: skip
    start = init_fn(jax.random.key(2), body, mass=shape().mass())
    run = jax.jit(lambda s, k: jax.lax.fori_loop(0, k, lambda i, s_: apply_fn(s_), s))
    rotation = jax.vmap(quat.to_matrix)
    r0 = np.asarray(rotation(start.position.orientation.vec))
    rows = []
    for t in TIMES:
        end = run(start, round(t / FREE_DT))
        m = np.einsum("nai,naj->nij", r0, np.asarray(rotation(end.position.orientation.vec)))
        cosines = np.stack([m[:, k, k] for k in range(3)], axis=1)
        p1, p2 = favro(KT / np.asarray(FRICTION), t)
        (p1_mean, p1_err), (p2_mean, p2_err) = mean_error(cosines), mean_error(1.5 * cosines**2 - 0.5)
        squared = np.sum((np.asarray(end.position.center) - np.asarray(start.position.center)) ** 2, axis=1)
        scale = 6 * KT / (4.0 * GAMMA_CENTRE) * t
        row = {"t": t, "bodies": n, "dt": FREE_DT, "p1": p1_mean, "p1_error": p1_err, "p1_favro": p1.tolist(),
               "p2": p2_mean, "p2_error": p2_err, "p2_favro": p2.tolist(),
               "msd_over_6Dt": float(squared.mean() / scale),
               "msd_over_6Dt_error": float(squared.std(ddof=1) / np.sqrt(n) / scale)}  # fmt: skip
        rows.append(row)
        line = f"t={t}: P1 {np.round(p1_mean, 4)} (Favro {np.round(p1, 4)}) P2 {np.round(p2_mean, 4)}"
        line += f" (Favro {np.round(p2, 4)}) msd/6Dt {row['msd_over_6Dt']:.4f}"
        print(line, file=sys.stderr, flush=True)
    return rows


def dipole_energy(position, field, **kwargs):
    axis = rigid_body.quaternion_rotate(position.orientation, jnp.array([1.0, 0.0, 0.0]))
    return -field * jnp.sum(axis[:, 2])


def dipole_rows(n):
    rows = []
    _, shift, body = free_system(n)
    init_fn, apply_fn = jm.brownian(dipole_energy, shift, DIPOLE_DT, KT, 1.0)

    @jax.jit  # one program for every field: the field reaches the energy as apply_fn's keyword
    def run(state, field):
        def snapshot(s, _):
            s = jax.lax.fori_loop(0, 50, lambda i, s_: apply_fn(s_, field=field), s)
            return s, rigid_body.quaternion_rotate(s.position.orientation, jnp.array([1.0, 0.0, 0.0]))[:, 2]

        state, _ = jax.lax.scan(snapshot, state, None, length=4)
        return jax.lax.scan(snapshot, state, None, length=8)[1]

    for field in FIELDS:
        start = init_fn(jax.random.key(3), body, mass=shape().mass())
        per_body = np.asarray(run(start, jnp.asarray(field))).mean(axis=0)
        expected = 1 / np.tanh(field / KT) - KT / field
        error = float(per_body.std(ddof=1) / np.sqrt(n))
        row = {"field_over_kT": field, "bodies": n, "dt": DIPOLE_DT, "cos": float(per_body.mean()),
               "cos_error": error, "langevin": float(expected)}  # fmt: skip
        rows.append(row)
        print(
            f"muB/kT={field}: <cos> {row['cos']:.4f} ± {row['cos_error']:.4f}, L = {expected:.4f}",
            file=sys.stderr,
        )
    return rows


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--bodies", type=int, default=16000)
    parser.add_argument("--quick", action="store_true", help="1000 bodies, printed, nothing written")
    parser.add_argument("--out", default=str(ROOT / "docs" / "jax_md_brownian.json"))
    args = parser.parse_args(argv)
    n = 1000 if args.quick else args.bodies
    result = {"free": free_rows(n), "dipole": dipole_rows(n)}
    if args.quick:
        return
    info = machine_info()
    info["jax_md"] = importlib.metadata.version("jax-md")
    command = ["python benchmarks/jax_md_brownian.py", *(argv if argv is not None else sys.argv[1:])]
    setting = {"kT": KT, "rotational_friction": list(FRICTION), "gamma_centre": GAMMA_CENTRE, "dipole_G": 1.0}
    result = {"machine": info, "command": " ".join(command), "setting": setting, **result}
    Path(args.out).write_text(json.dumps(result, indent=1) + "\n")
    print(f"wrote {args.out}", file=sys.stderr)


if __name__ == "__main__":
    main()
