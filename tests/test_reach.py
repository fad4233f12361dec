"""Reach of a front foot on three legs: the quasi-static controller, the bounds, the bench."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from benchmarks.reach import (
    ReachCfg,
    closest_point_in_triangle,
    kinematic_reach,
    measure_reach,
    shrunk_triangle,
)
from quaddance.cli import app
from quaddance.errors import QuaddanceError

# Heights from the issue: 5 cm is a small dance tap; 60 cm is above the trunk (about 0.32 m)
# plus a whole folded leg, out of any reach.
LOW_M, ABSURD_M = 0.05, 0.6


@pytest.fixture(scope="module")
def low_and_absurd() -> dict:
    """FL lifted to 5 cm and 60 cm, with one bisection step between them."""
    return measure_reach("FL", heights=(LOW_M, ABSURD_M), tolerance_m=0.3)


def trial_at(result: dict, target_m: float) -> dict:
    (trial,) = [t for t in result["trials"] if t["target_m"] == target_m]
    return trial


def test_low_lift_is_held_with_the_other_feet_down(low_and_absurd: dict) -> None:
    low = trial_at(low_and_absurd, LOW_M)
    assert low["success"], low
    assert low["reached_m"] >= 0.95 * LOW_M
    assert low["max_stance_foot_height_m"] <= 0.01  # rear feet (and FR) never left the floor
    assert low["min_trunk_height_m"] > 0.25 and low["max_tilt_deg"] < 10.0
    assert low["max_stance_slip_m"] < 0.02


def test_absurd_height_is_not_reached(low_and_absurd: dict) -> None:
    absurd = trial_at(low_and_absurd, ABSURD_M)
    assert not absurd["success"]
    assert absurd["reached_m"] < 0.95 * ABSURD_M
    assert low_and_absurd["first_failure_m"] == ABSURD_M
    # The sweep bisected once (0.325 m) and kept the highest success as the reach.
    targets = [t["target_m"] for t in low_and_absurd["trials"]]
    assert targets == sorted(targets) and len(targets) == 3
    successes = [t["target_m"] for t in low_and_absurd["trials"] if t["success"]]
    assert low_and_absurd["reach_m"] == max(successes)


def test_result_fields_are_consistent(low_and_absurd: dict) -> None:
    r = low_and_absurd
    for key in (
        "foot",
        "reach_m",
        "held_m",
        "first_failure_m",
        "kinematic_bound_m",
        "kinematic_bound_front_m",
        "trunk_height_m",
        "com_shift_m",
        "trials",
        "cfg",
    ):
        assert key in r
    assert r["foot"] == "FL"
    assert LOW_M <= r["reach_m"] < ABSURD_M
    assert r["held_m"] >= 0.95 * r["reach_m"]
    # Physics cannot beat the joint ranges, and the front-only bound is the tighter one.
    assert r["held_m"] <= r["kinematic_bound_front_m"] + 0.005
    assert r["kinematic_bound_front_m"] < r["kinematic_bound_m"]
    assert 0.25 < r["trunk_height_m"] < 0.35
    assert 0.01 < r["com_shift_m"] < 0.15  # the CoM had to move onto the triangle
    json.dumps(r)  # the bench writes it as JSON


def test_kinematic_bound_is_mirror_symmetric() -> None:
    left = kinematic_reach("FL", in_front=True)
    right = kinematic_reach("FR", in_front=True)
    assert left["height_m"] == pytest.approx(right["height_m"], abs=1e-3)
    assert left["foot_pos_w_m"][1] == pytest.approx(-right["foot_pos_w_m"][1], abs=1e-3)
    # The best front pose puts the foot above the standing hip height, in front of the hip.
    assert left["height_m"] > 0.3 and left["foot_pos_w_m"][0] > 0.19


def test_support_triangle_helpers() -> None:
    tri = np.array([[0.17, -0.16], [-0.27, -0.16], [-0.27, 0.16]])
    inner = shrunk_triangle(tri, 0.03)
    # Every inner vertex lies 3 cm inside the two edges that meet at the outer one.
    assert inner[0, 1] == pytest.approx(-0.13) and inner[2, 0] == pytest.approx(-0.24)
    centre = tri.mean(axis=0)
    assert np.allclose(closest_point_in_triangle(centre, inner), centre)
    outside = np.array([0.0, 0.0])  # the standing CoM, on the lifted foot's side
    moved = closest_point_in_triangle(outside, inner)
    # Lands on the inner diagonal, i.e. 3 cm inside the outer diagonal.
    edge = tri[2] - tri[0]
    inward = np.array([-edge[1], edge[0]]) / np.linalg.norm(edge)
    assert np.dot(moved - tri[0], inward) == pytest.approx(0.03)
    with pytest.raises(QuaddanceError, match="com_margin_m"):
        shrunk_triangle(tri, 0.5)


def test_bad_arguments_are_user_errors() -> None:
    with pytest.raises(QuaddanceError, match="foot"):
        measure_reach("RL")
    with pytest.raises(QuaddanceError, match="heights"):
        measure_reach("FL", heights=(-0.1, 0.2))
    with pytest.raises(QuaddanceError, match="tolerance"):
        measure_reach("FL", tolerance_m=0.0)
    with pytest.raises(QuaddanceError, match="lift_s"):
        ReachCfg(lift_s=0.0)


def test_bench_reach_writes_json(tmp_path: Path) -> None:
    out = tmp_path / "reach.json"
    args = ["bench", "reach", "-o", str(out), "--foot", "FR", "--height", "0.1"]
    result = CliRunner().invoke(app, [*args, "--height", "0.6", "--tolerance", "0.5"])
    assert result.exit_code == 0, result.output
    data = json.loads(out.read_text())
    assert list(data["feet"]) == ["FR"]
    fr = data["feet"]["FR"]
    assert fr["reach_m"] == 0.1 and fr["first_failure_m"] == 0.6
    assert data["held_m_min"] == fr["held_m"] and fr["wall_s"] > 0
    bad = CliRunner().invoke(app, ["bench", "reach", "-o", str(out), "--foot", "RL"])
    assert bad.exit_code != 0


def test_robot_option_measures_that_robot(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)  # the default output goes under the working directory
    args = ["bench", "reach", "--robot", "go2", "--foot", "FL", "--height", "0.05"]
    result = CliRunner().invoke(app, [*args, "--tolerance", "0.05"])
    assert result.exit_code == 0, result.output
    report = json.loads((tmp_path / "benchmarks/results/go2/reach.json").read_text())
    assert report["robot"] == "unitree_go2"
    assert report["feet"]["FL"]["reach_m"] == 0.05
    # The Go2's front thigh turns 90 deg forward (the Go1's 39 deg, whose bound is < 0.42 m).
    assert report["kinematic_bound_front_m"] > 0.5
