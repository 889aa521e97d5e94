"""`python -m jaxrot compare`: end to end at a tiny size, and its numbers checked independently."""

import csv
import json
import math
import subprocess
import sys
from typing import ClassVar

import diffrax
import jax
import jax.numpy as jnp
import pytest

import jaxrot
from jaxrot import comparison, quaternion as quat
from jaxrot._diffrax._reference import adaptive_solve
from jaxrot.comparison import (
    ADAPTIVE_SOLVERS,
    budget_table,
    compare,
    fit_order,
    format_budget_table,
    format_recommendation,
    measured_orders,
    recommend,
    stalled,
)
from jaxrot.schemes.euler import Euler


@pytest.mark.slow
def test_cli_runs_end_to_end_and_writes_table_csv_json_png(tmp_path):
    out = tmp_path / "out"
    # fmt: off
    command = [
        sys.executable, "-m", "jaxrot", "compare", "--coarse-steps", "20", "--levels", "3", "--repeats", "1",
        "--t-end", "1.0", "--particles", "3", "--dtype", "float32", "--schemes", "zhao,euler",
        "--solvers", "diffrax_tsit5", "--tolerances", "1e-3,1e-5", "--out", str(out),
    ]
    # fmt: on
    proc = subprocess.run(command, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    assert "max q err[rad]" in proc.stdout
    assert "fastest within error budget" in proc.stdout
    rows = list(csv.DictReader((out / "compare.csv").read_text().splitlines()))
    fixed = [r for r in rows if r["kind"] == "fixed"]
    assert [r["method"] for r in fixed][:3] == ["zhao"] * 3
    for name in ("zhao", "euler"):
        # Each ladder halves dt until `--levels` of its rungs are within 0.1 rad: zhao from the
        # first rung, first-order euler after its rungs above 0.1 rad.
        ladder = [r for r in fixed if r["method"] == name]
        assert [int(r["n_steps"]) for r in ladder] == [20 * 2**k for k in range(len(ladder))]
        errors = [float(r["max_orientation_error_rad"]) for r in ladder]
        assert sum(e <= 0.1 for e in errors) == 3 and errors[-1] <= 0.1 and errors[-2] <= 0.1
    assert len([r for r in fixed if r["method"] == "euler"]) > 3  # it started above 0.1 rad
    adaptive = [r for r in rows if r["kind"] == "adaptive"]
    tolerances = [(r["method"], float(r["tol"])) for r in adaptive]
    assert tolerances == [("diffrax_tsit5", 1e-3), ("diffrax_tsit5", 1e-5)]
    assert {r["dtype"] for r in rows} == {"float32"} and {r["particles"] for r in rows} == {"3"}
    for r in rows:
        for column in ("max_orientation_error_rad", "rel_energy_drift", "us_per_particle_step", "compile_s"):
            assert math.isfinite(float(r[column])) and float(r[column]) >= 0, (r["method"], column)
    for name in ("zhao", "euler"):
        assert f"measured order ({name})" in proc.stdout
    saved = json.loads((out / "compare.json").read_text())
    assert saved["machine"]["jax"] and saved["recommendation"]
    assert (out / "compare.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_cli_rejects_an_unknown_scene():
    proc = subprocess.run(
        [sys.executable, "-m", "jaxrot", "compare", "--scene", "nope"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 2
    assert "heavy_top" in proc.stderr


@pytest.fixture(scope="module")
def small_rows():
    return {
        dtype: compare(
            "heavy_top",
            t_end=1.0,
            particles=2,
            dtype=dtype,
            coarse_steps=10,
            levels=2,
            tolerances=(1e-5,),
            repeats=1,
            progress=False,
            schemes=["zhao"],
            solvers=["diffrax_tsit5"],
        )
        for dtype in ("float64", "float32")
    }


class _Registered(Euler):
    name: ClassVar[str] = "registered_later"


@pytest.mark.slow
def test_a_newly_registered_scheme_gets_its_rows_with_no_other_change(monkeypatch):
    """By default every scheme in SCHEMES and every adaptive solver gets its rows."""
    registry = {"euler": jaxrot.SCHEMES["euler"], "registered_later": _Registered()}
    monkeypatch.setattr(comparison._ladder, "SCHEMES", registry)
    rows = compare(
        t_end=0.2, particles=1, coarse_steps=5, levels=2, tolerances=(1e-4,), repeats=1, progress=False
    )
    expected = [(name, "fixed") for name in registry for _ in range(2)]
    expected += [(name, "adaptive") for name in ADAPTIVE_SOLVERS]
    assert [(r["method"], r["kind"]) for r in rows] == expected
    assert [r["n_steps"] for r in rows if r["kind"] == "fixed"] == [5, 10, 5, 10]
    assert "measured order (registered_later)" in comparison.format_table(rows)


def _independent_energy_drift(scene, traj):
    q, omega = traj.q.astype(jnp.float64), traj.omega.astype(jnp.float64)
    args = jax.tree_util.tree_map(lambda x: x.astype(jnp.float64), scene.args["gravity"])
    inertia = scene.inertia.astype(jnp.float64)
    energies = [
        0.5 * jnp.sum(omega_b * inertia * omega_b)
        - jnp.dot(args["weight"], quat.rotate(qi, args["offset_body"]))
        for qi, wi in zip(q, omega, strict=True)
        for omega_b in [quat.rotate(quat.conjugate(qi), wi)]
    ]
    energies = jnp.stack(energies)
    return float(jnp.max(jnp.abs(energies - energies[0])) / jnp.abs(energies[0]))


@pytest.mark.slow
@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_error_columns_equal_an_independent_computation(small_rows, dtype):
    scene = jaxrot.SCENES["heavy_top"](getattr(jnp, dtype))
    row = small_rows[dtype][1]
    assert (row["method"], row["n_steps"]) == ("zhao", 20)
    # Two vmapped particles in a jitted rollout saving every 2nd step: the same arithmetic as compare()'s
    # one program per ladder, compiled as another program, which may order roundings differently.
    # Bound: each of the n steps has about 50 dependent roundings, each off by at most one ulp.
    ulps = row["n_steps"] * 50 * float(jnp.finfo(getattr(jnp, dtype)).eps)
    batch = jax.tree_util.tree_map(lambda x: jnp.stack([x, x]), scene.state)

    def run(state, save_every):
        return jaxrot.rollout(
            "zhao", state, scene.inertia, row["dt"], row["n_steps"], torque=scene.torque, args=scene.args,
            save_every=save_every,
        )  # fmt: skip

    traj = jax.jit(run, static_argnums=1)(batch, 2)
    assert traj.q.dtype == getattr(jnp, dtype)
    traj = jaxrot.Trajectory(traj.t, traj.q[:, 0], traj.omega[:, 0])
    ref_scene = jaxrot.SCENES["heavy_top"]()
    ref = jaxrot.reference_rollout(
        ref_scene.state, ref_scene.inertia, jnp.linspace(0.0, 1.0, 21), torque=ref_scene.torque,
        args=ref_scene.args, rtol=1e-13, atol=1e-13,
    )  # fmt: skip
    coarse_ref = jaxrot.Trajectory(ref.t[::2], ref.q[::2], ref.omega[::2])
    q = traj.q.astype(jnp.float64)
    assert row["max_orientation_error_rad"] == pytest.approx(
        float(jnp.max(quat.angle_between(q, coarse_ref.q))), rel=1e-12, abs=ulps
    )
    final = float(jnp.linalg.norm(traj.omega[-1].astype(jnp.float64) - ref.omega[-1]))
    spin = float(jnp.max(jnp.linalg.norm(traj.omega, axis=-1)))
    assert row["final_omega_error"] == pytest.approx(final, rel=1e-12, abs=ulps * spin)
    # Relative energy: kinetic ½ωᵀIω moves by about 2|δω|/|ω| of itself, the potential by |δq|.
    drift = _independent_energy_drift(ref_scene, traj)
    assert row["rel_energy_drift"] == pytest.approx(drift, rel=1e-9, abs=3 * ulps)
    # compare() samples the error at the coarse grid only; the maximum over every step can only be larger.
    every = jax.jit(run, static_argnums=1)(batch, 1)
    every_step = float(jnp.max(quat.angle_between(every.q[:, 0].astype(jnp.float64), ref.q)))
    assert row["max_orientation_error_rad"] <= every_step * (1 + 1e-12) + ulps
    assert row["torque_evals"] == 2 * row["n_steps"]


def test_adaptive_rows_equal_a_direct_diffrax_solve(small_rows):
    row = next(r for r in small_rows["float64"] if r["method"] == "diffrax_tsit5")
    scene = jaxrot.SCENES["heavy_top"]()
    ts = jnp.linspace(0.0, 1.0, 11)
    ref = jaxrot.reference_rollout(
        scene.state, scene.inertia, ts, torque=scene.torque, args=scene.args, rtol=1e-13, atol=1e-13
    )
    omega_b0 = quat.rotate(quat.conjugate(scene.state.q), scene.state.omega)
    inertia = scene.inertia

    def field(t, y, args):
        q, w = y
        q_unit = q / jnp.linalg.norm(q)
        tau_b = quat.rotate(quat.conjugate(q_unit), scene.torque(t, q_unit, quat.rotate(q_unit, w), args))
        return 0.5 * quat.multiply(q, quat.pure(w)), (tau_b - jnp.cross(w, inertia * w)) / inertia

    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(field), diffrax.Tsit5(), 0.0, 1.0, None, (scene.state.q, omega_b0), args=scene.args,
        saveat=diffrax.SaveAt(ts=ts), stepsize_controller=diffrax.PIDController(rtol=1e-5, atol=1e-5),
    )  # fmt: skip
    q = sol.ys[0] / jnp.linalg.norm(sol.ys[0], axis=-1, keepdims=True)
    assert row["max_orientation_error_rad"] == pytest.approx(
        float(jnp.max(quat.angle_between(q, ref.q))), rel=1e-6
    )
    assert row["n_steps"] == int(sol.stats["num_steps"])


@pytest.mark.parametrize("name", list(ADAPTIVE_SOLVERS))
def test_adaptive_torque_evals_are_the_counted_calls(name):
    scene = jaxrot.SCENES["heavy_top"]()
    calls = []

    def counted(t, q, omega, args):
        jax.debug.callback(lambda: calls.append(1))
        return scene.torque(t, q, omega, args)

    solver, _, per_step = ADAPTIVE_SOLVERS[name]
    ts = jnp.linspace(0.0, 1.0, 5)
    *_, steps = adaptive_solve(
        solver(), scene.state.q[None], scene.state.omega[None], scene.inertia, False, ts, counted, scene.args,
        1e-6, 1e-6, 10_000,
    )  # fmt: skip
    jax.effects_barrier()
    assert len(calls) == per_step * int(steps[0]) + 1


def test_recommendation_is_the_fastest_row_within_each_budget():
    rows = [
        {"method": "a", "kind": "fixed", "dt": 0.1, "max_orientation_error_rad": 5e-2,
         "us_per_particle_run": 1.0},
        {"method": "a", "kind": "fixed", "dt": 0.05, "max_orientation_error_rad": 5e-3,
         "us_per_particle_run": 2.0},
        {"method": "b", "kind": "adaptive", "tol": 1e-6, "max_orientation_error_rad": 4e-4,
         "us_per_particle_run": 1.5},
    ]  # fmt: skip
    picks = dict(recommend(rows))
    assert picks[1e-1]["us_per_particle_run"] == 1.0
    assert picks[1e-2]["method"] == "b"  # within budget and faster than a at dt = 0.05
    assert picks[1e-3]["method"] == "b"
    assert picks[1e-4] is None
    assert "≤1e-04: none" in format_recommendation(rows)


def test_budget_table_pits_each_sides_fastest_row_against_the_other():
    rows = [
        {"method": "zhao", "kind": "fixed", "dt": 0.1, "max_orientation_error_rad": 5e-2,
         "us_per_particle_run": 1.0},
        {"method": "rkmk4", "kind": "fixed", "dt": 0.1, "max_orientation_error_rad": 5e-4,
         "us_per_particle_run": 3.0},
        {"method": "diffrax_tsit5", "kind": "adaptive", "tol": 1e-3, "max_orientation_error_rad": 4e-2,
         "us_per_particle_run": 4.0},
        {"method": "diffrax_tsit5", "kind": "adaptive", "tol": 1e-5, "max_orientation_error_rad": 4e-5,
         "us_per_particle_run": 6.0},
    ]  # fmt: skip
    table = budget_table(rows)
    assert [b for b, *_ in table] == [1e-1, 1e-2, 1e-3, 1e-4, 1e-5]  # down to the smallest error's decade
    by_budget = {
        b: (mine and mine["method"], best and best["us_per_particle_run"], r) for b, mine, best, r in table
    }
    assert by_budget[1e-1] == ("zhao", 4.0, 4.0)  # zhao 1 µs against Tsit5's 4 µs
    assert by_budget[1e-2] == ("rkmk4", 6.0, 2.0)
    assert by_budget[1e-4] == (None, 6.0, None)  # only diffrax meets it: no ratio
    assert by_budget[1e-5] == (None, None, None)
    text = format_budget_table(rows)
    assert "4.0×" in text and "2.0×" in text and text.count("\n") == 1 + len(table)


def test_a_row_that_blew_up_meets_no_budget():
    """A step past a scheme's stability limit gives a NaN error: no budget, no crash (it once did)."""
    rows = [
        {"method": "a", "kind": "fixed", "dt": 0.2, "max_orientation_error_rad": float("nan"),
         "us_per_particle_run": 0.5},
        {"method": "a", "kind": "fixed", "dt": 0.1, "max_orientation_error_rad": 5e-3,
         "us_per_particle_run": 1.0},
    ]  # fmt: skip
    picks = recommend(rows)
    assert [budget for budget, _ in picks] == [1e-1, 1e-2, 1e-3]
    assert [row and row["dt"] for _, row in picks] == [0.1, 0.1, None]
    assert "≤1e-03: none" in format_recommendation(rows)


def test_compare_rejects_bad_arguments():
    with pytest.raises(ValueError, match="dtype"):
        compare(dtype="float16", progress=False)
    with pytest.raises(ValueError, match="particles"):
        compare(particles=0, progress=False)


def test_measured_orders_skip_saturated_rungs():
    rows = [
        {"method": "zhao", "kind": "fixed", "dt": dt, "max_orientation_error_rad": err}
        for dt, err in [(0.4, 3.0), (0.2, 0.08), (0.1, 0.02), (0.05, 0.005)]
    ]
    assert measured_orders(rows)["zhao"] == pytest.approx(2.0, abs=1e-12)
    assert measured_orders(rows[:3])["zhao"] is None


def test_measured_orders_leave_out_the_floor():
    """An order-8 ladder that reaches the reference's floor (~1e-11 rad, the heavy top's numbers):
    the floor rungs would pull the fitted slope to ~2.7; left out, the slope is the scheme's."""
    errors = [2.7e-5, 7.8e-8, 2.3e-10, 9.2e-12, 9.4e-12, 9.4e-12]
    rows = [
        {"method": "rkmk_dopri8", "kind": "fixed", "dt": 0.2 / 2**k, "max_orientation_error_rad": e}
        for k, e in enumerate(errors)
    ]
    assert stalled(errors) and not stalled(errors[:4])
    assert measured_orders(rows)["rkmk_dopri8"] == pytest.approx(8.4, abs=0.05)
    assert measured_orders(rows[:2])["rkmk_dopri8"] is None


def test_fit_order_recovers_a_known_slope():
    dts = jnp.array([0.1, 0.05, 0.025])
    assert fit_order(dts, 3.0 * dts**2) == pytest.approx(2.0, abs=1e-12)


def test_each_ladder_compiles_one_program(monkeypatch):
    """dt and the step count are runtime values of one program per scheme, the tolerance of one
    program per adaptive solver: not one program per rung."""
    built = []
    for runner in ("_fixed_runner", "_adaptive_runner"):
        original = getattr(comparison._ladder, runner)

        def counting(problem, method, original=original):
            built.append(getattr(method, "name", method))
            return original(problem, method)

        monkeypatch.setattr(comparison._ladder, runner, counting)
    rows = compare(
        t_end=0.2, particles=1, coarse_steps=5, levels=3, schemes=["zhao", "rkmk4"],
        solvers=["diffrax_tsit5"], tolerances=(1e-4, 1e-6), repeats=1, progress=False,
    )  # fmt: skip
    assert sorted(built) == ["diffrax_tsit5", "rkmk4", "zhao"]
    assert [r["n_steps"] for r in rows if r["method"] == "zhao"] == [5, 10, 20]
    assert len({r["compile_s"] for r in rows if r["method"] == "zhao"}) == 1
    adaptive = [r for r in rows if r["method"] == "diffrax_tsit5"]
    assert [r["tol"] for r in adaptive] == [1e-4, 1e-6]
    assert adaptive[1]["n_steps"] > adaptive[0]["n_steps"]  # the runtime tolerance reached the controller
    assert len({r["compile_s"] for r in adaptive}) == 1
