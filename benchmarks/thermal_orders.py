"""Weak orders of the thermal schemes, measured: docs/thermal_orders.json (accuracy only, no timing).

For each scheme of `jaxrot.THERMAL_SCHEMES` (underdamped Langevin) and `jaxrot.BROWNIAN_SCHEMES`
(overdamped), and each oracle, the bias of an ensemble average at six steps, each half the last,
with one refined Brownian path per body for all six (`jaxrot.comparison._weak`: coupled levels, so the
differences between levels carry small statistical errors); the weak order is the slope of
``log |E_h − E_{h/2}|`` against ``log h`` over the levels where that difference exceeds three standard
errors, and the finest level extrapolated by Richardson's rule is compared with the closed form. The
local orders ``log2(d(h)/d(h/2))`` of each pair of resolved differences show where the asymptotic
order sets in (the fit over every level mixes in the coarse, pre-asymptotic ones).

- (a) equipartition, ``⟨I_k ω_k²⟩ = kT`` per body axis (Langevin schemes), and (b) a dipole in a field,
  ``⟨cos θ⟩ = coth x − 1/x`` at ``x = 2``: bodies started from the exact Boltzmann (and Maxwell) law,
  averaged over the second half of the run (t = 8 underdamped: inertia (1, 2, 3), friction 2;
  t = 4 overdamped: friction (1, 1.5, 2)); kT = 1; and the issue-60 body, the underdamped dipole
  with friction 1 ("dipole ζ=1").
- (c) free rotational diffusion, ``⟨e_i(t)·e_i(0)⟩`` at t = 1 from the identity: a sphere
  (``e^{−2Dt}``, D = 1) and a triaxial body (D = (1, 0.5, 0.25): Favro's ``exp(−(D_j + D_k) t)``) for
  the Brownian schemes; a triaxial Langevin body (inertia (1, 2, 3), friction 2), whose correlation
  has no closed form: there the limit of each scheme is recorded (the two schemes must agree).

    python benchmarks/thermal_orders.py --bodies 20000   # the published file: about 5 min on 2 cores
    python benchmarks/thermal_orders.py                  # 2**21 bodies: for a GPU
    python benchmarks/thermal_orders.py --quick          # 2000 bodies, to stdout, nothing written
    python benchmarks/thermal_orders.py --bodies 2097152 --schemes baoab --cases "dipole,dipole ζ=1" \
        --out docs/gpu_h200/thermal_orders_baoab.json     # BAOAB's weak order on the torqued body, GPU

The published file's command and machine are in it; with 20000 bodies its statistical floor is
about 1e-3 of an average's scale (the standard errors are in the file and the table).
"""

import argparse
import json
import sys
import time
from pathlib import Path

import jax


jax.config.update("jax_enable_x64", True)

import numpy as np

import jaxrot
from jaxrot.comparison import _thermal_problems as problems, _weak as weak, machine_info


ROOT = Path(__file__).resolve().parents[1]
# The torqued body (issue 60): the dipole at x = 2 with half the friction, ζ/I from 1/3 to 1.
DIPOLE_WEAK_FRICTION = problems.ThermalSetting((1.0, 1.0, 1.0), (1.0, 2.0, 3.0), 1.0, 2.0)
N_FINE = 256
COARSENINGS = (32, 16, 8, 4, 2, 1)

# (scheme family, label, setting, t_end, averaged over the second half?, quantity names, oracle letters)
CASES = {
    "langevin": [
        ("dipole", problems.DIPOLE_INERTIAL, 8.0, True,
         ["<cos θ>", "<I1 ω1²>/kT", "<I2 ω2²>/kT", "<I3 ω3²>/kT"], ["b", "a", "a", "a"]),
        ("dipole ζ=1", DIPOLE_WEAK_FRICTION, 8.0, True,
         ["<cos θ>", "<I1 ω1²>/kT", "<I2 ω2²>/kT", "<I3 ω3²>/kT"], ["b", "a", "a", "a"]),
        ("free triaxial", problems.FREE_INERTIAL, 1.0, False,
         ["<e1(t)·e1(0)>", "<e2(t)·e2(0)>", "<e3(t)·e3(0)>"], ["c", "c", "c"]),
    ],
    "brownian": [
        ("dipole", problems.DIPOLE_OVERDAMPED, 4.0, True, ["<cos θ>"], ["b"]),
        ("free sphere", problems.FREE_SPHERE, 1.0, False, ["<e1(t)·e1(0)>", "<e2(t)·e2(0)>", "<e3(t)·e3(0)>"],
         ["c", "c", "c"]),
        ("free triaxial", problems.FREE_OVERDAMPED, 1.0, False,
         ["<e1(t)·e1(0)>", "<e2(t)·e2(0)>", "<e3(t)·e3(0)>"], ["c", "c", "c"]),
    ],
}  # fmt: skip


def schemes():
    for name, scheme in jaxrot.THERMAL_SCHEMES.items():
        yield name, scheme, "langevin"
    for name, scheme in jaxrot.BROWNIAN_SCHEMES.items():
        yield name, scheme, "brownian"


def measure(n_bodies, only=None, on_case=None, cases=None):
    """The rows of every (scheme, case); ``on_case(rows)`` after each case (a partial results file);
    ``only`` and ``cases``: the scheme names and case labels to run (None: all)."""
    rows = []
    for name, scheme, family in schemes():
        if only and name not in only:
            continue
        for label, setting, t_end, averaged, quantities, letters in CASES[family]:
            if cases and label not in cases:
                continue
            start = time.perf_counter()
            largest_dt = t_end / N_FINE * COARSENINGS[0]
            problem = problems.problem(scheme, setting, n_bodies, jax.random.key(1), largest_dt=largest_dt)
            ladder = weak.ladder(
                problem, jax.random.key(2), t_end / N_FINE, N_FINE, COARSENINGS, 0.5 if averaged else 1.0
            )
            exact = problems.oracle(setting, t_end)
            seconds = time.perf_counter() - start
            for k, quantity in enumerate(quantities):
                order, order_err = weak.fit_order(ladder, k)
                local = weak.local_orders(ladder, k)
                limit, limit_err = weak.extrapolated(ladder, order if np.isfinite(order) else scheme.order)
                rows.append(
                    {
                        "scheme": name,
                        "family": family,
                        "nominal_order": scheme.order,
                        "oracle": letters[k],
                        "setting": label,
                        "quantity": quantity,
                        "t_end": t_end,
                        "averaged_over_second_half": averaged,
                        "exact": None if not np.isfinite(exact[k]) else float(exact[k]),
                        "dt": ladder.dt.tolist(),
                        "mean": ladder.mean[:, k].tolist(),
                        "stderr": ladder.stderr[:, k].tolist(),
                        "difference": ladder.difference[:, k].tolist(),
                        "difference_stderr": ladder.difference_stderr[:, k].tolist(),
                        "order": None if not np.isfinite(order) else order,
                        "order_stderr": None if not np.isfinite(order_err) else order_err,
                        "local_orders": [None if p is None else list(p) for p in local],
                        "limit": float(limit[k]),
                        "limit_stderr": float(limit_err[k]),
                        "seconds": seconds,
                    }
                )
            print(f"{name:<20} {label:<14} {seconds:6.1f} s", file=sys.stderr, flush=True)
            if on_case is not None:
                on_case(rows)
    return rows


def table(rows):
    lines = [
        f"{'scheme':<19} {'oracle':<3} {'quantity':<15} {'setting':<14} {'order':>12} "
        f"{'bias at dt (coarsest .. finest)':<46} {'limit - exact':>18}  local orders (coarse .. fine)"
    ]
    for r in rows:
        order = "exact?" if r["order"] is None else f"{r['order']:.2f}±{r['order_stderr']:.2f}"
        if r["exact"] is None:
            bias = "n/a (no closed form)"
            gap = f"limit {r['limit']:.4f}±{r['limit_stderr']:.0e}"
        else:
            bias = " ".join(f"{m - r['exact']:+.1e}" for m in r["mean"][::2])
            gap = f"{r['limit'] - r['exact']:+.1e}±{r['limit_stderr']:.0e}"
        local = " ".join("—" if p is None else f"{p[0]:.2f}±{p[1]:.2f}" for p in r["local_orders"])
        lines.append(
            f"{r['scheme']:<19} {r['oracle']:<3} {r['quantity']:<15} {r['setting']:<14} {order:>12} "
            f"{bias:<46} {gap:>18}  {local}"
        )
    return "\n".join(lines)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--bodies", type=int, default=2**21)
    parser.add_argument("--quick", action="store_true", help="2000 bodies, print only")
    parser.add_argument("--schemes", default=None, help="comma-separated names (default: all)")
    parser.add_argument("--cases", default=None, help="comma-separated case labels, e.g. 'dipole ζ=1'")
    parser.add_argument("--out", default=str(ROOT / "docs" / "thermal_orders.json"))
    args = parser.parse_args(argv)
    n_bodies = 2000 if args.quick else args.bodies
    only = None if args.schemes is None else set(args.schemes.split(","))
    start = time.perf_counter()
    cases = None if args.cases is None else set(args.cases.split(","))
    command = "python benchmarks/thermal_orders.py " + " ".join(argv if argv is not None else sys.argv[1:])

    def write(rows, final):
        """The results file; after each case as well (``"partial": true``), so a run stopped early
        (a GPU's time limit) leaves what finished."""
        result = {
            "machine": machine_info(),
            "command": command,
            "bodies": n_bodies,
            "fine_steps": N_FINE,
            "coarsenings": list(COARSENINGS),
            "dtype": "float64",
            "seconds": time.perf_counter() - start,
            "rows": rows,
        }
        if not final:
            result["partial"] = True
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(json.dumps(result, indent=1) + "\n")

    rows = measure(n_bodies, only, on_case=None if args.quick else lambda r: write(r, False), cases=cases)
    print(table(rows))
    if args.quick:
        return
    write(rows, True)
    print(f"wrote {args.out}", file=sys.stderr)


if __name__ == "__main__":
    main()
