"""An exported policy: loading it (ONNX + JSON), its errors, and closed-loop playback."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch

from quaddance import __version__
from quaddance.dancefile import Dance
from quaddance.errors import InputFileError, QuaddanceError
from quaddance.play.policy import OnnxPolicy
from quaddance.play.rollout import rollout
from quaddance.robots import GO1
from quaddance.sim import tasks
from quaddance.train import TrainCfg, Trainer

FPS = 50.0


@pytest.fixture(scope="module")
def trainer(tmp_path_factory) -> Trainer:
    run_dir = tmp_path_factory.mktemp("run")
    cfg = TrainCfg(run_dir=run_dir, iterations=0, preset="cpu", task=tasks.paws_only(num_envs=2))
    return Trainer(cfg, bank=np.zeros((1, 1100, 4), np.float32), log=lambda *a: None)


def export_constant_policy(trainer: Trainer, action: list[float], out_dir: Path) -> Path:
    """Export an actor whose output is `action` whatever it observes."""
    last = trainer.alg.get_policy().mlp[-1]  # the output layer
    with torch.no_grad():
        last.weight.zero_()
        last.bias.copy_(torch.tensor(action))
    out_dir.mkdir()
    onnx_path, _ = trainer.export(out_dir)
    return onnx_path


@pytest.fixture(scope="module")
def standing_policy(trainer, tmp_path_factory) -> Path:
    """Actions exactly 0: the robot holds its nominal pose."""
    return export_constant_policy(trainer, [0.0] * 12, tmp_path_factory.mktemp("x") / "stand")


@pytest.fixture(scope="module")
def collapsing_policy(trainer, tmp_path_factory) -> Path:
    """Thighs forward and knees folded by 1 rad: the trunk drops to the floor."""
    action = [0.0, 4.0, -4.0] * 4
    return export_constant_policy(trainer, action, tmp_path_factory.mktemp("x") / "collapse")


def copy_policy(onnx_path: Path, dest: Path) -> Path:
    dest.mkdir()
    for path in (onnx_path, onnx_path.with_suffix(".json")):
        shutil.copy(path, dest / path.name)
    return dest / onnx_path.name


def edit_json(onnx_path: Path, edit) -> None:
    json_path = onnx_path.with_suffix(".json")
    meta = json.loads(json_path.read_text())
    edit(meta)
    json_path.write_text(json.dumps(meta))


def make_dance(duration_s: float, lift_m: float) -> Dance:
    """A dance with one FL lift in its middle (or none when lift_m is 0)."""
    n = round(duration_s * FPS)
    time_s = np.arange(n) / FPS
    targets = np.zeros((n, 4))
    targets[n // 3 : n // 2, 0] = lift_m
    return Dance(
        fps=FPS,
        time_s=time_s,
        human_feet_m=targets[:, :2] * 2.0,
        targets_m=targets,
        beats_s=np.arange(0.0, duration_s, 0.5),
        downbeats_s=np.arange(0.0, duration_s, 2.0),
        mode="feasible",
        source="test",
        seed=0,
        version=__version__,
    )


# --- loading --------------------------------------------------------------------------------


def test_load_an_exported_policy(standing_policy):
    policy = OnnxPolicy.load(standing_policy)
    meta = json.loads(standing_policy.with_suffix(".json").read_text())
    assert policy.obs_dim == meta["obs"]["dim"]
    actions = policy.act(np.random.default_rng(0).normal(size=(3, policy.obs_dim)))
    assert actions.shape == (3, GO1.num_joints) and actions.dtype == np.float32
    np.testing.assert_array_equal(actions, 0.0)
    # The task settings come back from the JSON as the same dataclasses (tuples included).
    assert policy.task.obs.preview_s == (0.1, 0.2, 0.4)
    assert policy.task.domain_rand.friction == (0.1, 3.0)
    assert (policy.task.policy_hz, policy.task.decimation) == (50.0, 4)
    assert policy.task.scene.kp == meta["kp"]


def test_json_obs_dim_that_disagrees_with_its_terms(standing_policy, tmp_path):
    onnx_path = copy_policy(standing_policy, tmp_path / "p")

    def bump(meta):
        meta["obs"]["dim"] += 1

    edit_json(onnx_path, bump)
    with pytest.raises(InputFileError, match="sum of the term sizes") as err:
        OnnxPolicy.load(onnx_path)
    assert err.value.path == onnx_path.with_suffix(".json")


def test_onnx_input_that_disagrees_with_the_json(standing_policy, tmp_path):
    """A model of another network beside a valid JSON: the error names the .onnx."""
    onnx_path = copy_policy(standing_policy, tmp_path / "p")
    torch.onnx.export(torch.nn.Linear(10, 12), (torch.zeros(1, 10),), str(onnx_path), dynamo=False)
    with pytest.raises(InputFileError, match="observations") as err:
        OnnxPolicy.load(onnx_path)
    assert err.value.path == onnx_path


def test_missing_json(standing_policy, tmp_path):
    onnx_path = copy_policy(standing_policy, tmp_path / "p")
    onnx_path.with_suffix(".json").unlink()
    with pytest.raises(InputFileError) as err:
        OnnxPolicy.load(onnx_path)
    assert err.value.path == onnx_path.with_suffix(".json")


def test_missing_onnx(tmp_path):
    with pytest.raises(InputFileError) as err:
        OnnxPolicy.load(tmp_path / "absent.onnx")
    assert err.value.path == tmp_path / "absent.onnx"


@pytest.mark.parametrize(
    "text",
    ["{not json", "[]", '{"task": {}, "obs": {"dim": 5}}', '{"obs": {"dim": "many"}}'],
)
def test_json_that_is_not_a_policy_description(standing_policy, tmp_path, text):
    onnx_path = copy_policy(standing_policy, tmp_path / "p")
    onnx_path.with_suffix(".json").write_text(text)
    with pytest.raises(InputFileError) as err:
        OnnxPolicy.load(onnx_path)
    assert err.value.path == onnx_path.with_suffix(".json")


def test_onnx_file_that_is_not_a_model(standing_policy, tmp_path):
    onnx_path = copy_policy(standing_policy, tmp_path / "p")
    onnx_path.write_bytes(b"definitely not protobuf" * 10)
    with pytest.raises(InputFileError) as err:
        OnnxPolicy.load(onnx_path)
    assert err.value.path == onnx_path


# --- playback -------------------------------------------------------------------------------


def test_rollout_shapes_time_axis_and_targets(standing_policy):
    dance = make_dance(2.4, lift_m=0.1)
    calls = []
    result = rollout(dance, OnnxPolicy.load(standing_policy), progress=lambda i, n: calls.append(i))
    n = dance.targets_m.shape[0]
    assert result.fps == FPS
    assert result.time_s.shape == (n,) and result.qpos.shape == (n, 7 + GO1.num_joints)
    assert result.feet_m.shape == (n, 4) and result.targets_m.shape == (n, 4)
    np.testing.assert_allclose(result.time_s, dance.time_s)
    np.testing.assert_allclose(result.targets_m, dance.targets_m, atol=1e-7)
    assert np.all(np.isfinite(result.qpos)) and np.all(np.isfinite(result.feet_m))
    assert calls == list(range(1, n + 1))
    assert result.sim_wall_s > 0


def test_rollout_of_a_standing_policy_does_not_fall(standing_policy):
    """Zero actions hold the nominal pose: no falls, feet on the floor, base at height."""
    result = rollout(make_dance(2.0, lift_m=0.0), OnnxPolicy.load(standing_policy))
    assert result.falls_s == []
    settled = slice(25, None)
    assert np.abs(result.feet_m[settled]).max() < 0.01
    assert np.all((result.qpos[settled, 2] > 0.25) & (result.qpos[settled, 2] < 0.30))
    # The recorded qpos is the robot's: it starts in the home pose.
    np.testing.assert_allclose(result.qpos[0, 7:], GO1.nominal_joint_pos_rad, atol=1e-6)


def test_rollout_refuses_a_dance_at_another_rate(standing_policy):
    dance = make_dance(1.0, lift_m=0.0)
    dance.fps = 30.0
    with pytest.raises(QuaddanceError, match="30"):
        rollout(dance, OnnxPolicy.load(standing_policy))


def test_rollout_refuses_a_policy_trained_with_other_observations(standing_policy, tmp_path):
    onnx_path = copy_policy(standing_policy, tmp_path / "p")

    def longer_history(meta):
        meta["task"]["obs"]["history_len"] += 1

    edit_json(onnx_path, longer_history)
    with pytest.raises(QuaddanceError, match="observations"):
        rollout(make_dance(1.0, lift_m=0.0), OnnxPolicy.load(onnx_path))


def test_rollout_goes_on_after_falls(collapsing_policy):
    dance = make_dance(2.0, lift_m=0.1)
    result = rollout(dance, OnnxPolicy.load(collapsing_policy))
    falls = np.array(result.falls_s)
    assert len(falls) >= 3
    assert np.all(np.diff(falls) > 0) and falls[0] > 0 and falls[-1] <= dance.duration_s
    # After each fall the robot stands up again and the song carries on where it was.
    np.testing.assert_allclose(result.targets_m, dance.targets_m, atol=1e-7)
    after_fall = np.round(falls * FPS).astype(int)
    after_fall = after_fall[after_fall < len(dance.time_s)]
    np.testing.assert_allclose(result.qpos[after_fall, 2], GO1.init_base_height_m, atol=1e-6)
