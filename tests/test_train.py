"""PPO training: learning, checkpoints and resume, ONNX export, the target bank, the CLI."""

from __future__ import annotations

import csv
import dataclasses
import json
import math
import shutil
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import onnxruntime as ort
import pytest
import torch
from tensordict import TensorDict
from typer.testing import CliRunner

from quaddance.cli import app, main
from quaddance.errors import InputFileError, OutputFileError
from quaddance.play.policy_spec import PolicySpec
from quaddance.robots import GO1, GO2
from quaddance.sim import tasks
from quaddance.train import TrainCfg, Trainer, build_bank

NUM_ENVS = 8
STEPS_PER_ENV = 24  # the cpu preset's


def small_bank() -> np.ndarray:
    """(2, 1100, 4) targets at 50 Hz: a few front-foot lifts, rear feet down."""
    bank = np.zeros((2, 1100, 4), np.float32)
    for start in range(50, 1100, 150):
        bank[0, start : start + 25, 0] = 0.08
        bank[1, start + 40 : start + 60, 1] = 0.05
    return bank


def make_cfg(run_dir, reward_set: str = "paper", **kwargs) -> TrainCfg:
    task = tasks.paws_only(reward_set, num_envs=NUM_ENVS)
    return TrainCfg(run_dir=run_dir, preset="cpu", bank_size=2, task=task, **kwargs)


def actor_state(trainer: Trainer) -> dict[str, torch.Tensor]:
    return {k: v.detach().clone() for k, v in trainer.alg.get_policy().state_dict().items()}


@dataclass
class TrainedRun:
    trainer: Trainer
    initial_actor: dict[str, torch.Tensor]  # before learning
    rows: list[dict]
    onnx_path: Path
    json_path: Path

    @property
    def run_dir(self) -> Path:
        return self.trainer.cfg.run_dir


@pytest.fixture(scope="module")
def trained(tmp_path_factory) -> TrainedRun:
    """A trainer after 2 PPO iterations with Table 1's third reward set, exported."""
    run_dir = tmp_path_factory.mktemp("run")
    cfg = make_cfg(run_dir, "table1-3", iterations=2)
    trainer = Trainer(cfg, bank=small_bank(), log=lambda *a: None)
    initial = actor_state(trainer)
    rows = trainer.learn(2, progress=False)
    onnx_path, json_path = trainer.export()
    return TrainedRun(trainer, initial, rows, onnx_path, json_path)


# --- learning -------------------------------------------------------------------------------


def test_two_iterations_learn_and_log_a_curve(trained):
    t = trained.trainer
    assert (t.iteration, t.env_steps) == (2, 2 * STEPS_PER_ENV * NUM_ENVS)
    assert [r["iteration"] for r in trained.rows] == [1, 2]
    for row in trained.rows:
        assert math.isfinite(row["value_loss"]) and math.isfinite(row["surrogate_loss"])
        assert math.isfinite(row["reward_per_step"]) and row["action_std"] > 0
        assert 0 <= row["front_abs_err_m"] < 0.5
    # The update changed the actor.
    after = actor_state(t)
    assert any(not torch.equal(after[k], v) for k, v in trained.initial_actor.items())
    with (trained.run_dir / "curve.csv").open() as f:
        curve = list(csv.DictReader(f))
    assert [int(r["iteration"]) for r in curve] == [1, 2]
    assert float(curve[-1]["env_steps"]) == t.env_steps
    assert (trained.run_dir / "checkpoint.pt").is_file()


def test_resume_restores_counters_weights_and_appends_to_the_curve(trained, tmp_path):
    run_dir = tmp_path / "run"
    shutil.copytree(trained.run_dir, run_dir)
    cfg = make_cfg(run_dir, "table1-3", resume=True)
    resumed = Trainer(cfg, bank=small_bank(), log=lambda *a: None)
    assert (resumed.iteration, resumed.env_steps) == (2, trained.trainer.env_steps)
    assert resumed.wall_s == pytest.approx(trained.trainer.wall_s)
    expected = actor_state(trained.trainer)
    got = actor_state(resumed)
    assert got.keys() == expected.keys()
    for k in expected:
        torch.testing.assert_close(got[k], expected[k], rtol=0, atol=0)
    resumed.learn(1, progress=False)
    assert resumed.iteration == 3
    with (run_dir / "curve.csv").open() as f:
        assert [int(r["iteration"]) for r in csv.DictReader(f)] == [1, 2, 3]


# --- export ---------------------------------------------------------------------------------


def test_onnx_export_equals_the_deterministic_torch_policy(trained):
    policy = trained.trainer.alg.get_policy()
    # The running normaliser moved during learning, so this also checks it is exported.
    assert policy.obs_normalizer.mean.abs().max() > 0
    session = ort.InferenceSession(str(trained.onnx_path), providers=["CPUExecutionProvider"])
    dim = session.get_inputs()[0].shape[-1]
    obs = torch.randn(16, dim, generator=torch.Generator().manual_seed(0)) * 2.0
    policy.eval()
    try:
        with torch.no_grad():
            expected = policy(TensorDict({"actor": obs}, batch_size=[16]), stochastic_output=False)
    finally:
        policy.train()
    (got,) = session.run(None, {session.get_inputs()[0].name: obs.numpy()})
    assert got.shape == (16, GO1.num_joints)
    np.testing.assert_allclose(got, expected.numpy(), atol=1e-5, rtol=1e-5)


def test_policy_json_describes_the_policy(trained):
    meta = json.loads(trained.json_path.read_text())
    env = trained.trainer.env
    dim = env.obs_layout.actor_dim
    assert meta["obs"]["dim"] == dim == env.get_observations()["actor"].shape[1]
    assert [(t["name"], t["size"]) for t in meta["obs"]["terms"]] == [
        (t.name, t.size) for t in env.obs_layout.actor
    ]
    # Every actor term names the robot sensor it comes from: nothing privileged.
    assert {t["source"] for t in meta["obs"]["terms"]} <= {
        "imu",
        "dance",
        "joint_encoders",
        "kinematics",
        "previous_action",
        "imu+joint_encoders+kinematics+previous_action",
    }
    session = ort.InferenceSession(str(trained.onnx_path), providers=["CPUExecutionProvider"])
    assert session.get_inputs()[0].shape[-1] == dim
    assert meta["joint_names"] == list(GO1.joint_names)
    assert meta["feet"] == ["FL", "FR", "RL", "RR"]
    np.testing.assert_allclose(meta["action_scale"], [0.125, 0.25, 0.25] * 4)
    assert meta["nominal_joint_pos_rad"] == pytest.approx(list(GO1.nominal_joint_pos_rad))
    assert (meta["policy_hz"], meta["decimation"], meta["sim_dt_s"]) == (50.0, 4, 0.005)
    assert meta["training"]["iterations"] == 2
    assert meta["training"]["num_envs"] == NUM_ENVS


def test_policy_json_task_is_the_task_that_was_trained(trained):
    task = json.loads(trained.json_path.read_text())["task"]
    front = task["rewards"]["front_tracking"]
    assert front == {
        "fn": "front_tracking",
        "weight": 1.0,
        "params": {"c_f": 60.0, "lambda_f": 100.0},
        "curriculum": False,
        "per_step": True,
    }
    assert list(task["rewards"]) == list(trained.trainer.cfg.task.rewards)
    assert task["num_envs"] == NUM_ENVS
    # The JSON's task is the trained one, reward terms included.
    spec = PolicySpec.load(trained.json_path)
    assert spec.task_cfg == trained.trainer.cfg.task


# --- resume errors --------------------------------------------------------------------------


def test_resume_without_a_checkpoint_names_the_file(tmp_path):
    with pytest.raises(InputFileError) as err:
        Trainer(make_cfg(tmp_path, resume=True), bank=small_bank(), log=lambda *a: None)
    assert err.value.path == tmp_path / "checkpoint.pt"
    assert "checkpoint" in err.value.problem


def _truncated(trained, path):
    data = (trained.run_dir / "checkpoint.pt").read_bytes()
    path.write_bytes(data[: len(data) // 2])


def _without_counters(trained, path):
    # A checkpoint of the PPO models only (as rsl-rl's own runner writes one).
    torch.save(trained.trainer.alg.save(), path)


@pytest.mark.parametrize(
    "corrupt",
    [
        pytest.param(_truncated, id="truncated"),
        pytest.param(lambda trained, path: path.write_bytes(b""), id="empty"),
        pytest.param(
            lambda trained, path: path.write_text("not a checkpoint\n" * 20),
            id="text",
        ),
        pytest.param(
            _without_counters,
            id="no-counters",
        ),
    ],
)
def test_resume_from_a_corrupt_checkpoint_names_the_file(trained, tmp_path, corrupt):
    corrupt(trained, tmp_path / "checkpoint.pt")
    with pytest.raises(InputFileError) as err:
        Trainer(make_cfg(tmp_path, resume=True), bank=small_bank(), log=lambda *a: None)
    assert err.value.path == tmp_path / "checkpoint.pt"


# --- target bank ----------------------------------------------------------------------------


def test_resume_with_another_task_points_to_init_from(trained, tmp_path):
    run_dir = tmp_path / "run"
    shutil.copytree(trained.run_dir, run_dir)
    cfg = make_cfg(run_dir, resume=True)
    cfg.task.whole_body = True  # the paws-only run's networks have fewer inputs
    with pytest.raises(InputFileError, match="--init-from") as info:
        Trainer(cfg, bank=small_bank(), log=lambda *a: None)
    assert "checkpoint.pt" in str(info.value)


def test_init_from_an_older_checkpoint_carries_the_shared_inputs_over(trained, tmp_path):
    """A paws-only checkpoint whose config holds the flat reward weights of older versions
    starts a whole-body run: shared input columns keep their weights, new ones start at 0."""
    state = torch.load(trained.run_dir / "checkpoint.pt", weights_only=True)
    config = json.loads(state["config_json"])
    for key in ("base_height_target_m", "curriculum_env_steps"):  # newer than those configs
        del config["task"][key]
    config["task"]["scene"]["robot"] = {"name": "unitree_go1"}  # where some held the robot
    config["task"]["rewards"] = {"c_f": 60.0, "lambda_f": 100.0, "curriculum_terms": ["foot_slide"]}
    state["config_json"] = json.dumps(config)
    old = tmp_path / "old.pt"
    torch.save(state, old)
    task = tasks.whole_body(num_envs=NUM_ENVS, curriculum_env_steps=None)
    cfg = TrainCfg(run_dir=tmp_path / "run", bank_size=2, task=task, init_from=old)
    bank = np.concatenate([small_bank(), np.zeros_like(small_bank())], axis=2)
    logs = []
    trainer = Trainer(cfg, bank=bank, log=logs.append)
    old_cols = trained.trainer.env.obs_layout.column_names()["actor"]
    new_cols = trainer.env.obs_layout.column_names()["actor"]
    assert len(new_cols) == len(old_cols) + 4 + 12 + 1
    old_w = state["actor_state_dict"]["mlp.0.weight"]
    new_w = trainer.alg.save()["actor_state_dict"]["mlp.0.weight"]
    for j, name in enumerate(new_cols):
        want = old_w[:, old_cols.index(name)] if name in old_cols else torch.zeros(len(new_w))
        torch.testing.assert_close(new_w[:, j], want)
    assert f"{len(old_cols)} of {len(new_cols)} actor inputs carried over" in logs[-1]


def test_a_task_without_reward_terms_is_refused(tmp_path):
    from quaddance.errors import QuaddanceError
    from quaddance.sim.config import DanceTaskCfg

    cfg = TrainCfg(run_dir=tmp_path / "run", task=DanceTaskCfg(whole_body=True, num_envs=2))
    with pytest.raises(QuaddanceError, match=r"no reward terms.*paws-only, whole-body"):
        Trainer(cfg, bank=small_bank(), log=lambda *a: None)
    assert not (tmp_path / "run").exists()


def test_build_bank_makes_and_caches_front_foot_targets(tmp_path):
    cfg = make_cfg(tmp_path, bank_duration_s=8.0)
    bank = build_bank(cfg)
    assert bank.shape == (2, 400, 4) and bank.dtype == np.float32
    assert np.all(np.isfinite(bank))
    assert np.all(bank[:, :, 2:] == 0)  # rear-foot targets are 0 (paper)
    assert bank[:, :, :2].max() > 0.02 and bank.min() >= 0
    assert not np.array_equal(bank[0], bank[1])
    # The run dir's copy is what a second call returns (it is not rebuilt).
    cached = np.load(tmp_path / "bank.npy")
    np.testing.assert_array_equal(cached, bank)
    np.save(tmp_path / "bank.npy", bank[:1] * 0.5)
    np.testing.assert_array_equal(build_bank(cfg), bank[:1] * 0.5)


def test_an_eq4_bank_scales_with_h0(tmp_path):
    """``target_mode="paper"``: each sequence is eq. 4's h0 * h / max(h), so halving h0 halves
    the bank, and each sequence peaks near h0 (its human peak, resampled to 50 Hz)."""
    banks = {
        h0: build_bank(
            make_cfg(tmp_path / str(h0), bank_duration_s=8.0, target_mode="paper", h0_m=h0)
        )
        for h0 in (0.5, 2.0)
    }
    np.testing.assert_allclose(banks[2.0], 4.0 * banks[0.5], rtol=1e-5, atol=1e-6)
    peaks = banks[0.5][:, :, :2].max(axis=(1, 2))
    assert np.all((peaks > 0.45) & (peaks <= 0.5 + 1e-6))
    assert np.all(banks[0.5][:, :, 2:] == 0)


def test_an_eq4_policy_records_its_targets_and_dances_them(tmp_path):
    from quaddance.pipeline import DanceSpec
    from quaddance.play.dance import spec_for_policy
    from quaddance.play.policy import OnnxPolicy

    cfg = make_cfg(tmp_path, target_mode="paper", h0_m=0.5, iterations=1)
    cfg.task = tasks.paws_only(num_envs=NUM_ENVS, c_r=-3.0, without=("rear_lift_l1",))
    trainer = Trainer(cfg, bank=small_bank(), log=lambda *a: None)
    onnx_path, json_path = trainer.export()
    meta = json.loads(json_path.read_text())
    assert meta["targets"] == {"max_height_m": GO1.max_paw_height_m, "mode": "paper", "h0_m": 0.5}
    assert meta["task"]["rewards"]["rear_lift"]["weight"] == -3.0
    assert "rear_lift_l1" not in meta["task"]["rewards"]
    spec = PolicySpec.load(json_path)
    assert (spec.targets_mode, spec.targets_h0_m) == ("paper", 0.5)
    assert spec.task_cfg == cfg.task
    targets = spec_for_policy(DanceSpec(), OnnxPolicy.load(onnx_path)).targets
    assert (targets.mode, targets.h0_m) == ("paper", 0.5)


# --- CLI ------------------------------------------------------------------------------------


def test_train_help():
    result = CliRunner().invoke(app, ["train", "--help"])
    assert result.exit_code == 0
    for option in ("--engine", "--resume", "--reward", "--preset", "--run-dir"):
        assert option in result.output


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--engine", "nope"], "cpu or gpu"),
        (["--preset", "huge"], "huge"),
        (["--reward", "table1-9"], "table1-9"),
        (["--mode", "minmax"], "--mode must be one of feasible, paper"),
        (["--mode", "paper", "--h0", "0"], "not a finite number"),
        (["--h0", "1"], "--h0 scales eq. 4's targets: give it with --mode paper"),
        (["--c-r", "5"], "not a finite number"),
        (["--without", "nope"], "no reward term 'nope'"),
    ],
)
def test_train_rejects_bad_options_before_any_work(tmp_path, args, needle):
    run_dir = tmp_path / "run"
    result = CliRunner().invoke(app, ["train", "--run-dir", str(run_dir), *args])
    assert result.exit_code == 2
    assert needle in result.output
    assert not run_dir.exists()


def cli_train_cfg(monkeypatch, args: list[str]) -> TrainCfg:
    """The `TrainCfg` that ``quaddance train ARGS`` trains (nothing is trained)."""
    import quaddance.train as train_mod

    seen = {}

    def fake_train(cfg, **kwargs):
        seen["cfg"] = cfg
        raise SystemExit(0)

    monkeypatch.setattr(train_mod, "train", fake_train)
    monkeypatch.setattr(train_mod, "build_bank", lambda cfg: None)
    result = CliRunner().invoke(app, ["train", *args])
    assert result.exit_code == 0, result.output
    return seen["cfg"]


@pytest.mark.parametrize(
    ("args", "want"),
    [
        ([], (3_000_000, 13_000_000)),  # the default from scratch
        (["--curriculum", "0.001", "0.002"], (1_000, 2_000)),
        (["--curriculum", "0", "0"], None),  # the whole task at once
    ],
)
def test_train_whole_body_curriculum_option(tmp_path, monkeypatch, args, want):
    cfg = cli_train_cfg(monkeypatch, ["--whole-body", "--run-dir", str(tmp_path / "run"), *args])
    assert cfg.task.curriculum_env_steps == want
    # The CLI's whole-body task is the variant's, whatever the curriculum.
    assert cfg.task == tasks.whole_body(num_envs=256, curriculum_env_steps=want)


@pytest.mark.parametrize(
    ("args", "mode", "h0_m", "c_r", "dropped"),
    [
        ([], "feasible", 2.0, -30.0, ()),
        (["--mode", "paper", "--h0", "0.5"], "paper", 0.5, -30.0, ()),
        (["--c-r", "-3", "--without", "rear_lift_l1"], "feasible", 2.0, -3.0, ("rear_lift_l1",)),
        (["--without", "ours"], "feasible", 2.0, -30.0, tasks.OUR_TERMS),
    ],
)
def test_train_study_options_reach_the_bank_and_the_rewards(
    tmp_path, monkeypatch, args, mode, h0_m, c_r, dropped
):
    cfg = cli_train_cfg(monkeypatch, ["--run-dir", str(tmp_path / "run"), *args])
    assert (cfg.target_mode, cfg.h0_m) == (mode, h0_m)
    assert cfg.task.rewards["rear_lift"].weight == c_r
    assert set(tasks.dance_rewards()) - set(cfg.task.rewards) == set(dropped)
    assert cfg.task == tasks.paws_only(num_envs=256, c_r=c_r, without=dropped)


def test_train_curriculum_rejects_an_end_before_its_start(tmp_path):
    run_dir = tmp_path / "run"
    args = ["train", "--whole-body", "--run-dir", str(run_dir), "--curriculum", "5", "2"]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 2 and "--curriculum" in result.output
    assert not run_dir.exists()


def test_cli_resume_without_checkpoint_is_one_line_and_exit_2(tmp_path, monkeypatch, capsys):
    run_dir = tmp_path / "run"
    argv = ["quaddance", "train", "--resume", "--run-dir", str(run_dir), "--num-envs", "2"]
    monkeypatch.setattr(sys, "argv", [*argv, "--bank-size", "1", "--iterations", "1"])
    with pytest.raises(SystemExit) as exc:
        main()
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("quaddance: error:")
    assert str(run_dir / "checkpoint.pt") in err[-1]
    assert not any("Traceback" in line for line in err)


def test_sigterm_stops_training_with_a_checkpoint_of_the_last_iteration(tmp_path):
    """`kill` (as a job scheduler does) loses no finished iteration."""
    import csv
    import signal
    import subprocess
    import sys
    import time

    run = tmp_path / "run"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "quaddance.cli",
            "train",
            "--run-dir",
            str(run),
            "--num-envs",
            "8",
            "--bank-size",
            "2",
            "--iterations",
            "100000",
            "--no-progress",
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    curve = run / "curve.csv"
    deadline = time.monotonic() + 240
    while time.monotonic() < deadline and (
        not curve.exists() or len(curve.read_text().splitlines()) < 3
    ):
        time.sleep(0.5)
    proc.send_signal(signal.SIGTERM)
    proc.wait(timeout=120)
    state = torch.load(run / "checkpoint.pt", weights_only=True)
    with curve.open() as f:
        rows = list(csv.DictReader(f))
    assert len(rows) >= 2
    assert state["iteration"] == int(rows[-1]["iteration"])


# --- a run folder holds one run ---------------------------------------------------------------


@pytest.mark.parametrize(
    "content",
    [
        pytest.param(bytes(range(256)) * 40, id="random-bytes"),
        pytest.param(b"", id="empty"),
        pytest.param(b"\x08\x01\x12\x04onnx" * 30, id="onnx-like"),
    ],
)
def test_init_from_a_file_that_is_no_checkpoint_is_one_line_before_any_work(
    tmp_path, monkeypatch, capsys, content
):
    """torch.load raised an UnpicklingError (a traceback) or an EOFError (which click calls an
    abort: `quaddance: interrupted`); the bank was built before the file was read."""
    bad = tmp_path / "bad.pt"
    bad.write_bytes(content)
    run_dir = tmp_path / "run"
    monkeypatch.setattr(sys, "argv", ["quaddance", "train", "--run-dir", str(run_dir),
                                      "--init-from", str(bad), "--num-envs", "2",
                                      "--bank-size", "1", "--iterations", "1"])  # fmt: skip
    with pytest.raises(SystemExit) as exc:
        main()
    err = capsys.readouterr().err.strip().splitlines()
    assert exc.value.code == 2 and len(err) == 1, err
    assert err[0].startswith(f"quaddance: error: {bad}: not a quaddance checkpoint"), err
    assert not run_dir.exists()


def test_resume_refuses_options_that_change_what_the_run_learns(trained, tmp_path):
    run_dir = tmp_path / "run"
    shutil.copytree(trained.run_dir, run_dir)
    before = (run_dir / "checkpoint.pt").read_bytes()
    changed = make_cfg(run_dir, "table1-3", resume=True, seed=5)
    changed.task = tasks.paws_only("table1-3", num_envs=NUM_ENVS, robot=GO2)
    with pytest.raises(InputFileError) as info:
        Trainer(changed, bank=small_bank(), log=lambda *a: None)
    message = str(info.value)
    assert message.startswith(f"{run_dir / 'checkpoint.pt'}: --resume continues a run")
    assert "robot (run: unitree_go1, now: unitree_go2)" in message
    assert "seed (run: 1, now: 5)" in message
    # How long and where it runs may change: more envs, another budget.
    more = make_cfg(run_dir, "table1-3", resume=True, max_minutes=1.0)
    more.task = tasks.paws_only("table1-3", num_envs=2 * NUM_ENVS)
    assert Trainer(more, bank=small_bank(), log=lambda *a: None).iteration == 2
    assert (run_dir / "checkpoint.pt").read_bytes() == before


def test_a_new_run_in_a_folder_of_another_run_is_refused(trained, tmp_path):
    run_dir = tmp_path / "run"
    shutil.copytree(trained.run_dir, run_dir)
    before = {p.name: p.read_bytes() for p in run_dir.iterdir() if p.is_file()}
    with pytest.raises(OutputFileError, match=r"holds another run \(checkpoint.pt\); continue"):
        Trainer(make_cfg(run_dir, "table1-3"), bank=small_bank(), log=lambda *a: None)
    assert {p.name: p.read_bytes() for p in run_dir.iterdir() if p.is_file()} == before


def test_a_new_run_starts_the_curve_of_a_run_killed_before_its_first_checkpoint(tmp_path):
    """kill -9 before the first checkpoint leaves curve rows and nothing to resume: the next
    run (a `quaddance study` that continues, say) starts the curve again."""
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    (run_dir / "curve.csv").write_text("iteration,reward_per_step\n1,-0.5\n2,-0.4\n")
    trainer = Trainer(make_cfg(run_dir, "table1-3"), bank=small_bank(), log=lambda *a: None)
    trainer.learn(1, progress=False)
    with (run_dir / "curve.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert [int(r["iteration"]) for r in rows] == [1] and "front_abs_err_m" in rows[0]
    assert (run_dir / "curve.unfinished.csv").read_text().endswith("2,-0.4\n")  # kept aside


def test_resume_drops_the_curve_rows_after_its_checkpoint(trained, tmp_path):
    """Killed (kill -9) after a row was written but before the next checkpoint: the resumed
    run redoes that iteration, and the curve holds it once."""
    run_dir = tmp_path / "run"
    shutil.copytree(trained.run_dir, run_dir)
    curve = run_dir / "curve.csv"
    lines = curve.read_text().splitlines(keepends=True)
    curve.write_text("".join(lines) + lines[-1].replace("2,", "3,", 1) + "\\x00\\x00")  # cut short
    resumed = Trainer(make_cfg(run_dir, "table1-3", resume=True), bank=small_bank(),
                      log=lambda *a: None)  # fmt: skip
    resumed.learn(1, progress=False)
    with curve.open() as f:
        assert [int(r["iteration"]) for r in csv.DictReader(f)] == [1, 2, 3]


def test_the_cached_bank_follows_the_bank_options(tmp_path):
    """`bank.npy` is rebuilt when the options that made it change, or when it does not read;
    with `--bank-size 1 --seed 7` the cache of a 2-song bank of seed 1 was returned."""
    first = build_bank(make_cfg(tmp_path, bank_duration_s=8.0))
    other = dataclasses.replace(make_cfg(tmp_path, bank_duration_s=8.0, seed=7), bank_size=1)
    other_seed = build_bank(other)
    assert other_seed.shape == (1, 400, 4) and not np.array_equal(other_seed[0], first[0])
    assert json.loads((tmp_path / "bank.json").read_text())["seed"] == 7
    (tmp_path / "bank.npy").write_bytes(b"")
    np.testing.assert_array_equal(build_bank(other), other_seed)
