"""Human feet -> robot targets (paper, minmax, feasible), the dance.npz file, make_dance, CLI."""

from __future__ import annotations

import dataclasses
import itertools
import zipfile
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from typer.testing import CliRunner

import quaddance.choreo.motion as motion_module
from quaddance.choreo.body import MoveSet
from quaddance.choreo.choreographer import choreograph
from quaddance.choreo.grid import synthetic_grid
from quaddance.cli import app
from quaddance.dancefile import KEYS, OPTIONAL_KEYS, Dance, load_dance, save_dance
from quaddance.errors import InputFileError, QuaddanceError
from quaddance.pipeline import DanceSpec, compose, make_dance, target_bank
from quaddance.targets import TargetConfig, robot_targets

OUT_FPS = 50.0


def bump(t_s: np.ndarray, peak_s: float, height_m: float, half_width_s: float) -> np.ndarray:
    """A raised-cosine lift centred on ``peak_s``."""
    x = np.clip((t_s - peak_s) / half_width_s, -1.0, 1.0)
    return height_m * 0.5 * (1.0 + np.cos(np.pi * x))


def segments(h: np.ndarray) -> list[tuple[int, int]]:
    """(start, stop) frame ranges where ``h`` > 0."""
    up = np.concatenate([[0], (h > 0).astype(np.int8), [0]])
    edges = np.diff(up)
    return list(zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1), strict=True))


# --- paper and minmax -------------------------------------------------------------------------


def test_paper_mode_is_eq4_with_one_max_over_both_feet():
    feet = np.array([[0.0, 0.1], [0.2, 0.05], [0.4, 0.0], [0.1, 0.3]])
    t, targets = robot_targets(feet, OUT_FPS, np.array([]), TargetConfig(mode="paper", h0_m=2.0))
    np.testing.assert_allclose(t, [0.0, 0.02, 0.04, 0.06])
    # h0 * h / max(h) = 2 * h / 0.4 = 5 h
    np.testing.assert_allclose(targets[:, :2], [[0.0, 0.5], [1.0, 0.25], [2.0, 0.0], [0.5, 1.5]])
    assert not targets[:, 2:].any()


def test_minmax_mode_normalises_each_foot():
    feet = np.array([[0.1, 0.0], [0.3, 0.05], [0.2, 0.025]])
    _, targets = robot_targets(feet, OUT_FPS, np.array([]), TargetConfig(mode="minmax", scale=0.5))
    np.testing.assert_allclose(targets[:, 0], [0.0, 0.5, 0.25])
    np.testing.assert_allclose(targets[:, 1], [0.0, 0.5, 0.25])
    flat = np.column_stack([np.full(4, 0.2), np.linspace(0.0, 0.3, 4)])
    _, targets = robot_targets(flat, OUT_FPS, np.array([]), TargetConfig(mode="minmax"))
    assert not targets[:, 0].any()  # a foot that never moves gets a flat 0 target


@pytest.mark.parametrize("mode", ["paper", "minmax"])
def test_resampling_interpolates_not_nearest(mode):
    fps = 30.0
    t_h = np.arange(90) / fps
    feet = np.column_stack([0.1 + 0.2 * t_h / t_h[-1], 0.05 + 0.0 * t_h])
    feet[45, 1] = 0.3  # one spike so the right foot is not flat
    cfg = TargetConfig(mode=mode, h0_m=1.0, scale=1.0)
    t, targets = robot_targets(feet, fps, np.array([]), cfg)
    assert t.size == 150 and np.allclose(np.diff(t), 1 / OUT_FPS)
    # The ramp maps to a ramp: each 50 Hz sample lies on the line, between 30 fps frames.
    expected = (0.1 + 0.2 * t / t_h[-1]) / 0.3 if mode == "paper" else t / t_h[-1]
    inside = t <= t_h[-1]
    np.testing.assert_allclose(targets[inside, 0], expected[inside], atol=1e-12)
    # Nearest-frame resampling would repeat values; interpolation gives distinct ones.
    assert np.unique(np.round(targets[inside, 0], 12)).size == inside.sum()


# --- feasible ---------------------------------------------------------------------------------


def check_feasible(t: np.ndarray, targets: np.ndarray, cfg: TargetConfig) -> None:
    """The promises of the feasible mode, checked on sampled targets."""
    dt = 1.0 / cfg.out_fps
    front = targets[:, :2]
    assert not targets[:, 2:].any()
    assert front.min() >= 0.0 and front.max() <= cfg.max_height_m + 1e-12
    assert np.all(np.minimum(front[:, 0], front[:, 1]) == 0.0)
    assert np.abs(np.diff(front, axis=0)).max() / dt <= cfg.max_speed_m_s * (1 + 1e-6)
    assert np.abs(np.diff(front, n=2, axis=0)).max() / dt**2 <= cfg.max_accel_m_s2 * (1 + 1e-6)
    # Back to exactly 0 between lifts, both feet down for min_ground_s.
    runs = segments(front.max(axis=1))
    for (_, stop), (start, _) in itertools.pairwise(runs):
        assert (start - stop) * dt >= cfg.min_ground_s - dt
    # Targets start and end on the floor.
    assert not front[0].any() and not front[-1].any()
    for foot in (0, 1):
        for a, b in segments(front[:, foot]):
            assert front[a:b, foot].max() >= cfg.min_lift_m - 1e-9


@pytest.mark.parametrize(("tempo", "seed"), [(80.0, 0), (118.0, 1), (140.0, 2), (175.0, 3)])
def test_feasible_targets_from_choreography(tempo, seed):
    grid = synthetic_grid(tempo, 60.0, np.random.default_rng(seed))
    feet = choreograph(grid, seed=seed, fps=60.0)
    cfg = TargetConfig()
    t, targets = robot_targets(feet, 60.0, grid.beats_s, cfg)
    assert t.size == 3000
    check_feasible(t, targets, cfg)
    # Peaks stay on the beat (or half beat) they were on, within one 50 Hz sample.
    beats = grid.beats_s
    grid_s = np.sort(np.concatenate([beats, 0.5 * (beats[:-1] + beats[1:])]))
    peaks = [
        t[a + int(np.argmax(targets[a:b, k]))] for k in (0, 1) for a, b in segments(targets[:, k])
    ]
    # Fast songs keep fewer lifts (each needs 0.3-0.8 s within the speed bounds), but even
    # at 175 BPM at least one beat in five has one.
    assert len(peaks) > 0.2 * beats.size
    to_grid = np.abs(np.asarray(peaks)[:, None] - grid_s[None, :]).min(axis=1)
    assert to_grid.max() <= 1.0 / OUT_FPS + 1e-9
    # The largest human lifts use the robot's full reach.
    assert targets.max() > 0.95 * cfg.max_height_m


def test_feasible_keeps_the_larger_of_two_overlapping_lifts():
    fps = 100.0
    t = np.arange(400) / fps
    left = bump(t, 1.0, 0.30, 0.25) + bump(t, 3.0, 0.10, 0.2)
    right = bump(t, 1.15, 0.12, 0.25) + bump(t, 2.9, 0.10, 0.2)  # ties with left at 3.0
    cfg = TargetConfig(beat_snap_s=0.0)
    tt, targets = robot_targets(np.column_stack([left, right]), fps, np.array([]), cfg)
    check_feasible(tt, targets, cfg)
    first, second = tt < 2.0, tt >= 2.0
    assert targets[first, 0].max() > 0.15 and not targets[first, 1].any()
    # Equal sizes: the lift that started first (right, at 2.9 s) stays.
    assert targets[second, 1].max() > 0.05 and not targets[second, 0].any()
    assert abs(tt[np.argmax(targets[:, 0])] - 1.0) <= 0.02


def test_feasible_drops_a_lift_made_while_the_other_foot_is_up():
    """Slow human lifts overlapping at half height: one foot wins even though the robot
    would have time for two quick lifts; the later, larger one is the one kept."""
    fps = 100.0
    t = np.arange(300) / fps
    left = bump(t, 1.0, 0.2, 0.6)
    right = bump(t, 1.5, 0.3, 0.6)
    cfg = TargetConfig(beat_snap_s=0.0)
    tt, targets = robot_targets(np.column_stack([left, right]), fps, np.array([]), cfg)
    check_feasible(tt, targets, cfg)
    assert not targets[:, 0].any() and targets[:, 1].max() > 0.15


def test_feasible_scales_robustly_and_drops_small_lifts():
    fps = 100.0
    t = np.arange(1200) / fps
    left = sum(bump(t, p, 0.15, 0.2) for p in (1.0, 3.0, 5.0, 7.0, 9.0))
    right = bump(t, 2.0, 0.016 + 0.02, 0.2) + bump(t, 4.0, 0.10, 0.2)
    cfg = TargetConfig(max_height_m=0.2, min_lift_m=0.06)
    tt, targets = robot_targets(np.column_stack([left, right]), fps, np.array([]), cfg)
    check_feasible(tt, targets, cfg)
    # The common lift size (90th percentile) maps to max height; 0.10 m maps to 2/3 of it.
    np.testing.assert_allclose(targets[:, 0].max(), 0.2, rtol=1e-3)
    np.testing.assert_allclose(targets[:, 1].max(), 0.2 * 0.10 / 0.15, rtol=1e-2)
    # The 0.036 m lift maps below min_lift_m and disappears.
    assert not targets[(tt > 1.6) & (tt < 2.4), 1].any()


def test_feasible_stretches_fast_lifts_but_keeps_their_peak_time():
    fps = 200.0
    t = np.arange(600) / fps
    left = bump(t, 1.5, 0.3, 0.05)  # a 0.1 s flick: too fast for the robot at full height
    cfg = TargetConfig(beat_snap_s=0.0)
    tt, targets = robot_targets(np.column_stack([left, 0 * t]), fps, np.array([]), cfg)
    check_feasible(tt, targets, cfg)
    a, b = segments(targets[:, 0])[0]
    assert (b - a) / OUT_FPS > 0.3  # stretched well beyond the human's 0.1 s
    assert abs(tt[a + np.argmax(targets[a:b, 0])] - 1.5) <= 0.01


def test_feasible_snaps_near_peaks_onto_beats():
    fps = 100.0
    t = np.arange(500) / fps
    left = bump(t, 1.02, 0.2, 0.2) + bump(t, 3.1, 0.2, 0.2)
    beats = np.array([1.0, 2.0, 3.0, 4.0])
    cfg = TargetConfig()
    tt, targets = robot_targets(np.column_stack([left, 0 * t]), fps, beats, cfg)
    runs = segments(targets[:, 0])
    peaks = [tt[a + int(np.argmax(targets[a:b, 0]))] for a, b in runs]
    assert abs(peaks[0] - 1.0) < 1e-9  # 20 ms late -> on the beat
    assert abs(peaks[1] - 3.1) < 1e-9  # 100 ms off -> left alone


def test_feasible_thins_lifts_too_crowded_for_the_robot():
    fps = 200.0
    t = np.arange(int(6 * fps)) / fps
    eighth_s = 60.0 / 180.0 / 2.0  # eighth notes at 180 BPM, alternating feet
    peaks = np.arange(0.5, 5.5, eighth_s)
    left = sum(bump(t, p, 0.1, 0.07) for p in peaks[0::2])
    right = sum(bump(t, p, 0.1, 0.07) for p in peaks[1::2])
    cfg = TargetConfig()
    tt, targets = robot_targets(np.column_stack([left, right]), fps, peaks, cfg)
    check_feasible(tt, targets, cfg)
    n_lifts = sum(len(segments(targets[:, k])) for k in (0, 1))
    # Thinned (a 10 cm lift needs about 0.4 s within the speed bounds) but not emptied.
    assert 0.1 * peaks.size <= n_lifts < peaks.size


def test_feasible_without_lifts_is_all_zero():
    t, targets = robot_targets(np.zeros((100, 2)), 60.0, np.array([1.0]), TargetConfig())
    assert t.size == 84 and not targets.any()


@pytest.mark.parametrize(
    ("feet", "fps"),
    [(np.zeros((10, 3)), 60.0), (np.full((10, 2), np.nan), 60.0), (np.zeros((10, 2)), 0.0)],
)
def test_targets_reject_bad_input(feet, fps):
    with pytest.raises(QuaddanceError):
        robot_targets(feet, fps, np.array([]))


@pytest.mark.parametrize(
    "kwargs", [{"mode": "hop"}, {"max_height_m": -0.1}, {"out_fps": 0.0}, {"lift_percentile": 0}]
)
def test_target_config_rejects_bad_settings(kwargs):
    with pytest.raises(QuaddanceError):
        TargetConfig(**kwargs)


def test_target_bank_is_feasible_and_reproducible():
    cfg = TargetConfig()
    bank = target_bank(6, 12.0, seed=3, cfg=cfg)
    assert bank.shape == (6, 600, 4) and bank.dtype == np.float32
    np.testing.assert_array_equal(bank, target_bank(6, 12.0, seed=3, cfg=cfg))
    assert not np.array_equal(bank, target_bank(6, 12.0, seed=4, cfg=cfg))
    assert not bank[:, :, 2:].any()
    assert np.all(np.minimum(bank[:, :, 0], bank[:, :, 1]) == 0.0)
    assert bank.max() <= cfg.max_height_m + 1e-6
    assert all(seq[:, :2].max() > 0.1 for seq in bank)  # every song gets a dance


# --- dance.npz --------------------------------------------------------------------------------


def make_test_dance(n: int = 120) -> Dance:
    t = np.arange(n) / 50.0
    feet = np.column_stack([0.1 * np.sin(t) ** 2, 0.05 * np.cos(t) ** 2])
    return Dance(
        fps=50.0,
        time_s=t,
        human_feet_m=feet,
        targets_m=np.column_stack([feet, np.zeros((n, 2))]),
        beats_s=np.array([0.5, 1.0, 1.5]),
        downbeats_s=np.array([0.5]),
        mode="feasible",
        source="tést song.wav",
        seed=7,
        version="0.1.0",
    )


def test_dance_round_trip(tmp_path):
    path = tmp_path / "dance.npz"
    dance = make_test_dance()
    save_dance(path, dance)
    save_dance(path, dance)  # overwriting works and leaves no temporary files
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dance.npz"]
    with np.load(path, allow_pickle=False) as npz:
        assert sorted(npz.files) == sorted(KEYS + OPTIONAL_KEYS)
    loaded = load_dance(path)
    for field in dataclasses.fields(Dance):
        a, b = getattr(dance, field.name), getattr(loaded, field.name)
        if isinstance(a, np.ndarray):
            np.testing.assert_array_equal(a, b)
        else:
            assert a == b and type(a) is type(b)
    assert loaded.duration_s == pytest.approx(120 / 50.0)


def write_npz(path: Path, **arrays: np.ndarray) -> Path:
    np.savez(path, **arrays)
    return path


def dance_arrays(dance: Dance) -> dict[str, np.ndarray]:
    arrays = {
        f.name: np.asarray(getattr(dance, f.name))
        for f in dataclasses.fields(Dance)
        if f.name != "clamp_report"  # not part of the file
    }
    for key in ("mode", "source", "version"):
        arrays[key] = np.array(arrays[key], dtype=np.str_)
    return arrays


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"targets_m": None}, "missing targets_m"),
        ({"targets_m": np.zeros((120, 3))}, "targets_m must have shape"),
        ({"human_feet_m": np.zeros((119, 2))}, "human_feet_m must have shape"),
        ({"human_feet_m": np.full((120, 2), np.nan)}, "NaN"),
        ({"fps": np.float64(0.0)}, "fps must be > 0"),
        ({"time_s": np.zeros(120)}, "not increasing"),
        ({"mode": np.float64(1.0)}, "mode must be a text value"),
        ({"seed": np.float64(1.5)}, "seed must be a single number"),
    ],
)
def test_malformed_dance_files_are_named(tmp_path, change, message):
    arrays = dance_arrays(make_test_dance())
    for key, value in change.items():
        if value is None:
            del arrays[key]
        else:
            arrays[key] = value
    path = write_npz(tmp_path / "bad.npz", **arrays)
    with pytest.raises(InputFileError, match=message) as err:
        load_dance(path)
    assert err.value.path == path


def test_unreadable_dance_files(tmp_path):
    text = tmp_path / "notes.npz"
    text.write_text("this is not an archive")
    with pytest.raises(InputFileError, match="cannot read"):
        load_dance(text)
    with pytest.raises(InputFileError, match="no such file"):
        load_dance(tmp_path / "absent.npz")
    single = tmp_path / "single.npy"
    np.save(single, np.zeros(3))
    with pytest.raises(InputFileError, match="not a dance file"):
        load_dance(single)
    other_zip = tmp_path / "other.npz"
    with zipfile.ZipFile(other_zip, "w") as zf:
        zf.writestr("readme.txt", "hello")
    with pytest.raises(InputFileError, match="missing"):
        load_dance(other_zip)
    # An object array would need unpickling: refused, not executed.
    arrays = dance_arrays(make_test_dance())
    arrays["source"] = np.array([{"a": 1}], dtype=object)
    pickled = tmp_path / "pickled.npz"
    np.savez(pickled, **arrays)
    with pytest.raises(InputFileError):
        load_dance(pickled)


# --- make_dance and the CLI -------------------------------------------------------------------


def fake_analysis(duration_s: float = 20.0) -> SimpleNamespace:
    grid = synthetic_grid(110.0, duration_s, np.random.default_rng(0))
    return SimpleNamespace(
        tempo_bpm=110.0,
        beats_s=grid.beats_s,
        downbeats_s=grid.downbeats_s,
        rms_env=grid.energy,
        onset_env=grid.energy,
        env_fps=grid.energy_fps,
        sections_s=grid.sections_s,
        duration_s=duration_s,
    )


def test_make_dance_from_analysis(tmp_path):
    analysis = fake_analysis()
    dance, used = make_dance(None, None, DanceSpec(seed=2), analysis=analysis)
    assert used is analysis
    assert dance.fps == 50.0 and dance.targets_m.shape == (1000, 4)
    assert dance.human_feet_m.shape == (1000, 2)
    np.testing.assert_array_equal(dance.beats_s, analysis.beats_s)
    check_feasible(dance.time_s, dance.targets_m, TargetConfig())
    paper, _ = make_dance(
        None, None, DanceSpec(seed=2, targets=TargetConfig(mode="paper")), analysis=analysis
    )
    assert paper.mode == "paper"
    np.testing.assert_allclose(paper.targets_m.max(), 2.0, rtol=0.02)
    # The same human dance drives both: the paper targets are 2 m / max times it.
    np.testing.assert_allclose(paper.human_feet_m, dance.human_feet_m)
    save_dance(tmp_path / "d.npz", dance)
    assert load_dance(tmp_path / "d.npz").seed == 2


def test_make_dance_from_motion(monkeypatch, tmp_path):
    fps = 30.0
    t = np.arange(300) / fps
    feet = np.column_stack([bump(t, 2.0, 0.3, 0.3), bump(t, 5.0, 0.25, 0.3)])
    human = SimpleNamespace(fps=fps, feet_m=feet, source="edge.pkl (EDGE)")
    monkeypatch.setattr(motion_module, "load_motion", lambda path: human)
    dance, analysis = make_dance(
        None, tmp_path / "edge.pkl", DanceSpec(targets=TargetConfig(mode="minmax"))
    )
    assert analysis is None and dance.beats_s.size == 0
    assert dance.source == "edge.pkl (EDGE)" and dance.mode == "minmax"
    assert dance.targets_m.shape == (500, 4)
    np.testing.assert_allclose(dance.targets_m[:, :2].max(axis=0), [1.0, 1.0], atol=0.01)
    with pytest.raises(QuaddanceError):
        make_dance(None, None)


def test_a_dance_spec_names_a_known_style():
    with pytest.raises(QuaddanceError, match="ballet"):
        DanceSpec(style="ballet")
    assert DanceSpec(style="wiggly", moves=MoveSet(styles={"wiggly": {}})).mode == "feasible"


def test_compose_without_the_trunk_keeps_the_paws():
    """A paws-only dance (the bank of a paws-only policy) has the paws of the whole-body one
    and a still trunk."""
    grid = synthetic_grid(110.0, 12.0, np.random.default_rng(0))
    spec = DanceSpec(seed=1, targets=TargetConfig(mode="paper"))
    full = compose(spec, grid)
    paws = compose(spec, grid, whole_body=False)
    assert full.mode == paws.mode == "paper"
    np.testing.assert_array_equal(paws.targets_m, full.targets_m)
    assert full.body_targets.any() and not paws.body_targets.any()
    assert set(full.clamp_report) == {"paw", "body"} and set(paws.clamp_report) == {"paw"}


def test_cli_needs_song_or_motion(tmp_path):
    runner = CliRunner()
    result = runner.invoke(app, ["choreograph", "-o", str(tmp_path / "d.npz")])
    assert result.exit_code == 2 and "--motion" in result.output
    result = runner.invoke(app, ["choreograph", str(tmp_path / "absent.wav")])
    assert isinstance(result.exception, InputFileError)
    result = runner.invoke(app, ["choreograph", "--mode", "hop", str(tmp_path / "x.wav")])
    assert result.exit_code == 2


def test_cli_choreographs_a_generated_song(tmp_path):
    pytest.importorskip("quaddance.music.analysis")
    import soundfile as sf

    from quaddance.music.synth import render_song

    y, truth = render_song(tempo_bpm=120.0, duration_s=10.0, seed=1, sr=22050)
    song = tmp_path / "song.wav"
    sf.write(song, y, 22050)
    out = tmp_path / "dance.npz"
    result = CliRunner().invoke(app, ["choreograph", str(song), "-o", str(out), "--seed", "3"])
    assert result.exit_code == 0, result.output
    dance = load_dance(out)
    assert dance.seed == 3 and dance.mode == "feasible"
    assert abs(dance.duration_s - truth.duration_s) < 0.1
    check_feasible(dance.time_s, dance.targets_m, TargetConfig())
    assert dance.targets_m.max() > 0.1
