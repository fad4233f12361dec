"""`quaddance live`: the on-the-fly choreographer, and the command end to end on the
simulated robot with a song fed at real-time pace."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import soundfile as sf
from realtime import skip_if_stalled_before, skip_if_starved

from quaddance.choreo.accents import beat_coverage, motion_accents_s
from quaddance.live.choreographer import (
    CALM_CHUNK_S,
    CALM_LOOKAHEAD_S,
    LOOKAHEAD_S,
    LiveChoreographer,
)
from quaddance.pipeline import DanceSpec
from quaddance.robots import GO1, GO2
from quaddance.targets import TargetConfig

HZ = 50.0


def _state(now_s: float, locked: bool, period_s: float = 0.5, phase_s: float = 0.1):
    """A tracker state with a steady grid: beats at phase_s + k * period_s."""
    k_next = np.floor((now_s - phase_s) / period_s) + 1
    return SimpleNamespace(
        energy=0.8,
        locked=locked,
        beat_period_s=period_s if locked else 0.0,
        next_beat_s=phase_s + k_next * period_s if locked else float("nan"),
        next_beat_in_bar=int(k_next) % 4,
    )


def _run(
    lock_from_s: float, duration_s: float, period_of=lambda t: 0.5, spec: DanceSpec | None = None
) -> LiveChoreographer:
    lc = LiveChoreographer(HZ, spec or DanceSpec(seed=3))
    for i in range(round(duration_s / 0.05)):
        now = i * 0.05
        locked = now >= lock_from_s
        n = lc.update(_state(now, locked, period_of(now)), now)
        # Final targets always ahead of the music, a bar more once dancing.
        assert n / HZ >= now + (LOOKAHEAD_S if locked else CALM_LOOKAHEAD_S)
    return lc


def test_calm_without_a_lock():
    lc = _run(lock_from_s=1e9, duration_s=5.0)
    assert np.all(lc.rows[: lc.planned_until_step] == 0.0)
    assert lc.current_move == "calm"


def test_dance_after_lock_is_smooth_feasible_and_on_the_beat():
    lc = _run(lock_from_s=3.0, duration_s=30.0)
    rows = lc.rows[: lc.planned_until_step]
    t = np.arange(rows.shape[0]) / HZ
    cfg = TargetConfig()
    assert np.all(rows[t < 3.0] == 0.0)  # calm until the lock
    # The first bar is planned from where the calm rows end, which is not far ahead.
    first_s = min(s.start_s for s in lc.segments if s.move != "calm")
    assert first_s <= 3.0 + CALM_LOOKAHEAD_S + CALM_CHUNK_S
    assert rows[:, :2].max() > 0.05 and np.ptp(rows[:, 4:], axis=0).min() > 0.01
    assert rows[:, :2].max() <= cfg.max_height_m + 1e-9
    assert np.all(rows[:, 2:4] == 0.0)  # rear feet down
    # No jumps at segment seams: paws within their speed bound, trunk within 2.5 rad/s.
    step = np.abs(np.diff(rows, axis=0))
    assert step[:, :2].max() <= cfg.max_speed_m_s / HZ * 1.05
    assert step[:, 5:].max() <= 2.5 / HZ
    beats = 0.1 + 0.5 * np.arange(80)
    after = beats[(beats > 5.0) & (beats < t[-1] - 1.0)]
    coverage = beat_coverage(motion_accents_s(t, rows[:, :4], rows[:, 4:]), after)
    assert coverage >= 0.7
    assert {s.move for s in lc.segments} - {"calm"}  # real moves were chosen


@pytest.mark.parametrize("period_s", [0.6, 0.43, 0.36, 0.3])
def test_one_front_paw_up_at_a_time_across_segment_seams(period_s):
    """The offline rule holds live too: never both front paws up, and both down for
    min_ground_s between lifts. A seam's blend of two plans broke it (both paws up for up to
    1 s in 40 s), and at 141 BPM the robot fell."""
    min_gap = round(TargetConfig().min_ground_s * HZ)
    for seed in range(4):
        lc = LiveChoreographer(HZ, DanceSpec(seed=seed))
        for i in range(round(30.0 / 0.05)):
            now = i * 0.05
            lc.update(_state(now, now >= 2.0, period_s), now)
        up = lc.rows[: lc.planned_until_step, :2] > 1e-3
        assert up.any(axis=0).all()  # both paws dance
        assert not np.any(up[:, 0] & up[:, 1])
        either = np.concatenate([[False], up.any(axis=1), [False]])
        edges = np.flatnonzero(np.diff(either.astype(np.int8)))
        ground_steps = edges[2::2] - edges[1:-1:2]  # rows down between two lifts
        assert ground_steps.min() >= min_gap


def test_a_seam_hands_the_trunk_to_the_new_plan_smoothly_by_its_first_beat():
    """The trunk cross-fades from the old plan's tail to the new plan over ``fade_steps`` and
    is the new plan's own from there: a fade that reached past the segment's first beat
    halved its gesture (one downbeat in six of the tuning songs lost its accent). The fade's
    weight is minimum-jerk, so the trunk's velocity does not jump where it starts or ends."""
    n_old, start, n_fade = 200, 100, 25
    t = np.arange(n_old + 150) / HZ
    old = np.zeros((n_old, 8))
    old[:, 4] = 0.03 * np.sin(2.0 * np.pi * t[:n_old])
    old[:, 6] = 0.1 * np.cos(1.5 * np.pi * t[:n_old])
    new = np.zeros((150, 8))
    new[:, 4] = -0.02 * np.cos(3.0 * np.pi * t[start : start + 150])
    new[:, 6] = 0.05 * np.sin(2.0 * np.pi * t[start : start + 150])
    lc = LiveChoreographer(HZ)
    lc._write(0, old)
    lc._write(start, new, fade_steps=n_fade)
    rows = lc.rows
    np.testing.assert_array_equal(rows[:start], old[:start])  # final rows never change
    np.testing.assert_allclose(rows[start + n_fade :, 4:], new[n_fade:, 4:], atol=1e-12)
    vel = np.diff(rows[:, 4:], axis=0)
    vel_old, vel_new = np.diff(old[:, 4:], axis=0), np.diff(new[:, 4:], axis=0)
    # At both ends of the fade the velocity is the plan's own (a linear weight adds the
    # plans' gap over the fade, about (new - old) / n_fade = 2e-3 per step here).
    for k in (start - 1, start):
        assert np.abs(vel[k] - vel_old[k]).max() < 5e-4, k
    for k in (start + n_fade - 1, start + n_fade):
        assert np.abs(vel[k] - vel_new[k - start]).max() < 5e-4, k


@pytest.mark.parametrize("period_s", [0.6, 0.43, 0.3])
def test_the_trunk_keeps_its_bounds_at_seams_and_back_to_calm_after_a_lost_lock(period_s):
    """Live trunk targets keep the speed and acceleration bounds of the offline ones
    (`feasible_body_targets`) at every seam, and go back to the calm pose within them when
    the lock is lost: the blend of two plans exceeded them (height speed up to 1.2 x), and a
    lost lock dropped the trunk to calm in one tick."""
    v_max = np.minimum(GO1.body_four_feet.max_speed, GO1.body_paw_up.max_speed)
    a_max = np.minimum(GO1.body_four_feet.max_accel, GO1.body_paw_up.max_accel)
    for seed in range(3):
        lc = LiveChoreographer(HZ, DanceSpec(seed=seed))
        for i in range(round(20.0 / 0.05)):
            now = i * 0.05
            lc.update(_state(now, 2.0 <= now < 12.0, period_s), now)
        body = lc.rows[: lc.planned_until_step, 4:]
        speed = np.abs(np.diff(body, axis=0)) * HZ
        accel = np.abs(np.diff(body, n=2, axis=0)) * HZ**2
        assert np.all(speed <= v_max * (1 + 1e-6)), speed.max(axis=0)
        assert np.all(accel <= a_max * (1 + 1e-6)), accel.max(axis=0)
        t = np.arange(body.shape[0]) / HZ
        assert np.ptp(body[(t > 4.0) & (t < 12.0)], axis=0).max() > 0.02  # it did dance
        # Calm again once the rows final at the loss (up to a bar and 0.7 s ahead) are danced.
        assert np.abs(body[t > 17.0]).max() < 1e-9


def test_each_bar_is_composed_with_the_spec_s_target_limits():
    """The planner composes each bar as every dance is composed (`pipeline.compose`), with
    the spec's target settings: its paw height limit and its smallest lift."""
    rows = _run(2.0, 20.0).rows
    low = _run(2.0, 20.0, spec=DanceSpec(seed=3, targets=TargetConfig(max_height_m=0.12))).rows
    assert rows[:, :2].max() > 0.2 and low[:, :2].max() <= 0.12 + 1e-9
    high = _run(2.0, 20.0, spec=DanceSpec(seed=3, targets=TargetConfig(min_lift_m=0.2))).rows

    def n_lifts(paws: np.ndarray) -> int:
        return int(np.count_nonzero(np.diff((paws > 1e-3).astype(np.int8), axis=0) == 1))

    assert n_lifts(high[:, :2]) < n_lifts(rows[:, :2])  # the low lifts are gone


def test_a_tempo_change_is_followed_bar_by_bar():
    lc = _run(lock_from_s=2.0, duration_s=24.0, period_of=lambda t: 0.5 if t < 12 else 0.4)
    tempos = [(s.start_s, s.tempo_bpm) for s in lc.segments if s.move != "calm"]
    assert any(abs(bpm - 120) < 1 for t, bpm in tempos if t < 10)
    assert all(abs(bpm - 150) < 1 for t, bpm in tempos if t > 14)


@pytest.fixture(scope="module")
def song(tmp_path_factory) -> Path:
    from quaddance.music.synth import render_song

    path = tmp_path_factory.mktemp("live") / "song.wav"
    y, _ = render_song(120.0, 9.0, seed=11)
    sf.write(path, y, 22050)
    return path


def _live(*args: str, timeout: float = 240) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "quaddance.cli", "live", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
    )


@pytest.mark.parametrize("backend", ["sim", "go2-sim"])
def test_live_from_file_dances_in_real_time(song, tmp_path, backend):
    """On quaddance's own simulated robot, and on a Go2 through unitree_sdk2 (DDS)."""
    from quaddance.play.rollout import ROLLOUT_KEYS

    t0 = time.monotonic()
    proc = _live("--from-file", str(song), "--robot", backend, "--out", str(tmp_path))
    wall_s = time.monotonic() - t0
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert wall_s >= 9.0  # the song is fed at real-time pace, never faster
    live = json.loads((tmp_path / "live.json").read_text())
    deployed = json.loads((tmp_path / "deploy.json").read_text())
    if live["final_state"] != "done":
        skip_if_starved(deployed)  # the machine's failure, not the code's
        skip_if_stalled_before(deployed, 9.0)
    assert live["duration_s"] == pytest.approx(9.0, abs=0.1), deployed["events"]
    assert live["falls"] == 0 and live["final_state"] == "done"
    assert live["lock_s"] is not None and live["lock_s"] < 6.0
    beats = np.asarray(live["beats_s"])
    assert beats.size >= 6 and np.all(np.diff(beats) > 0.2)
    locked = [p["bpm"] for p in live["tempo_bpm"] if p["locked"]]
    assert locked and min(abs(b - 120) for b in locked) < 3  # 120 BPM (or its octave)
    assert live["latency_ms"]["p50"] is not None and live["latency_ms"]["p50"] < 100
    assert live["loop_ms"]["p99"] is not None
    with np.load(tmp_path / "rollout.npz") as z:
        assert set(z.files) == set(ROLLOUT_KEYS)
        assert z["time_s"].size == pytest.approx(9.0 * HZ, abs=3)
        assert z["beats_s"].size == beats.size
    assert deployed["robot"] == backend and deployed["sim"]["rejected"] == 0


def test_live_errors_are_one_line(tmp_path, song):
    proc = _live("--video", "--out", str(tmp_path), timeout=60)
    assert proc.returncode == 2 and "--video needs --from-file" in proc.stderr
    assert "Traceback" not in proc.stderr
    proc = _live("--from-file", str(tmp_path / "nope.wav"), "--out", str(tmp_path), timeout=60)
    assert proc.returncode == 2 and "nope.wav" in proc.stderr and "Traceback" not in proc.stderr
    proc = _live("--start", "3", "--out", str(tmp_path), timeout=60)
    assert proc.returncode == 2 and "--start needs --from-file" in proc.stderr
    assert "Traceback" not in proc.stderr
    proc = _live("--from-file", str(song), "--start", "12", "--out", str(tmp_path), timeout=120)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert "song.wav: --start 12 s is not within the song" in proc.stderr.replace("\n", "")


def test_microphone_without_a_sound_card_is_one_line(tmp_path):
    try:
        import sounddevice as sd

        if any(d["max_input_channels"] > 0 for d in sd.query_devices()):
            pytest.skip("this machine has an audio input: the error path cannot be shown")
    except OSError:
        pass  # PortAudio missing: the command must say so in one line
    proc = _live("--seconds", "2", "--out", str(tmp_path), timeout=120)
    assert proc.returncode == 2, proc.stderr[-2000:]
    lines = [ln for ln in proc.stderr.splitlines() if "error" in ln]
    assert len(lines) == 1 and "audio input" in lines[0]
    assert "Traceback" not in proc.stderr


@pytest.mark.parametrize(("from_file", "start_s"), [(True, 0.0), (True, 2.0), (False, 0.0)])
def test_the_listener_tells_the_tracker_whether_music_may_already_be_playing(
    monkeypatch, from_file, start_s
):
    """A file played from its start starts with the song; a microphone, or a file started
    part-way (``--start``), may join music already playing: the tracker's ``song_start``
    (which listener it trusts first, `music.online_beats`)."""
    import queue
    import threading

    from quaddance.live import session
    from quaddance.music import live as music_live
    from quaddance.music import online_beats

    told: list[bool] = []
    opened: list[float] = []

    class Tracker(online_beats.OnlineBeatTracker):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            told.append(self._first_trusted)

    class Source:  # a tenth of a second of silence, from the file or the microphone
        duration_s = 0.1

        def __init__(self, *args, **kwargs):
            opened.append(kwargs.get("start_s", 0.0))

        def __iter__(self):
            return iter(music_live.ArraySource(np.zeros(2205, np.float32), 22050))

    monkeypatch.setattr(online_beats, "OnlineBeatTracker", Tracker)
    monkeypatch.setattr(music_live, "FileSource" if from_file else "MicSource", Source)
    monkeypatch.setattr(session, "ignore_sigint", lambda: None)  # not in pytest's process
    spec = {
        "from_file": "song.wav" if from_file else None,
        "start_s": start_s,
        "device": None,
        "policy_hz": HZ,
        "dance": DanceSpec(),
    }
    out: queue.Queue = queue.Queue()
    go = threading.Event()
    go.set()
    session._listen(spec, out, go, threading.Event())
    messages = [out.get_nowait() for _ in range(out.qsize())]
    assert messages[0][0] == "ready" and messages[-1] == ("end", None)
    assert len(messages) > 3  # the blocks went through the tracker
    assert told == [from_file and start_s == 0]
    assert opened == [start_s]


def test_live_from_file_started_part_way_dances_the_rest(song, tmp_path):
    """--start joins the 9 s song 5 s in: the dance lasts the 4 s left, live.json says where
    it started, and its times count from there."""
    proc = _live(
        "--from-file", str(song), "--start", "5", "--style", "calm", "--out", str(tmp_path)
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    live = json.loads((tmp_path / "live.json").read_text())
    assert live["start_s"] == 5.0
    assert live["duration_s"] == pytest.approx(4.0, abs=0.1)
    beats = np.asarray(live["beats_s"])
    assert np.all((beats >= 0.0) & (beats <= 4.1))


def test_live_video_plays_the_song_from_where_the_dance_heard_it(monkeypatch, tmp_path):
    from quaddance.deploy.states import DeployState
    from quaddance.live import session
    from quaddance.play import video

    calls = []
    monkeypatch.setattr(video, "render_video", lambda *a, **k: calls.append((a, k)))
    n = 10
    rollout = SimpleNamespace(base_rpy_rad=np.zeros((n, 3)), base_height_m=np.full(n, 0.27), fps=HZ)
    log = {"state": np.full(n, DeployState.DANCE.code), "q": np.zeros((n, 12))}
    session._video(tmp_path / "dance.mp4", rollout, log, tmp_path / "song.wav", 5.0, GO2)
    ((args, kwargs),) = calls
    assert kwargs["audio_path"] == tmp_path / "song.wav" and kwargs["audio_offset_s"] == 5.0
    assert args[1].shape == (n, 19)  # free joint (position, quaternion) and 12 joints
    assert kwargs["cfg"].robot is GO2  # the policy's robot is drawn


def test_live_with_viewer_and_video(song, tmp_path):
    """--viewer serves the page while dancing (on a free loopback port); --video with
    --from-file films the dance afterwards, with the song."""
    import socket

    from quaddance.play.video import video_info

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    args = ["--from-file", str(song), "--seconds", "3", "--video", "--viewer"]
    proc = _live(*args, "--port", str(port), "--style", "calm", "--out", str(tmp_path))
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "viewer: http://127.0.0.1:" in proc.stderr.replace("\n", "")
    info = video_info(tmp_path / "dance.mp4")
    assert info["duration_s"] == pytest.approx(3.0, abs=0.3) and info["has_audio"]
    # The dance ends on the first 50 Hz tick at or past 3 s of wall-clock time: a tick
    # that the scheduler starts a few ms late ends it a few ms late (CI saw 3.001).
    live_s = json.loads((tmp_path / "live.json").read_text())["duration_s"]
    assert live_s == pytest.approx(3.0, abs=0.05)
