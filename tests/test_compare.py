"""`python -m jaxrot compare`: end to end at a tiny size, and its numbers checked independently."""

import csv
import json
import subprocess
import sys

import jax.numpy as jnp
import pytest

import jaxrot
from jaxrot import quaternion as quat
from jaxrot._compare import compare, fit_order, measured_orders


def test_cli_runs_end_to_end_and_writes_table_csv_json_png(tmp_path):
    out = tmp_path / "out"
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "jaxrot",
            "compare",
            "--coarse-steps",
            "20",
            "--levels",
            "3",
            "--repeats",
            "1",
            "--t-end",
            "1.0",
            "--out",
            str(out),
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    assert "max q err [rad]" in proc.stdout
    rows = list(csv.DictReader((out / "compare.csv").read_text().splitlines()))
    # Every registered scheme gets its rows with no change to the compare code.
    assert [r["scheme"] for r in rows] == [name for name in jaxrot.SCHEMES for _ in range(3)]
    assert [int(r["n_steps"]) for r in rows] == [20, 40, 80] * len(jaxrot.SCHEMES)
    for name in jaxrot.SCHEMES:
        assert f"measured order ({name})" in proc.stdout
    assert json.loads((out / "compare.json").read_text())["machine"]["jax"]
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


def test_error_column_equals_an_independent_computation():
    rows = compare("heavy_top", t_end=1.0, coarse_steps=10, levels=2, repeats=1, progress=False)
    scene = jaxrot.SCENES["heavy_top"]()
    row = rows[1]
    traj = jaxrot.rollout(
        "zhao", scene.state, scene.inertia, row["dt"], row["n_steps"], torque=scene.torque, args=scene.args
    )
    ref = jaxrot.reference_rollout(
        scene.state, scene.inertia, traj.t, torque=scene.torque, args=scene.args, rtol=1e-13, atol=1e-13
    )
    every_step = float(jnp.max(quat.angle_between(traj.q, ref.q)))
    # compare() samples the error at the coarse grid only; the maximum over every step can only be larger.
    on_coarse_grid = float(jnp.max(quat.angle_between(traj.q[::2], ref.q[::2])))
    assert row["max_orientation_error_rad"] == pytest.approx(on_coarse_grid, rel=1e-9)
    assert row["max_orientation_error_rad"] <= every_step * (1 + 1e-9)
    assert row["torque_evals"] == 2 * row["n_steps"]


def test_measured_orders_skip_saturated_rungs():
    rows = [
        {"scheme": "zhao", "dt": dt, "max_orientation_error_rad": err}
        for dt, err in [(0.4, 3.0), (0.2, 0.08), (0.1, 0.02), (0.05, 0.005)]
    ]
    assert measured_orders(rows)["zhao"] == pytest.approx(2.0, abs=1e-12)
    assert measured_orders(rows[:3])["zhao"] is None


def test_fit_order_recovers_a_known_slope():
    dts = jnp.array([0.1, 0.05, 0.025])
    assert fit_order(dts, 3.0 * dts**2) == pytest.approx(2.0, abs=1e-12)
