"""End to end: `quaddance dance` and `quaddance eval` with the shipped policy."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf
from dance_keys import DANCE_FOOT_KEYS, DANCE_METRIC_KEYS
from test_whole_body_sim import check_rollout_and_body_metrics

from quaddance.errors import InputFileError, QuaddanceError
from quaddance.music.synth import render_song
from quaddance.play.dance import DanceJob, run_dance
from quaddance.play.policy import OnnxPolicy, shipped_policy_path
from quaddance.robots import GO1


@pytest.fixture(scope="module")
def short_song(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("song") / "short.wav"
    y, _ = render_song(120.0, 4.0, seed=3)
    sf.write(path, y, 22050)
    return path


def test_shipped_policy_loads_and_matches_the_task():
    policy = OnnxPolicy.load(shipped_policy_path())
    from quaddance.sim.observations import ActorObservation

    layout = ActorObservation(policy.task, 1).layout
    assert sum(s.size for s in layout) == policy.obs_dim
    actions = policy.act(np.zeros((1, policy.obs_dim), np.float32))
    assert actions.shape == (1, 12) and np.isfinite(actions).all()


def test_dance_writes_video_plot_and_complete_metrics(short_song, tmp_path):
    from quaddance.play.video import video_info

    out = run_dance(DanceJob(out_dir=tmp_path, song=short_song, width=320, height=240))
    metrics = json.loads((tmp_path / "metrics.json").read_text())
    assert set(metrics) >= DANCE_METRIC_KEYS
    assert set(metrics["front"]) == {"fl", "fr"}
    for foot in ("fl", "fr"):
        assert set(metrics["front"][foot]) >= DANCE_FOOT_KEYS
        assert metrics["front"][foot]["mae_m"] is not None
    assert metrics["duration_s"] == pytest.approx(4.0, abs=0.05)
    assert metrics["realtime_factor_render"] is not None
    info = video_info(tmp_path / "dance.mp4")
    assert info["duration_s"] == pytest.approx(4.0, abs=0.2)
    assert info["has_audio"]
    assert (tmp_path / "feet.png").stat().st_size > 10_000
    assert out.dance.targets_m.shape[1] == 4


def test_dance_cli_without_video(short_song, tmp_path):
    # A video of an earlier run in the folder is kept, and named as not this run's.
    older = tmp_path / "dance.mp4"
    older.write_bytes(b"an earlier run's video")
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "quaddance.cli",
            "dance",
            str(short_song),
            "--no-video",
            "--out",
            str(tmp_path),
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    # It ends without the interpreter's teardown (`cli._exit_without_teardown`): nothing
    # may be left for multiprocessing's resource tracker to warn about.
    assert "Warning" not in proc.stderr and "Traceback" not in proc.stderr, proc.stderr
    assert older.read_bytes() == b"an earlier run's video"
    notes = [line for line in proc.stderr.splitlines() if line.startswith("note:")]
    assert notes == [f"note: {older} is from an earlier run (this one did not write it)"]
    metrics = json.loads((tmp_path / "metrics.json").read_text())
    assert metrics["realtime_factor_render"] is None
    assert metrics["realtime_factor_sim"] > 0  # a rate; its speed is benchmarked, not tested
    check_rollout_and_body_metrics(tmp_path, 4.0)


@pytest.mark.parametrize(
    ("content", "suffix", "needle"),
    [(b"not audio at all", ".wav", "bad.wav"), (b"", ".mp3", "bad.mp3"), (b"x", ".xyz", "bad.xyz")],
)
def test_dance_cli_bad_song_is_one_clear_line(tmp_path, content, suffix, needle):
    bad = tmp_path / f"bad{suffix}"
    bad.write_bytes(content)
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "quaddance.cli",
            "dance",
            str(bad),
            "--no-video",
            "--out",
            str(tmp_path / "o"),
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 2
    assert needle in proc.stderr
    assert "Traceback" not in proc.stderr
    errors = [line for line in proc.stderr.splitlines() if "error" in line.lower()]
    assert len(errors) == 1 and errors[0].startswith("quaddance: error: ")


def test_analysis_in_a_second_process_makes_the_same_dance(short_song, tmp_path):
    """`dance` analyses the song in another process while it loads torch: same dance."""
    here = run_dance(DanceJob(out_dir=tmp_path / "here", song=short_song, video=False))
    there = run_dance(
        DanceJob(out_dir=tmp_path / "there", song=short_song, video=False, analysis_process=True)
    )
    assert here.dance.beats_s.size > 0
    np.testing.assert_array_equal(here.dance.beats_s, there.dance.beats_s)
    np.testing.assert_array_equal(here.dance.targets_m, there.dance.targets_m)
    np.testing.assert_array_equal(here.dance.body_targets, there.dance.body_targets)
    # The beat metrics are computed in the helper too.
    for key in ("beat_coverage", "body"):
        assert here.metrics[key] == there.metrics[key]


def test_missing_song_is_reported(tmp_path):
    with pytest.raises(InputFileError, match=r"nope\.wav"):
        run_dance(DanceJob(out_dir=tmp_path, song=tmp_path / "nope.wav", video=False))


def test_silent_and_too_short_audio_are_refused(tmp_path):
    silent, short = tmp_path / "silent.wav", tmp_path / "short.wav"
    sf.write(silent, np.zeros(22050 * 5, np.float32), 22050)
    sf.write(short, 0.3 * np.random.default_rng(0).standard_normal(22050).astype(np.float32), 22050)
    for path in (silent, short):
        with pytest.raises(QuaddanceError, match=re.escape(path.name)):
            run_dance(DanceJob(out_dir=tmp_path / "o", song=path, video=False))


def test_policy_whose_json_disagrees_with_the_task_is_refused(tmp_path, short_song):
    src = shipped_policy_path()
    onnx = tmp_path / "p.onnx"
    onnx.write_bytes(src.read_bytes())
    meta = json.loads(src.with_suffix(".json").read_text())
    meta["task"]["obs"]["history_len"] += 2  # the task would make more observations
    onnx.with_suffix(".json").write_text(json.dumps(meta))
    with pytest.raises(QuaddanceError, match="observations"):
        run_dance(DanceJob(out_dir=tmp_path / "o", song=short_song, policy=onnx, video=False))


def test_a_failing_render_keeps_the_previous_video(short_song, tmp_path, monkeypatch):
    old = tmp_path / "dance.mp4"
    old.write_bytes(b"previous good video")
    from quaddance.play.video import encode

    encoder_args = encode.encoder_args

    def broken_encoder(*args, **kwargs):
        # A real failure of the encoder, after the workers have started rendering.
        return [a if a != "libx264" else "no_such_codec" for a in encoder_args(*args, **kwargs)]

    monkeypatch.setattr(encode, "encoder_args", broken_encoder)
    with pytest.raises(QuaddanceError, match="ffmpeg could not write"):
        run_dance(DanceJob(out_dir=tmp_path, song=short_song, width=160, height=120))
    assert old.read_bytes() == b"previous good video"
    assert sorted(p.name for p in tmp_path.iterdir() if p.suffix == ".mp4") == ["dance.mp4"]


def test_eval_reports_each_item_and_the_mean(short_song, tmp_path):
    from quaddance.play.evaluate import evaluate

    second = tmp_path / "second.wav"
    y, _ = render_song(96.0, 4.0, seed=5)
    sf.write(second, y, 22050)
    report = tmp_path / "report.md"
    rows = evaluate([short_song, second], None, report)
    text = report.read_text()
    assert len(rows) == 2
    assert "short.wav" in text and "second.wav" in text and "**mean**" in text
    assert report.with_suffix(".png").exists()


def test_shipped_feedforward_table_is_the_one_the_task_computes():
    """Playback uses the table from the policy's JSON; training computes it: they agree."""
    from quaddance.sim.feedforward import lift_table

    meta = json.loads(shipped_policy_path().with_suffix(".json").read_text())
    shipped = np.asarray(meta["front_feedforward"]["thigh_calf_offsets_rad"])
    np.testing.assert_allclose(shipped, lift_table(GO1), atol=1e-6)


def test_policy_json_without_its_feedforward_table_is_refused(tmp_path):
    src = shipped_policy_path()
    onnx = tmp_path / "p.onnx"
    onnx.write_bytes(src.read_bytes())
    meta = json.loads(src.with_suffix(".json").read_text())
    del meta["front_feedforward"]
    onnx.with_suffix(".json").write_text(json.dumps(meta))
    with pytest.raises(InputFileError, match="front_feedforward"):
        OnnxPolicy.load(onnx)
