"""Outputs of `quaddance dance`: metrics, Fig.-4 plots and the video with music."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest
from dance_keys import DANCE_FOOT_KEYS, DANCE_METRIC_KEYS

from quaddance.errors import InputFileError, QuaddanceError
from quaddance.play import metrics, plots

# --- metrics -----------------------------------------------------------------------------------


def _stop_and_go(fps: float, duration_s: float, beat_s: float, shift_s: float) -> np.ndarray:
    """A coordinate that moves forward and comes to rest at t = shift + k * beat, (T, 2)."""
    t = np.arange(int(duration_s * fps)) / fps - shift_s
    x = t - np.sin(2 * np.pi * t / beat_s) * beat_s / (2 * np.pi)  # speed 1 - cos: 0 at beats
    return np.stack([x, np.zeros_like(x)], axis=1)  # a still second column adds no speed


def test_bas_is_one_on_the_beat_and_low_half_a_beat_off() -> None:
    fps, beat_s = 60.0, 0.5
    beats = np.arange(0.5, 8.0, beat_s)  # the motion's ends never count as motion beats
    on = _stop_and_go(fps, 8.0, beat_s, shift_s=0.0)
    off = _stop_and_go(fps, 8.0, beat_s, shift_s=beat_s / 2)
    found = metrics.motion_beats(on, fps)
    assert len(found) == len(beats) == 15
    np.testing.assert_allclose(found, beats, atol=1.0 / fps)
    assert metrics.beat_align_score(on, fps, beats) > 0.95
    assert metrics.beat_align_score(off, fps, beats) < 0.05


def test_bas_ignores_beats_outside_the_motion_and_handles_no_beats() -> None:
    fps, beat_s = 60.0, 0.5
    on = _stop_and_go(fps, 4.0, beat_s, shift_s=0.0)
    inside = np.arange(0.5, 3.6, beat_s)
    far_beats = np.r_[inside, 10.0, 11.0, 12.0]
    assert metrics.beat_align_score(on, fps, far_beats) == pytest.approx(
        metrics.beat_align_score(on, fps, inside)
    )
    assert np.isnan(metrics.beat_align_score(on, fps, np.array([20.0])))
    still = np.zeros((240, 2))
    assert metrics.beat_align_score(still, fps, inside) == 0.0


def test_bas_accepts_joint_positions() -> None:
    fps, beat_s = 60.0, 0.5
    x = _stop_and_go(fps, 4.0, beat_s, 0.0)[:, 0]
    joints = np.zeros((len(x), 3, 3))
    joints[:, :, 1] = x[:, None]  # three joints moving together along y
    beats = np.arange(0.5, 3.6, beat_s)
    assert metrics.beat_align_score(joints, fps, beats) > 0.95


def _hand_made_dance() -> dict[str, np.ndarray]:
    """200 frames at 50 Hz: FL follows a feasible ramp, then misses an unreachable 0.5 m."""
    n = 200
    time_s = np.arange(n) / 50.0
    targets = np.zeros((n, 4))
    targets[:100, 0] = np.linspace(0.0, 0.15, 100)
    targets[100:, 0] = 0.5
    feet = np.zeros((n, 4))
    feet[:100, 0] = targets[:100, 0]  # exact on the feasible ramp
    feet[100:, 0] = 0.2  # 0.3 m short of the unreachable target
    feet[:, 1] = 0.01  # FR hovers 1 cm above its 0 target
    feet[50:100, 2] = 0.05  # RL lifts for 1 s
    feet[:, 3] = 0.02
    return {"time_s": time_s, "targets": targets, "feet": feet}


def test_feasible_mask_follows_its_definition() -> None:
    targets = np.array(
        [
            [0.0, 0.0, 0, 0],  # both down: feasible for both
            [0.1, 0.0, 0, 0],  # FL lifts within reach: FL yes, FR no (FL is not standing)
            [0.3, 0.0, 0, 0],  # FL out of reach
            [0.1, 0.1, 0, 0],  # both up: neither
            [0.0, 0.2, 0, 0],  # FR at the limit
        ]
    )
    expected = np.array([[1, 1], [1, 0], [0, 0], [0, 0], [0, 1]], dtype=bool)
    np.testing.assert_array_equal(metrics.feasible_mask(targets, 0.2, 0.01), expected)


def test_dance_metrics_values_and_keys() -> None:
    d = _hand_made_dance()
    m = metrics.dance_metrics(
        d["time_s"], d["targets"], d["feet"], np.arange(0, 4, 0.5), [3.2], 2.0, None
    )
    assert set(m) == DANCE_METRIC_KEYS
    assert set(m["front"]) == {"fl", "fr"}
    for foot in ("fl", "fr"):
        assert set(m["front"][foot]) == DANCE_FOOT_KEYS
    assert m["duration_s"] == pytest.approx(4.0)
    assert m["falls_s"] == [3.2]
    fl, fr = m["front"]["fl"], m["front"]["fr"]
    assert fl["mae_m"] == pytest.approx(0.15)  # half the frames 0 error, half 0.3 m
    assert fl["mae_feasible_m"] == pytest.approx(0.0, abs=1e-12)
    assert fl["corr_feasible"] == pytest.approx(1.0)
    expected_corr = np.corrcoef(d["targets"][:, 0], d["feet"][:, 0])[0, 1]
    assert fl["corr"] == pytest.approx(expected_corr)
    assert fr["mae_m"] == pytest.approx(0.01)
    assert fr["mae_feasible_m"] == pytest.approx(0.01)
    assert fr["corr"] is None  # constant target: undefined, not NaN
    assert m["rear_lift_mean_m"] == pytest.approx((50 * 0.05 + 200 * 0.02) / 400)
    assert m["rear_lift_max_m"] == pytest.approx(0.05)
    assert m["realtime_factor_sim"] == pytest.approx(2.0)
    assert m["realtime_factor_render"] is None
    json.dumps(m, allow_nan=False)  # JSON-ready: no NaN anywhere


def test_rear_feet_pressed_into_the_floor_count_as_no_lift() -> None:
    t = np.arange(100) / 50.0
    feet = np.zeros((100, 4))
    feet[:, 2:] = -0.002  # soft-contact penetration
    feet[10, 3] = 0.01
    m = metrics.dance_metrics(t, np.zeros((100, 4)), feet, np.array([]), [], 1.0, None)
    assert m["rear_lift_max_m"] == pytest.approx(0.01)
    assert m["rear_lift_mean_m"] == pytest.approx(0.01 / 200)


def test_identical_tracking_gives_zero_error_and_correlation_one() -> None:
    t = np.arange(300) / 50.0
    targets = np.zeros((300, 4))
    targets[:, 0] = 0.1 * np.sin(2 * np.pi * t) ** 2
    m = metrics.dance_metrics(t, targets, targets.copy(), np.array([1.0, 2.0]), [], 1.0, 3.0)
    assert m["front"]["fl"]["mae_m"] == 0.0
    assert m["front"]["fl"]["corr"] == pytest.approx(1.0)
    assert m["realtime_factor_render"] == pytest.approx(2.0)


def test_pearson_skips_nan_and_rejects_constant() -> None:
    a = np.array([0.0, 1.0, np.nan, 3.0, 4.0])
    b = np.array([0.0, 2.0, 5.0, np.nan, 8.0])
    assert metrics.pearson(a, b) == pytest.approx(1.0)
    assert metrics.pearson(np.ones(5), np.arange(5.0)) is None
    assert metrics.pearson(np.array([1.0]), np.array([2.0])) is None


def test_metrics_reject_bad_shapes() -> None:
    with pytest.raises(QuaddanceError, match=r"\(T, 4\)"):
        metrics.dance_metrics(np.arange(3.0), np.zeros((3, 2)), np.zeros((3, 4)), [], [], 1, None)


def test_default_feasible_limit_is_the_feasible_target_ceiling() -> None:
    from quaddance.targets import TargetConfig

    ceiling_m = TargetConfig().max_height_m
    targets = np.zeros((3, 4))
    targets[1, 0] = ceiling_m  # reachable: the highest lift the feasible mode asks for
    targets[2, 0] = ceiling_m + 0.02
    np.testing.assert_array_equal(metrics.feasible_mask(targets)[:, 0], [True, True, False])


def test_summary_table_shows_the_numbers() -> None:
    from rich.console import Console

    d = _hand_made_dance()
    m = metrics.dance_metrics(d["time_s"], d["targets"], d["feet"], [0.5], [3.2], 2.0, 8.0)
    console = Console(record=True, width=100)
    console.print(metrics.summary_table(m))
    text = console.export_text()
    assert "15.0 cm" in text  # FL MAE
    assert "first at 3.2 s" in text
    assert "n/a" in text  # FR correlation with a constant target


# --- plots ---------------------------------------------------------------------------------------


def _png_size(path: Path) -> tuple[int, int]:
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    return int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")


def test_plot_feet_writes_a_figure(tmp_path: Path) -> None:
    d = _hand_made_dance()
    out = plots.plot_feet(
        tmp_path / "feet.png", d["time_s"], d["targets"], d["feet"], [0.5, 1.0], "test song"
    )
    assert out.stat().st_size > 20_000
    width, height = _png_size(out)
    assert (width, height) == (1200, 780)  # 10 x 6.5 inches at 120 dpi
    assert list(tmp_path.iterdir()) == [out]  # no temporary left behind


def test_plot_feet_rejects_mismatched_arrays(tmp_path: Path) -> None:
    d = _hand_made_dance()
    with pytest.raises(QuaddanceError):
        plots.plot_feet(tmp_path / "x.png", d["time_s"][:10], d["targets"], d["feet"], [])
    assert not (tmp_path / "x.png").exists()


def test_plot_eval_writes_a_figure(tmp_path: Path) -> None:
    d = _hand_made_dance()
    m = metrics.dance_metrics(d["time_s"], d["targets"], d["feet"], [0.5], [3.2], 2.0, None)
    rows = [{"name": "song a", **m}, {"name": "song b", **m, "bas": None}]
    out = plots.plot_eval(tmp_path / "eval.png", rows)
    assert out.stat().st_size > 20_000


# --- video ---------------------------------------------------------------------------------------

SIM_FPS = 50.0


@pytest.fixture(scope="module")
def scene_model():
    from quaddance.sim.scene import build_model

    return build_model(visual=True)


def _dancing_qpos(model, seconds: float) -> np.ndarray:
    """The home pose with the front-left thigh swinging, (T, nq) at SIM_FPS."""
    import mujoco

    n = int(seconds * SIM_FPS)
    qpos = np.tile(model.key_qpos[0], (n, 1))
    adr = model.jnt_qposadr[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, "FL_thigh_joint")]
    qpos[:, adr] -= 0.7 * np.sin(np.pi * np.arange(n) / SIM_FPS) ** 2
    return qpos


def _click_track(path: Path, seconds: float, clicks_s: list[float], sr: int = 22050) -> None:
    """A quiet sine with loud 10 ms clicks at the given times."""
    import soundfile as sf

    t = np.arange(int(seconds * sr)) / sr
    y = 0.02 * np.sin(2 * np.pi * 220.0 * t)
    for c in clicks_s:
        i = int(c * sr)
        y[i : i + sr // 100] = 0.9
    sf.write(path, y.astype(np.float32), sr)


def _decode_audio(path: Path, sr: int = 22050) -> np.ndarray:
    import imageio_ffmpeg

    cmd = [imageio_ffmpeg.get_ffmpeg_exe(), "-v", "error", "-i", str(path), "-vn"]
    cmd += ["-ac", "1", "-ar", str(sr), "-f", "s16le", "-"]
    raw = subprocess.run(cmd, capture_output=True, check=True).stdout
    return np.frombuffer(raw, dtype=np.int16).astype(float) / 32768.0


def test_video_with_music_is_in_sync_and_shows_the_robot(tmp_path: Path, scene_model) -> None:
    import imageio_ffmpeg

    from quaddance.play import video

    song = tmp_path / "song.wav"
    _click_track(song, 3.5, clicks_s=[1.5])
    qpos = _dancing_qpos(scene_model, 2.5)
    targets = np.zeros((len(qpos), 4))
    targets[:, 0] = 0.12
    out = tmp_path / "dance.mp4"
    timing = video.render_video(
        scene_model,
        qpos,
        SIM_FPS,
        out,
        audio_path=song,
        audio_offset_s=0.5,
        width=320,
        height=240,
        target_heights_m=targets,
        progress=False,
        workers=2,
    )
    n_video = round(2.5 * video.VIDEO_FPS)
    assert timing["frames"] == n_video and timing["workers"] == 2

    info = video.video_info(out)
    assert info["has_video"] and info["has_audio"]
    # The song is longer than the dance; the video is cut at the dance's 2.5 s.
    assert info["duration_s"] == pytest.approx(2.5, abs=0.06)
    n_frames, _ = imageio_ffmpeg.count_frames_and_secs(str(out))
    assert n_frames == n_video  # both segments joined

    # Sync: the click at song time 1.5 s plays at video time 1.5 - 0.5 = 1.0 s.
    audio = _decode_audio(out)
    click_s = np.argmax(np.abs(audio) > 0.5) / 22050
    assert click_s == pytest.approx(1.0, abs=0.02)

    reader = imageio_ffmpeg.read_frames(str(out))
    meta = next(reader)
    assert tuple(meta["size"]) == (320, 240)
    frame = np.frombuffer(next(reader), dtype=np.uint8).reshape(240, 320, 3)
    reader.close()
    assert frame.std() > 20  # not one flat colour
    # The Go1 is near-black on a light floor: dark pixels in the middle of the picture.
    middle = frame[60:180, 80:240].mean(axis=2)
    assert (middle < 50).mean() > 0.03


def test_frames_from_several_workers_come_in_order(tmp_path: Path, scene_model) -> None:
    """Workers draw frames round robin; the video must not depend on how many there are,
    nor on the workers having started (and the caller having waited) long before."""
    import time

    import imageio_ffmpeg

    from quaddance.play import video

    qpos = _dancing_qpos(scene_model, 1.0)
    frames = {}
    for workers in (1, 3):
        renderer = video.VideoRenderer(scene_model, 160, 120, workers=workers)
        with renderer:
            time.sleep(0.5 * workers)  # the caller busy elsewhere while the workers start
            out = tmp_path / f"w{workers}.mp4"
            timing = renderer.render(qpos, SIM_FPS, out, progress=False)
        assert timing["frames"] == round(video.VIDEO_FPS) and timing["workers"] == workers
        reader = imageio_ffmpeg.read_frames(str(out))
        next(reader)
        frames[workers] = np.stack([np.frombuffer(f, np.uint8).astype(int) for f in reader])
    assert frames[1].shape == frames[3].shape == (round(video.VIDEO_FPS), 160 * 120 * 3)
    # The same pictures in the same order (the encoder is deterministic for equal input).
    assert np.abs(frames[1] - frames[3]).max() <= 2
    # ... and the leg really moves, so a shuffled order would show.
    assert np.abs(frames[1][0] - frames[1][15]).mean() > 0.5


def test_a_slow_encoder_gets_every_frame_as_drawn(tmp_path: Path, scene_model, monkeypatch):
    """The workers draw into a ring of frame slots that the encoder writes out: when the
    encoder is slower than the workers, they wait for it and never draw over a frame it has
    not written yet. 100 frames over 2 workers go round each worker's slots 5 times."""
    import os
    import time

    import imageio_ffmpeg

    from quaddance.play import video
    from quaddance.play.video import workers

    qpos = _dancing_qpos(scene_model, 4.0)
    frame = workers.FrameSlots.frame

    def slow_frame(self, worker: int, slot: int) -> memoryview:
        time.sleep(0.02)  # the workers run ahead meanwhile
        return frame(self, worker, slot)

    videos = []
    for name in ("fast", "slow"):
        if name == "slow":
            monkeypatch.setattr(workers.FrameSlots, "frame", slow_frame)
        out = tmp_path / f"{name}.mp4"
        with video.VideoRenderer(scene_model, 160, 120, workers=2) as renderer:
            if name == "fast":
                # Workers yield the cores to the caller (its simulation feeds them).
                own = os.getpriority(os.PRIO_PROCESS, 0)
                for proc in renderer._pool.procs:
                    nice = os.getpriority(os.PRIO_PROCESS, proc.pid)
                    assert nice == min(19, own + workers.WORKER_NICE) > own
            renderer.render(qpos, SIM_FPS, out, progress=False)
        reader = imageio_ffmpeg.read_frames(str(out))
        next(reader)
        videos.append(np.stack([np.frombuffer(f, np.uint8).astype(int) for f in reader]))
    n_video = round(4.0 * video.VIDEO_FPS)
    assert n_video > 2 * 2 * workers.SLOTS
    assert videos[0].shape == videos[1].shape == (n_video, 160 * 120 * 3)
    assert np.abs(videos[0] - videos[1]).max() <= 2


def test_frame_buffers_fall_back_to_disk_and_a_full_disk_is_one_clear_error(
    tmp_path: Path, monkeypatch
) -> None:
    import errno
    import os

    from quaddance.errors import QuaddanceError
    from quaddance.play.video import workers

    slots = workers.FrameSlots(tmp_path, 2, 64, 48)
    try:
        assert slots.path.is_file() and slots.path.stat().st_size == 2 * workers.SLOTS * 64 * 48 * 3
        assert len(slots.frame(1, workers.SLOTS - 1)) == 64 * 48 * 3
    finally:
        slots.close()
    assert not slots.path.exists()

    full = os.statvfs_result((4096, 4096, 100, 0, 0, 100, 0, 0, 0, 255))
    monkeypatch.setattr(os, "statvfs", lambda path: full)  # /dev/shm without room
    slots = workers.FrameSlots(tmp_path, 2, 64, 48)
    assert slots.path.parent == tmp_path
    slots.close()

    def no_space(fd: int, offset: int, size: int) -> None:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(os, "posix_fallocate", no_space)
    with pytest.raises(QuaddanceError, match=r"no room .* frame buffers .*No space left"):
        workers.FrameSlots(tmp_path, 2, 64, 48)
    assert not list(tmp_path.iterdir())  # nothing left behind

    # Without posix_fallocate (macOS), zeros are written instead.
    monkeypatch.delattr(os, "posix_fallocate")
    slots = workers.FrameSlots(tmp_path, 3, 640, 480)  # more than one 1 MB chunk of zeros
    assert slots.path.stat().st_size == 3 * workers.SLOTS * 640 * 480 * 3
    assert len(slots.frame(2, 0)) == 640 * 480 * 3
    slots.close()


def test_video_streamed_during_the_simulation_equals_the_one_made_afterwards(
    tmp_path: Path, scene_model
) -> None:
    """Poses added one by one (frames handed out before the camera path is complete) make
    the same video as the whole trajectory at once."""
    import imageio_ffmpeg

    from quaddance.play import video

    qpos = _dancing_qpos(scene_model, 2.0)
    qpos[:, 0] += 0.4 * np.arange(len(qpos)) / SIM_FPS  # the base walks: the camera follows
    targets = np.zeros((len(qpos), 4))
    targets[:, 1] = np.linspace(0.0, 0.2, len(qpos))
    outs = [tmp_path / "batch.mp4", tmp_path / "streamed.mp4"]
    with video.VideoRenderer(None, 160, 120) as renderer:  # the model built in the workers
        renderer.render(qpos, SIM_FPS, outs[0], target_heights_m=targets, progress=False)
    # Given the model, the renderer knows its layout at once and hands frames out early.
    with video.VideoRenderer(scene_model, 160, 120) as renderer:
        stream = renderer.stream(len(qpos), SIM_FPS, outs[1], target_markers=True, progress=False)
        for q, t in zip(qpos, targets, strict=True):
            stream.add(q, t)
        timing = stream.finish().wait()
    n_video = round(2.0 * video.VIDEO_FPS)
    assert timing["frames"] == n_video
    frames = []
    for out in outs:
        reader = imageio_ffmpeg.read_frames(str(out))
        next(reader)
        frames.append(np.stack([np.frombuffer(f, np.uint8).astype(int) for f in reader]))
    assert frames[0].shape == frames[1].shape == (n_video, 160 * 120 * 3)
    assert np.abs(frames[0] - frames[1]).max() <= 2


def test_failed_video_leaves_the_previous_one(tmp_path: Path, scene_model) -> None:
    from quaddance.play import video

    out = tmp_path / "dance.mp4"
    out.write_bytes(b"previous good video")
    qpos = _dancing_qpos(scene_model, 0.5)
    with pytest.raises(InputFileError, match="not found"):
        video.render_video(scene_model, qpos, SIM_FPS, out, audio_path=tmp_path / "nope.wav")
    not_audio = tmp_path / "notes.wav"
    not_audio.write_text("this is not audio")
    with pytest.raises(InputFileError, match="cannot decode"):
        video.render_video(scene_model, qpos, SIM_FPS, out, audio_path=not_audio)
    # A failure inside a render worker surfaces as a RenderError, with the same guarantee.
    bad_cfg = video.RenderCfg(camera="no_such_camera")
    with pytest.raises(video.RenderError, match="no_such_camera"):
        video.render_video(
            scene_model, qpos, SIM_FPS, out, width=64, height=48, progress=False, cfg=bad_cfg
        )
    with pytest.raises(QuaddanceError, match="qpos_s"):
        video.render_video(scene_model, qpos[:, :5], SIM_FPS, out)
    assert out.read_bytes() == b"previous good video"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dance.mp4", "notes.wav"]


def test_png_stills_show_the_robot(tmp_path: Path, scene_model) -> None:
    import imageio.v3 as iio

    from quaddance.play import video

    qpos = _dancing_qpos(scene_model, 1.0)
    paths = video.write_frames_png(
        scene_model, qpos, SIM_FPS, [0.0, 0.5], tmp_path / "stills", width=160, height=120
    )
    assert [p.exists() for p in paths] == [True, True]
    first, second = (iio.imread(p) for p in paths)
    assert first.shape == (120, 160, 3)
    # At 0.5 s the front-left leg is swung forward: the two stills differ.
    assert np.abs(first.astype(int) - second.astype(int)).mean() > 0.5


def test_resample_qpos_interpolates_and_keeps_unit_quaternions(scene_model) -> None:
    from quaddance.play.video import resample_qpos

    qpos = np.tile(scene_model.key_qpos[0], (2, 1))
    qpos[1, 0] = 1.0  # base moves 1 m in x
    half = np.sqrt(0.5)
    qpos[1, 3:7] = [-half, 0.0, 0.0, -half]  # 90 degrees about z, written with a negative w
    out = resample_qpos(scene_model, qpos, 1.0, np.array([0.0, 0.5, 1.0, 2.0]))
    assert out[:, 0] == pytest.approx([0.0, 0.5, 1.0, 1.0])
    np.testing.assert_allclose(np.linalg.norm(out[:, 3:7], axis=1), 1.0)
    # Halfway along the short arc: 45 degrees about z (up to sign).
    expected = np.array([np.cos(np.pi / 8), 0.0, 0.0, np.sin(np.pi / 8)])
    assert abs(out[1, 3:7] @ expected) == pytest.approx(1.0)


def test_simplified_meshes_keep_valid_triangles(scene_model) -> None:
    import copy

    from quaddance.play.video import simplify_meshes

    model = copy.deepcopy(scene_model)
    before = int(model.mesh_facenum.sum())
    after = simplify_meshes(model, 0.004)
    assert 0 < after < before / 4
    for i in range(model.nmesh):
        adr, num = model.mesh_faceadr[i], model.mesh_facenum[i]
        faces = model.mesh_face[adr : adr + num]
        assert faces.min() >= 0 and faces.max() < model.mesh_vertnum[i]
        assert np.all((faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]))


def test_learning_curve_plot_from_a_curve_csv(tmp_path) -> None:
    from quaddance.play.plots import plot_learning_curve

    csv_path = tmp_path / "curve.csv"
    lines = ["iteration,env_steps,wall_s,front_abs_err_m,fall_rate,rear_lift_m"]
    lines += [f"{i},{i * 6144},{i * 1.2},{0.03 / i},{1 / i},{0.01 / i}" for i in range(1, 120)]
    csv_path.write_text("\n".join(lines) + "\n")
    out = plot_learning_curve(tmp_path / "curve.png", csv_path)
    assert out.stat().st_size > 10_000
    empty = tmp_path / "empty.csv"
    empty.write_text("iteration,env_steps\n")
    with pytest.raises(QuaddanceError, match="no rows"):
        plot_learning_curve(tmp_path / "x.png", empty)
    # After one iteration (`train --iterations 1`): a point, and no matplotlib warning.
    one = tmp_path / "one.csv"
    one.write_text("\n".join(lines[:2]) + "\n")
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert plot_learning_curve(tmp_path / "one.png", one).stat().st_size > 10_000


def test_finite_planes_bound_an_infinite_floor_for_drawing_only() -> None:
    import mujoco

    from quaddance.play.video import finite_planes

    xml = """<mujoco><asset>
      <texture name="t" type="2d" builtin="checker" width="8" height="8"/>
      <material name="floor" texture="t" texrepeat="4 4"/>
      <material name="shared" texture="t" texrepeat="2 2"/></asset>
      <worldbody>
        <geom name="inf" type="plane" size="0 0 0.05" material="floor"/>
        <geom name="fin" type="plane" size="2 3 0.1" material="floor"/>
        <geom name="inf2" type="plane" size="0 0 0.05" material="shared"/>
        <geom name="box" type="box" size="1 1 1" material="shared"/>
      </worldbody></mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    assert finite_planes(model, 30.0, 0.5) == 2
    np.testing.assert_allclose(model.geom("inf").size, [30.0, 30.0, 0.5])
    np.testing.assert_allclose(model.geom("inf2").size, [30.0, 30.0, 0.5])
    np.testing.assert_allclose(model.geom("fin").size, [2.0, 3.0, 0.1])  # already finite
    # The floor's checker keeps its size per metre; a material that a box shares keeps its
    # mapping, or the box would change its look.
    assert model.mat_texuniform[model.material("floor").id] == 1
    assert model.mat_texuniform[model.material("shared").id] == 0
