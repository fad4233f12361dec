"""Held-out sets beyond the training generator, the robustness envelope, and the training
switch of the feed-forward ablation."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import soundfile as sf
import torch
from scipy.signal import find_peaks
from typer.testing import CliRunner

from benchmarks import envelope
from quaddance.choreo.motion import load_motion
from quaddance.cli import app
from quaddance.errors import InputFileError
from quaddance.music.synth import render_song
from quaddance.play.heldout import OTHER_ITEMS, render_feet, write_held_out_set
from quaddance.play.policy import shipped_policy_path
from quaddance.play.rollout import PinnedDynamics
from quaddance.robots import GO1

DURATION_S = 12.0


@pytest.fixture(scope="module")
def other_set(tmp_path_factory) -> dict[str, tuple[object, np.ndarray, np.ndarray, str]]:
    """name -> (item, designed feet at the file's rate, loaded feet, loader's description)."""
    files = write_held_out_set(tmp_path_factory.mktemp("other"), "other", DURATION_S)
    out = {}
    for item, path in zip(OTHER_ITEMS, files, strict=True):
        motion = load_motion(path)
        lifts = item.pattern(np.random.default_rng(item.seed), DURATION_S)
        designed = render_feet(lifts, DURATION_S, motion.fps)
        out[item.name] = (item, designed, motion.feet_m, motion.source)
    return out


def test_other_set_files_load_back_as_the_designed_foot_heights(other_set):
    for name, (_, designed, loaded, _) in other_set.items():
        n = min(len(designed), len(loaded))
        assert abs(len(designed) - len(loaded)) <= 1, name
        # SMPL knee axes are not exactly lateral: a few cm at the highest lifts.
        assert np.abs(designed[:n] - loaded[:n]).max() < 0.05, name
        assert loaded.max() > 0.05, name


def test_other_set_spans_formats_units_and_axes(other_set):
    sources = " | ".join(src for *_, src in other_set.values())
    for needle in ("BVH, cm", "BVH, inch", "BVH, mm", "BVH, m,", "z-up", "y-up"):
        assert needle in sources
    for needle in ("EDGE full_pose", "EDGE SMPL parameters", "AIST++ SMPL"):
        assert needle in sources
    ankles = {
        src.split("ankles ")[1].split(",")[0] for *_, src in other_set.values() if "BVH" in src
    }
    assert len(ankles) == 5  # five skeletons, five naming schemes


def _peaks(feet: np.ndarray, fps: float) -> list[np.ndarray]:
    return [find_peaks(feet[:, k], prominence=0.03)[0] / fps for k in (0, 1)]


def test_other_set_patterns_are_what_their_names_say(other_set):
    def get(prefix):
        _, designed, loaded, _ = next(v for k, v in other_set.items() if k.startswith(prefix))
        fps = len(loaded) / DURATION_S
        return designed, loaded, fps

    _, feet, fps = get("holds_60bpm")
    up = feet.max(axis=1) > 0.9 * feet.max()
    runs = np.diff(np.flatnonzero(np.diff(np.r_[0, up.astype(int), 0])))[::2]
    assert runs.max() / fps >= 2.9  # holds of 3 beats at 60 BPM

    _, feet, fps = get("alternation_200bpm")
    peaks = np.sort(np.concatenate(_peaks(feet, fps)))
    assert np.median(np.diff(peaks)) == pytest.approx(0.3, abs=0.02)  # a step per 200 BPM beat

    _, feet, _ = get("high_knees")
    assert feet.max() >= 0.5

    _, feet, _ = get("jumps")
    assert (feet.min(axis=1) > 0.05).any()  # both feet off the floor together

    designed, _, fps = get("accelerando")
    gaps = np.diff(np.sort(np.concatenate(_peaks(designed, fps))))
    assert gaps.max() > 0.8 and gaps.min() < 0.45  # from about 60 to about 150+ BPM


# --- the envelope ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def song(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("song") / "song_4s.wav"
    y, _ = render_song(120.0, 4.0, seed=3)
    sf.write(path, y, 22050)
    return path


@pytest.fixture(scope="module")
def small_envelope(song) -> dict:
    return envelope.run_envelope(
        [song],
        conditions={"nominal": PinnedDynamics(), "friction 0.1": PinnedDynamics(friction=0.1)},
        push_bases={"nominal": PinnedDynamics()},
        vels_m_s=(0.25, 3.0),
    )


def test_envelope_reports_the_first_push_that_makes_it_fall(small_envelope):
    sweep = small_envelope["pushes"]["nominal"]
    assert [v["push_vel_m_s"] for v in sweep["per_vel"]] == [0.25, 3.0]
    assert sweep["per_vel"][0]["falls"] == 0
    assert sweep["per_vel"][1]["falls"] >= 1
    assert sweep["per_vel"][1]["pushes_followed_by_a_fall"][0]["push_s"] == 2.0
    assert sweep["first_fall_vel_m_s"] == 3.0


def test_envelope_conditions_change_the_robot(small_envelope):
    ends = small_envelope["range_ends"]
    assert ends["friction 0.1"]["dynamics"]["friction"] == 0.1
    assert ends["friction 0.1"]["mae_m"] != ends["nominal"]["mae_m"]


def test_envelope_stops_the_sweep_after_falls_in_a_row(song, monkeypatch):
    tried = []

    def fake(items, policy, settings):
        tried.append(settings.pinned.push_vel_m_s)
        return [{**_row(), "falls_s": [2.1]}]

    monkeypatch.setattr(envelope, "evaluate_items", fake)
    vels = (0.5, 1.0, 1.5, 2.0)
    result = envelope.push_sweep([song], None, PinnedDynamics(), vels, stop_after_falls=2)
    assert tried == [0.5, 1.0]
    assert result["first_fall_vel_m_s"] == 0.5
    tried.clear()
    envelope.push_sweep([song], None, PinnedDynamics(), vels)
    assert tried == [0.5]  # by default the first velocity with a fall ends the sweep


def _row() -> dict:
    from quaddance.play.metrics import dance_metrics

    t = np.arange(200) / 50.0
    feet = np.zeros((200, 4))
    return {"name": "x", **dance_metrics(t, feet, feet, [], [], 1.0, None)}


def test_bench_envelope_command_writes_json_and_markdown(
    song, small_envelope, tmp_path, monkeypatch
):
    monkeypatch.setattr(envelope, "run_envelope", lambda items, policy, log: small_envelope)
    out, report = tmp_path / "env.json", tmp_path / "env.md"
    args = ["bench", "envelope", str(song), "--out", str(out), "--report", str(report)]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    assert json.loads(out.read_text())["pushes"]["nominal"]["first_fall_vel_m_s"] == 3.0
    text = report.read_text()
    assert "first fall at 3.00 m/s" in text
    assert "| friction 0.1 |" in text
    assert "quaddance bench envelope" in text


def test_bench_envelope_robot_picks_the_robots_policy(song, small_envelope, tmp_path, monkeypatch):
    seen = []

    def fake_run(items, policy, log):
        seen.append(policy)
        return small_envelope

    monkeypatch.setattr(envelope, "run_envelope", fake_run)
    out, report = tmp_path / "env.json", tmp_path / "env.md"
    args = ["bench", "envelope", str(song), "--out", str(out), "--report", str(report)]
    assert CliRunner().invoke(app, [*args, "--robot", "go1"]).exit_code == 0
    assert seen == [shipped_policy_path(GO1)]
    # The Go1's policy on the Go2: the one-line user error naming both, nothing run.
    wrong = CliRunner().invoke(app, [*args, "--robot", "go2", "--policy", str(seen[0])])
    assert isinstance(wrong.exception, InputFileError) and len(seen) == 1
    assert "a policy for go1, not for go2" in str(wrong.exception)


# --- the feed-forward ablation's training switch ------------------------------------------


@pytest.mark.parametrize(("flags", "expected"), [([], True), (["--no-feedforward"], False)])
def test_train_no_feedforward_flag_turns_the_feedforward_off(
    tmp_path, monkeypatch, flags, expected
):
    import quaddance.train as train_mod

    seen = []

    def fake_train(cfg, **kwargs):
        seen.append(cfg)
        return SimpleNamespace(iteration=0, env_steps=0, wall_s=0.0)

    monkeypatch.setattr(train_mod, "train", fake_train)
    monkeypatch.setattr(train_mod, "build_bank", lambda cfg: np.zeros((1, 10, 4)))
    args = ["train", "--run-dir", str(tmp_path / "run"), "--no-progress", *flags]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    assert seen[0].task.front_feedforward is expected


def test_without_feedforward_the_joint_targets_are_the_policy_alone():
    from quaddance.sim.config import DanceTaskCfg
    from quaddance.sim.task import DanceEnv
    from quaddance.train import TrainCfg, policy_metadata

    bank = np.zeros((1, 60, 4), np.float32)
    bank[0, :, 0] = 0.2  # front-left asked 0.2 m up all along
    targets = {}
    for on in (True, False):
        cfg = DanceTaskCfg(num_envs=1, front_feedforward=on)
        env = DanceEnv(cfg, bank, compute_rewards=False)
        targets[on] = env.joint_targets(torch.zeros(1, 12))[0]
        meta = policy_metadata(env, TrainCfg(task=cfg))
        assert (meta["front_feedforward"] is None) is (not on)
        assert meta["task"]["front_feedforward"] is on
    nominal = torch.tensor(GO1.nominal_joint_pos_rad)
    torch.testing.assert_close(targets[False], nominal)
    assert (targets[True] - nominal).abs().max() > 0.1


def _write_curve(path: Path, err_m: list[float], gz: bool = False) -> None:
    import gzip

    lines = ["iteration,env_steps,wall_s,front_abs_err_m,rear_lift_m,fall_rate,reward_per_step"]
    for i, e in enumerate(err_m):
        lines.append(f"{i + 1},{(i + 1) * 125_000},{20.0 * (i + 1)},{e},0.001,0.0,-0.2")
    text = "\n".join(lines) + "\n"
    path.write_bytes(gzip.compress(text.encode()) if gz else text.encode())


def test_bench_ff_ablation_compares_both_runs_with_standing_still(tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    _write_curve(run / "curve.csv", [0.03, 0.03, 0.025, 0.024])  # up to 0.5 M env steps
    shipped = tmp_path / "shipped.csv.gz"
    _write_curve(shipped, [0.03, 0.02, 0.015, 0.012, 0.01, 0.009, 0.008, 0.008], gz=True)
    bank = np.zeros((2, 100, 4), np.float32)
    bank[0, :50, 0] = 0.1  # mean |front target| = 0.1 * 50 / 400
    np.save(run / "bank.npy", bank)
    same = tmp_path / "same"
    same.mkdir()
    _write_curve(same / "curve.csv", [0.03, 0.02, 0.018, 0.016])
    out, docs = tmp_path / "ablation.json", tmp_path / "docs"
    args = ["bench", "ff-ablation", str(run), "--shipped-curve", str(shipped)]
    args += ["--with-ff-run", str(same), "--out", str(out), "--docs", str(docs)]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    data = json.loads(out.read_text())
    assert data["standing_still_front_err_m"] == pytest.approx(0.0125)
    at = {name: {a["env_steps"]: a for a in r["at"]} for name, r in data["runs"].items()}
    no_ff = at["without feed-forward"]
    assert no_ff[500_000]["front_abs_err_m"] == pytest.approx(0.024)
    assert no_ff[1_000_000]["front_abs_err_m"] is None  # the run never got there
    assert at["with feed-forward (shipped run)"][1_000_000]["front_abs_err_m"] == pytest.approx(
        0.008
    )
    # The window mean over (400 k, 500 k] env steps holds only the 4th row: 0.016.
    same_at = at["with feed-forward, same settings"]
    assert same_at[500_000]["front_abs_err_m"] == pytest.approx(0.016)
    assert (docs / "learning_curve_with_feedforward.csv").read_bytes() == (
        same / "curve.csv"
    ).read_bytes()
    assert (docs / "learning_curve_no_feedforward.csv").read_bytes() == (
        run / "curve.csv"
    ).read_bytes()
    assert (docs / "learning_curve_no_feedforward.png").stat().st_size > 0
    assert (docs / "learning_curve_ff_ablation.png").stat().st_size > 0


def test_bench_ff_ablation_without_a_run_is_one_line_and_exit_2(tmp_path, monkeypatch, capsys):
    import sys

    from quaddance.cli import main

    monkeypatch.setattr(sys, "argv", ["quaddance", "bench", "ff-ablation", str(tmp_path)])
    with pytest.raises(SystemExit) as exc:
        main()
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("quaddance: error:")
    assert "curve.csv" in err[0]
