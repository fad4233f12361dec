"""The robot a dance is for: ``--robot`` on dance, choreograph and eval, the robot's limits
in every dance composed, the robot recorded in dance.npz and named by the policy, and the
Go2 in the dance task."""

from __future__ import annotations

import dataclasses
import json
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from quaddance.choreo.grid import synthetic_grid
from quaddance.choreo.moves_file import load_moves
from quaddance.cli import main
from quaddance.dancefile import load_dance, save_dance
from quaddance.errors import InputFileError, QuaddanceError
from quaddance.layout import BODY, PAWS
from quaddance.pipeline import DanceSpec, compose, target_bank
from quaddance.play.dance import spec_for_policy
from quaddance.play.policy import OnnxPolicy, choose_policy, shipped_policy_path
from quaddance.robots import GO1, GO2, ROBOTS, BodyLimits
from quaddance.sim import tasks
from quaddance.sim.task import DanceEnv
from quaddance.targets import TargetConfig
from quaddance.train import TrainCfg, Trainer

#: A Go2 whose reach is far below the Go1's, so that every limit shows which robot it is from.
SMALL_GO2 = dataclasses.replace(
    GO2,
    max_paw_height_m=0.08,
    body_four_feet=BodyLimits(height_offset_m=(-0.01, 0.01), roll_rad=0.02, pitch_rad=0.02,
                              yaw_rad=0.02),
    body_paw_up=BodyLimits(height_offset_m=(-0.005, 0.005), roll_rad=0.01, pitch_rad=0.01,
                           yaw_rad=0.01),
)  # fmt: skip


@pytest.fixture(scope="module")
def go2_policy(tmp_path_factory) -> Path:
    """A Go2 whole-body policy after one PPO iteration: its actions mean nothing, its contract
    is a Go2's (about 15 s)."""
    run_dir = tmp_path_factory.mktemp("go2_run")
    task = tasks.whole_body(num_envs=8, robot=GO2, curriculum_env_steps=None)
    cfg = TrainCfg(run_dir=run_dir, preset="cpu", bank_size=1, task=task)
    bank = np.zeros((1, 200, 8), np.float32)
    bank[0, 50:80, 0] = 0.1  # a front-left lift: the range the policy declares it was trained on
    trainer = Trainer(cfg, bank=bank, log=lambda *a: None)
    trainer.learn(1, progress=False)
    onnx_path, _ = trainer.export()
    return onnx_path


def _quaddance(monkeypatch, capsys, *args: str) -> tuple[int, list[str]]:
    """Run ``quaddance ARGS`` as the console does: (exit status, stderr lines)."""
    monkeypatch.setattr(sys, "argv", ["quaddance", *map(str, args)])
    with pytest.raises(SystemExit) as exc:
        main()
    return exc.value.code, capsys.readouterr().err.strip().splitlines()


def _one_line_error(code: int, err: list[str], *needles: str) -> None:
    assert code == 2, err
    assert len(err) == 1 and err[0].startswith("quaddance: error:"), err
    for needle in needles:
        assert needle in err[0], err


# --- the robot's limits in every dance ------------------------------------------------------


def test_target_config_takes_its_limits_from_its_robot():
    assert TargetConfig().robot is GO1
    assert TargetConfig().max_height_m == GO1.max_paw_height_m
    assert TargetConfig(robot=SMALL_GO2).max_height_m == 0.08
    assert TargetConfig(robot=SMALL_GO2, max_height_m=0.05).max_height_m == 0.05


def test_a_dance_keeps_to_its_robot_s_paw_and_trunk_limits():
    grid = synthetic_grid(120.0, 20.0, np.random.default_rng(0))
    spec = DanceSpec(style="energetic", seed=1, targets=TargetConfig(robot=SMALL_GO2))
    dance = compose(spec, grid)
    assert dance.robot == GO2.name
    assert dance.targets_m.max() <= 0.08 + 1e-9
    lo, hi = SMALL_GO2.body_four_feet.low, SMALL_GO2.body_four_feet.high
    assert np.all(dance.body_targets >= lo - 1e-9) and np.all(dance.body_targets <= hi + 1e-9)
    # The same dance for the Go1 moves more: the limits came from the robot.
    go1 = compose(dataclasses.replace(spec, targets=TargetConfig()), grid)
    assert go1.targets_m.max() > 0.1 and np.abs(go1.body_targets).max() > 0.05


def test_the_training_bank_keeps_to_its_robot_s_limits():
    bank = target_bank(2, 8.0, seed=3, cfg=TargetConfig(robot=SMALL_GO2), body=True)
    assert bank[..., PAWS].max() <= 0.08 + 1e-6
    body = bank[..., BODY].reshape(-1, 4)
    assert np.all(body >= SMALL_GO2.body_four_feet.low - 1e-6)
    assert np.all(body <= SMALL_GO2.body_four_feet.high + 1e-6)


def test_a_moves_file_is_checked_against_the_robot_s_range(tmp_path):
    moves = tmp_path / "moves.toml"
    moves.write_text('[moves.nod]\ngestures = [{ column = "pitch_rad", amplitude = 0.1 }]\n')
    assert "nod" in {m.name for m in load_moves(moves, GO1.body_four_feet).body_moves}
    with pytest.raises(InputFileError, match=r"pitch_rad range \[-0.02, 0.02\]"):
        load_moves(moves, SMALL_GO2.body_four_feet)


# --- dance.npz names its robot --------------------------------------------------------------


def test_dance_npz_records_its_robot_and_is_refused_by_another(tmp_path):
    grid = synthetic_grid(100.0, 4.0, np.random.default_rng(1))
    path = tmp_path / "go2.npz"
    save_dance(path, compose(DanceSpec(targets=TargetConfig(robot=GO2)), grid))
    assert load_dance(path).robot == GO2.name
    assert load_dance(path, GO2).robot == GO2.name
    with pytest.raises(InputFileError) as err:
        load_dance(path, GO1)
    assert str(err.value) == (
        f"{path}: a dance for go2, not go1 (choreograph it again with --robot go1)"
    )


def test_a_dance_npz_without_a_robot_is_a_go1_dance(tmp_path):
    grid = synthetic_grid(100.0, 4.0, np.random.default_rng(1))
    path = tmp_path / "new.npz"
    save_dance(path, compose(DanceSpec(), grid))
    with np.load(path) as npz:
        old = {k: npz[k] for k in npz.files if k != "robot"}
    old["format"] = np.int64(2)
    np.savez(tmp_path / "old.npz", **old)
    assert load_dance(tmp_path / "old.npz", GO1).robot == GO1.name
    with pytest.raises(InputFileError, match="a dance for go1, not go2"):
        load_dance(tmp_path / "old.npz", GO2)


def test_a_dance_npz_naming_an_unknown_robot_is_refused(tmp_path):
    grid = synthetic_grid(100.0, 4.0, np.random.default_rng(1))
    path = tmp_path / "d.npz"
    save_dance(path, compose(DanceSpec(), grid))
    with np.load(path) as npz:
        arrays = {k: npz[k] for k in npz.files}
    arrays["robot"] = np.array("unitree_b2")
    np.savez(path, **arrays)
    with pytest.raises(InputFileError, match="robot must be one of unitree_go1, unitree_go2"):
        load_dance(path)


# --- the policy names its robot -------------------------------------------------------------


def test_choose_policy_follows_robot_and_policy(go2_policy):
    assert choose_policy(None, None) == (GO1, shipped_policy_path(GO1))
    assert choose_policy("go1", None) == (GO1, shipped_policy_path(GO1))
    assert choose_policy(None, go2_policy) == (GO2, go2_policy)
    assert choose_policy("go2", go2_policy) == (GO2, go2_policy)
    with pytest.raises(QuaddanceError) as err:
        choose_policy("go1", go2_policy)
    assert str(err.value) == f"{go2_policy}: a policy for go2, not for go1 (--robot go1)"


def test_a_missing_shipped_policy_names_the_robot_and_the_path(monkeypatch):
    absent = dataclasses.replace(GO2, policy="absent_go2.onnx")
    with pytest.raises(QuaddanceError, match=r"^no go2 policy ships .*absent_go2.onnx is missing"):
        shipped_policy_path(absent)
    monkeypatch.setitem(ROBOTS, GO2.name, absent)
    with pytest.raises(QuaddanceError, match="no go2 policy ships"):
        choose_policy("go2", None)


def test_a_policy_is_refused_by_a_dance_for_another_robot(go2_policy):
    policy = OnnxPolicy.load(go2_policy)
    assert policy.robot is GO2 and policy.spec.robot == GO2.name
    assert spec_for_policy(DanceSpec(targets=TargetConfig(robot=GO2)), policy).robot is GO2
    with pytest.raises(InputFileError, match=r"a policy for go2, not for go1 \(the dance's"):
        spec_for_policy(DanceSpec(), policy)


# --- the commands ---------------------------------------------------------------------------


def test_choreograph_robot_makes_a_dance_for_it(monkeypatch, capsys, song_3s, tmp_path):
    out = tmp_path / "go2.npz"
    code, err = _quaddance(monkeypatch, capsys, "choreograph", song_3s, "--robot", "go2", "-o", out)
    assert code == 0, err
    assert load_dance(out).robot == GO2.name
    code, err = _quaddance(monkeypatch, capsys, "choreograph", song_3s, "--robot", "go7", "-o", out)
    _one_line_error(code, err, "unknown robot 'go7'; known: go1, go2")


def test_deploy_refuses_a_dance_made_for_another_robot(monkeypatch, capsys, song_3s, tmp_path):
    made = tmp_path / "go2.npz"
    assert (
        _quaddance(monkeypatch, capsys, "choreograph", song_3s, "--robot", "go2", "-o", made)[0]
        == 0
    )
    code, err = _quaddance(
        monkeypatch, capsys, "deploy", "--dance", made, "--out", tmp_path / "out", "--auto-start"
    )
    _one_line_error(code, err, f"{made}: a dance for go2, not go1")


def test_dance_without_a_shipped_go2_policy_is_one_line(monkeypatch, capsys, tmp_path):
    monkeypatch.setitem(ROBOTS, GO2.name, dataclasses.replace(GO2, policy="absent_go2.onnx"))
    code, err = _quaddance(monkeypatch, capsys, "dance", "--demo", "--robot", "go2", "--no-video",
                           "--out", tmp_path)  # fmt: skip
    _one_line_error(code, err, "no go2 policy ships", "absent_go2.onnx")


@pytest.mark.parametrize("command", ["dance", "eval"])
def test_robot_and_policy_that_disagree_are_one_line(monkeypatch, capsys, go2_policy, song_3s,
                                                     tmp_path, command):  # fmt: skip
    code, err = _quaddance(monkeypatch, capsys, command, song_3s, "--policy", go2_policy,
                           "--robot", "go1", "--out" if command == "dance" else "--report",
                           tmp_path / "out")  # fmt: skip
    _one_line_error(code, err, f"{go2_policy}: a policy for go2, not for go1 (--robot go1)")


def test_dance_with_a_go2_policy_dances_a_go2(monkeypatch, capsys, go2_policy, song_3s, tmp_path):
    """--policy alone picks its robot: the dance is the Go2's, and so is the simulation."""
    # The command ends its process without teardown; here it must return to the tests.
    monkeypatch.setattr("quaddance.cli.dance.exit_without_teardown", lambda: None)
    code, err = _quaddance(monkeypatch, capsys, "dance", song_3s, "--policy", go2_policy,
                           "--no-video", "--out", tmp_path)  # fmt: skip
    assert code == 0, err
    assert load_dance(tmp_path / "dance.npz").robot == GO2.name
    metrics = json.loads((tmp_path / "metrics.json").read_text())
    assert metrics["policy"] == str(go2_policy)
    with np.load(tmp_path / "rollout.npz") as rollout:
        assert rollout["time_s"].size == 150


# --- the Go2 in the dance task --------------------------------------------------------------


def test_a_go2_stands_on_zero_actions():
    """A DanceEnv of the Go2 (its model, gains, nominal pose) holds its stand for 1 s."""
    cfg = tasks.whole_body(num_envs=1, robot=GO2, curriculum_env_steps=None)
    cfg.domain_rand.enabled = False
    env = DanceEnv(cfg, np.zeros((1, 100, 8), np.float32), seed=0, random_start=False)
    heights = []
    for _ in range(round(cfg.policy_hz)):
        _, _, dones, _ = env.step(torch.zeros(1, GO2.num_joints))
        assert not dones.any()
        heights.append(float(env.robot.base_pos_w[0, 2]))
    # The drop from the spawn height rings down over the second; by its end the trunk stands
    # near its height.
    late = np.array(heights[-10:])
    assert np.all(np.abs(late - GO2.standing_height_m) < 0.015), late
    assert env.robot.foot_height_m.abs().max() < 0.01  # four feet on the floor


def test_playback_refuses_a_dance_for_another_robot(go2_policy):
    from quaddance.play.rollout import playback_env

    grid = synthetic_grid(100.0, 2.0, np.random.default_rng(1))
    with pytest.raises(InputFileError, match="a policy for go2, not for go1"):
        playback_env(compose(DanceSpec(), grid), OnnxPolicy.load(go2_policy))


def test_deploy_sim_simulates_the_policys_robot():
    from quaddance.deploy.job import BackendOptions, make_robot

    made = [make_robot(BackendOptions(robot="sim"), robot) for robot in (GO2, GO1)]
    assert [r.cfg.robot for r in made] == [GO2.name, GO1.name]  # not started: no process
    with pytest.raises(QuaddanceError, match="drives a Go1"):
        make_robot(BackendOptions(robot="go1"), GO2)


def test_reports_name_a_shipped_policy_by_its_file_not_this_machines_path(tmp_path):
    from quaddance.play.policy import policy_label

    assert policy_label(shipped_policy_path(GO2)) == "shipped (go2_dance.onnx)"
    assert policy_label(None) == "shipped (go1_dance.onnx)"
    mine = tmp_path / "go1_dance.onnx"  # the same name elsewhere is the user's own
    assert policy_label(mine) == str(mine)


@pytest.mark.parametrize("robot", [GO1, GO2])
def test_choreograph_makes_the_dance_that_dance_performs(monkeypatch, capsys, song_3s, tmp_path,
                                                         robot):  # fmt: skip
    """Without --max-height, `choreograph` keeps to the range of the robot's shipped policy,
    as `dance` does: its dance.npz is the dance that `dance` performs."""
    monkeypatch.setattr("quaddance.cli.dance.exit_without_teardown", lambda: None)
    made = tmp_path / "made.npz"
    args = ("--robot", robot.name, "--seed", "4")
    code, err = _quaddance(monkeypatch, capsys, "choreograph", song_3s, *args, "-o", made)
    assert code == 0, err
    code, err = _quaddance(monkeypatch, capsys, "dance", song_3s, *args, "--no-video",
                           "--out", tmp_path / "danced")  # fmt: skip
    assert code == 0, err
    made, danced = load_dance(made), load_dance(tmp_path / "danced" / "dance.npz")
    # The same dance, to float rounding: `dance` composes it in its helper process.
    np.testing.assert_allclose(made.targets_m, danced.targets_m, rtol=0, atol=1e-6)
    np.testing.assert_allclose(made.body_targets, danced.body_targets, rtol=0, atol=1e-6)
    trained = OnnxPolicy.load(shipped_policy_path(robot)).spec.targets_max_height_m
    assert trained < robot.max_paw_height_m and made.targets_m.max() <= trained + 1e-6
