"""Whole-body dance: body limits, feasible body targets, body choreography, moves files,
accents and beat coverage, dance.npz body_targets, choreograph --check."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from quaddance.choreo.accents import (
    ACCENT_MIN_ANGLE_RAD,
    ACCENT_MIN_HEIGHT_M,
    beat_coverage,
    motion_accents_s,
)
from quaddance.choreo.body import BODY_MOVES, BODY_STYLES, choreograph_body, render_keys
from quaddance.choreo.choreographer import MOVES, STYLES, choreograph
from quaddance.choreo.grid import MusicGrid, synthetic_grid
from quaddance.choreo.moves_file import load_moves
from quaddance.cli import app
from quaddance.dancefile import Dance, load_dance, save_dance
from quaddance.errors import InputFileError, QuaddanceError
from quaddance.layout import BODY_COLUMNS, CHOREO_FPS
from quaddance.pipeline import DanceSpec, make_dance, target_bank
from quaddance.play.metrics import body_and_coverage
from quaddance.robots import GO1
from quaddance.targets import (
    TargetConfig,
    feasible_body_targets,
    fit_body,
    robot_targets,
)

FPS = 50.0


def check_limits(
    body: np.ndarray, fps: float, paw_up: np.ndarray | None = None, rtol: float = 1e-6
) -> None:
    """Range (the paw-up one where ``paw_up``), speed and acceleration of body targets;
    ``rtol`` allows for float32 rounding."""
    lo, hi = GO1.body_four_feet.low, GO1.body_four_feet.high
    assert np.all(body >= lo - 1e-9) and np.all(body <= hi + 1e-9)
    if paw_up is not None and paw_up.any():
        up = body[paw_up]
        assert np.all(up >= GO1.body_paw_up.low - 1e-9)
        assert np.all(up <= GO1.body_paw_up.high + 1e-9)
    vel = np.diff(body, axis=0) * fps
    acc = np.diff(vel, axis=0) * fps
    assert np.all(np.abs(vel) <= np.array(GO1.body_four_feet.max_speed) * (1 + rtol))
    assert np.all(np.abs(acc) <= np.array(GO1.body_four_feet.max_accel) * (1 + rtol))


def energetic_grid(duration_s: float = 40.0, tempo_bpm: float = 120.0) -> MusicGrid:
    rng = np.random.default_rng(3)
    grid = synthetic_grid(tempo_bpm, duration_s, rng)
    grid.energy = np.ones_like(grid.energy)  # a flat envelope reads as 0.5 ...
    grid.energy[::7] = 0.0  # ... so leave a few quiet frames: most of it normalises to 1
    return grid


def two_level_grid() -> MusicGrid:
    """120 BPM, 64 s: the first half quiet (0.1), the second loud (1.0)."""
    beats = 0.5 + 0.5 * np.arange(126)
    t = np.arange(64 * 50) / 50.0
    return MusicGrid(64.0, beats, beats[::4], np.where(t < 32.0, 0.1, 1.0), 50.0, [0.0, 32.0])


# --- feasible_body_targets -------------------------------------------------------------------


def test_limits_are_the_provisional_values():
    assert BODY_COLUMNS == ("height_offset_m", "roll_rad", "pitch_rad", "yaw_rad")
    assert GO1.body_four_feet.height_offset_m == (-0.06, 0.03)
    assert GO1.body_paw_up.roll_rad == 0.12
    assert GO1.body_four_feet.max_speed[0] == 0.25
    assert GO1.body_four_feet.max_accel[1] == 20.0
    with pytest.raises(dataclasses.FrozenInstanceError):
        GO1.body_four_feet.roll_rad = 1.0  # type: ignore[misc]


def test_wild_body_curves_are_clamped_into_range_speed_and_accel():
    t = np.arange(3000) / FPS
    rng = np.random.default_rng(0)
    wild = np.column_stack(
        [
            0.1 * np.sign(np.sin(2 * t)),  # steps beyond the height range
            0.5 * np.sin(7 * t),  # too far and too fast
            rng.normal(0.0, 0.2, t.size),  # noise
            0.1 * np.sin(t),  # fine: untouched
        ]
    )
    paws = np.zeros((t.size, 4))
    paws[(t % 4) < 1, 0] = 0.1
    # Input at 100 Hz: resampled to the output times.
    wild_100 = np.repeat(wild, 2, axis=0)
    body, report = feasible_body_targets(wild_100, 100.0, t, paws)
    assert body.shape == (t.size, 4)
    check_limits(body, FPS, paw_up=paws[:, 0] > TargetConfig().min_lift_m)
    np.testing.assert_allclose(body[:, 3], wild[:, 3], atol=1e-3)
    assert report["samples"] == t.size
    assert report["yaw_rad"]["clamped"] < 10
    # 0.1 -> 0.03 at least; more where the smoothed steps lag behind.
    assert 0.07 - 1e-9 <= report["height_offset_m"]["max"] <= 0.16
    assert report["roll_rad"]["clamped"] > 1000
    assert 0 < report["pitch_rad"]["mean"] <= report["pitch_rad"]["max"]


def test_a_feasible_body_curve_passes_unchanged():
    t = np.arange(1000) / FPS
    body = np.column_stack([0.02 * np.sin(2 * t), 0.1 * np.sin(3 * t), 0.05 * np.cos(t), 0 * t])
    out, report = feasible_body_targets(body, FPS, t)
    np.testing.assert_allclose(out, body, atol=1e-12)
    assert all(report[name]["clamped"] == 0 for name in BODY_COLUMNS)


def test_bad_body_curves_are_errors():
    t = np.arange(10) / FPS
    with pytest.raises(QuaddanceError, match="shape"):
        feasible_body_targets(np.zeros((10, 3)), FPS, t)
    with pytest.raises(QuaddanceError, match="NaN"):
        feasible_body_targets(np.full((10, 4), np.nan), FPS, t)


def test_fit_body_scales_down_never_up():
    big = np.column_stack(
        [np.linspace(-0.2, 0.1, 500), np.linspace(-1, 1, 500), *[np.zeros(500)] * 2]
    )
    fitted = fit_body(big)
    assert np.percentile(-fitted[:, 0], 98) <= 0.9 * 0.06 + 1e-9
    assert np.abs(fitted[:, 1]).max() < 0.25
    small = 0.01 * np.ones((10, 4))
    np.testing.assert_array_equal(fit_body(small), small)


# --- choreography ----------------------------------------------------------------------------


def body_for(grid: MusicGrid, seed: int = 0, style: str = "mixed") -> np.ndarray:
    feet = choreograph(grid, seed=seed, fps=CHOREO_FPS, style=style)
    return choreograph_body(grid, feet, CHOREO_FPS, seed=seed, style=style)


def test_body_choreography_is_reproducible_and_seeded():
    grid = synthetic_grid(110.0, 30.0, np.random.default_rng(1))
    a, b = body_for(grid, seed=4), body_for(grid, seed=4)
    np.testing.assert_array_equal(a, b)
    assert a.shape == (int(np.ceil(30.0 * CHOREO_FPS)), 4)
    assert not np.allclose(a, body_for(grid, seed=5))
    # The body has its own random stream: the paws of a seed are what they were.
    feet = choreograph(grid, seed=4, fps=CHOREO_FPS)
    np.testing.assert_array_equal(feet, choreograph(grid, seed=4, fps=CHOREO_FPS))


@pytest.mark.parametrize("tempo", [80.0, 120.0, 160.0])
def test_body_choreography_is_smooth_and_inside_the_range(tempo):
    grid = synthetic_grid(tempo, 60.0, np.random.default_rng(int(tempo)))
    body = body_for(grid, seed=2)
    lo, hi = GO1.body_four_feet.low, GO1.body_four_feet.high
    assert np.all(body >= lo - 1e-9) and np.all(body <= hi + 1e-9)
    vel = np.diff(body, axis=0) * CHOREO_FPS
    acc = np.diff(vel, axis=0) * CHOREO_FPS
    # C1 and minimum-jerk shapes: bounded acceleration, within the robot's limits (the
    # lean follows the human feet, smoothed: a little more).
    limit = np.array(GO1.body_four_feet.max_accel)
    assert np.all(np.abs(acc[:, [0, 2, 3]]) <= limit[[0, 2, 3]] * 1.05)
    assert np.abs(acc[:, 1]).max() < 2 * limit[1]


def test_render_keys_rests_on_each_keyframe():
    keys_t, keys_v = np.array([0.0, 0.5, 1.0]), np.array([0.0, -0.03, 0.0])
    t = np.linspace(0, 1.2, 121)
    x = render_keys(t, keys_t, keys_v)
    assert x.min() == pytest.approx(-0.03) and t[np.argmin(x)] == pytest.approx(0.5)
    assert x[-1] == 0.0
    v = np.gradient(x, t)
    assert abs(v[50]) < 1e-3  # at rest on the keyframe


def test_body_accents_land_on_the_beats():
    grid = energetic_grid()
    body = body_for(grid, seed=1)
    t = np.arange(body.shape[0]) / CHOREO_FPS
    from quaddance.choreo.accents import _extrema

    beats = grid.beats_s
    half = 0.5 * (beats[1:] + beats[:-1])
    grid_points = np.sort(np.concatenate([beats, half]))
    for c, threshold in enumerate((ACCENT_MIN_HEIGHT_M,) + (ACCENT_MIN_ANGLE_RAD,) * 3):
        if c == 1:
            continue  # roll carries the lean, which follows the lifts (also on beats, below)
        times = t[_extrema(body[:, c], threshold, max_hold=6)]
        if times.size == 0:
            continue
        # Every extremum sits on a beat (or the half beat where a dip comes back up).
        off = np.abs(times[:, None] - grid_points[None, :]).min(axis=1)
        assert np.all(off <= 1.5 / CHOREO_FPS), (c, times[off > 1.5 / CHOREO_FPS])
    # The deepest points of the bounce are on beats, not half beats.
    dips = t[_extrema(-np.minimum(body[:, 0], 0.0), ACCENT_MIN_HEIGHT_M, max_hold=6)]
    dips = dips[body[(dips * CHOREO_FPS).round().astype(int), 0] < -ACCENT_MIN_HEIGHT_M]
    assert dips.size > 10
    assert np.abs(dips[:, None] - beats[None, :]).min(axis=1).max() <= 1.5 / CHOREO_FPS


def test_energetic_passages_get_accents_on_most_beats_and_quiet_ones_are_calmer():
    grid = two_level_grid()
    cfg = TargetConfig()
    for seed in range(3):
        feet = choreograph(grid, seed=seed, fps=CHOREO_FPS)
        t, paws = robot_targets(feet, CHOREO_FPS, grid.beats_s, cfg)
        raw = choreograph_body(grid, feet, CHOREO_FPS, seed=seed)
        body, _ = feasible_body_targets(raw, CHOREO_FPS, t, paws)
        accents = motion_accents_s(t, paws, body)
        loud = grid.beats_s[grid.beats_s > 33.0]
        assert beat_coverage(accents, loud) >= 0.7
        assert beat_coverage(accents, loud) > beat_coverage(motion_accents_s(t, paws), loud)
        motion = np.abs(np.diff(body, axis=0)).sum(axis=0)
        quiet_part = np.abs(np.diff(body[t < 31.0], axis=0)).sum(axis=0)
        loud_part = motion - quiet_part
        assert loud_part[0] > 1.5 * quiet_part[0]  # bounce deeper and more often when loud


def test_styles_choose_the_mix():
    assert set(BODY_STYLES) == set(STYLES)
    grid = synthetic_grid(120.0, 120.0, np.random.default_rng(9))

    def activity(style: str) -> float:
        return sum(np.abs(np.diff(body_for(grid, s, style), axis=0)).sum() for s in range(3))

    assert activity("energetic") > 1.2 * activity("calm")
    with pytest.raises(QuaddanceError, match="style"):
        choreograph_body(grid, None, CHOREO_FPS, style="ballet")


def test_lean_goes_away_from_the_lifted_foot():
    grid = MusicGrid(10.0, [], [], np.zeros(10), 1.0, [])  # no beats: only the lean moves
    t = np.arange(600) / CHOREO_FPS
    feet = np.zeros((600, 2))
    feet[:, 0] = 0.2 * np.exp(-(((t - 3.0) / 0.3) ** 2))  # left foot up at 3 s
    feet[:, 1] = 0.2 * np.exp(-(((t - 7.0) / 0.3) ** 2))  # right foot up at 7 s
    body = choreograph_body(grid, feet, CHOREO_FPS)
    assert body[180, 1] > 0.05  # roll > 0: trunk tilts right, onto the stance legs
    assert body[420, 1] < -0.05
    assert not body[:, [0, 2, 3]].any()


# --- coverage on the demo song ---------------------------------------------------------------


def test_accents_and_coverage_functions():
    t = np.arange(500) / FPS
    paws = np.zeros((500, 4))
    paws[:, 0] = 0.1 * np.exp(-(((t - 2.0) / 0.1) ** 2))
    body = np.zeros((500, 4))
    body[:, 2] = 0.1 * np.exp(-(((t - 5.0) / 0.1) ** 2))  # a 5.7 degree nod at 5 s
    body[:, 3] = 0.01 * np.exp(-(((t - 7.0) / 0.1) ** 2))  # 0.6 degrees: not visible
    accents = motion_accents_s(t, paws, body)
    np.testing.assert_allclose(accents, [2.0, 5.0])
    assert beat_coverage(accents, [2.05, 5.2, 7.0]) == pytest.approx(1 / 3)
    assert beat_coverage(accents, [2.05, 5.2, 7.0], tol_s=0.25) == pytest.approx(2 / 3)
    assert beat_coverage(accents, []) == 0.0
    assert beat_coverage([], [1.0]) == 0.0
    # A dance (a motion) that ends before the song: only the beats it spans count, not the
    # song's 40 after it (coverage was 2 of 44).
    song_beats = np.concatenate([[2.05, 5.0, 7.5, 9.0], np.arange(10.5, 30.0, 0.5)])
    coverage = body_and_coverage(t, paws, body, body, song_beats)["beat_coverage"]
    assert coverage == pytest.approx(2 / 4)


def test_demo_song_whole_body_covers_the_energetic_beats(demo_song):
    path, _ = demo_song
    dance, analysis = make_dance(path, None, DanceSpec(seed=0))
    grid = MusicGrid.from_analysis(analysis)
    energetic = dance.beats_s[grid.energy_at(dance.beats_s) >= 0.5]
    assert energetic.size >= 8
    paws_only = beat_coverage(motion_accents_s(dance.time_s, dance.targets_m), energetic)
    whole = beat_coverage(
        motion_accents_s(dance.time_s, dance.targets_m, dance.body_targets), energetic
    )
    assert whole >= 0.7 and whole > paws_only
    check_limits(dance.body_targets, dance.fps)
    body_range = np.ptp(dance.body_targets, axis=0)
    assert body_range[0] >= 0.02 and np.sum(body_range[1:] > 0) >= 2  # the trunk moves
    # Which turns a dance uses is the seed's draw: over three seeds, every angle moves.
    ranges = [body_range] + [
        np.ptp(make_dance(path, None, DanceSpec(seed=s))[0].body_targets, axis=0) for s in (1, 2)
    ]
    assert np.all(np.max(ranges, axis=0) > 0)
    report = dance.clamp_report
    assert set(report) == {"paw", "body"} and set(BODY_COLUMNS) <= set(report["body"])


# --- the training bank -----------------------------------------------------------------------


def test_target_bank_with_body():
    paws = target_bank(3, 8.0, seed=5)
    both = target_bank(3, 8.0, seed=5, body=True)
    assert paws.shape == (3, 400, 4) and both.shape == (3, 400, 8)
    np.testing.assert_array_equal(both[:, :, :4], paws)
    for seq in both:
        check_limits(seq[:, 4:].astype(np.float64), FPS, rtol=1e-3)
    assert np.abs(both[:, :, 4:]).max() > 0.01


# --- dance.npz -------------------------------------------------------------------------------


def small_dance(body: np.ndarray | None) -> Dance:
    n = 100
    t = np.arange(n) / FPS
    return Dance(
        fps=FPS,
        time_s=t,
        human_feet_m=np.zeros((n, 2)),
        targets_m=np.zeros((n, 4)),
        beats_s=np.array([0.5]),
        downbeats_s=np.zeros(0),
        mode="feasible",
        source="x",
        seed=1,
        version="0.1.0",
        body_targets=body,
    )


def test_dance_file_round_trips_body_targets_and_reads_old_files(tmp_path):
    body = np.zeros((100, 4))
    body[:, 0] = -0.03 * np.sin(np.arange(100) / 5.0) ** 2
    body[:, 3] = 0.2 * np.sin(np.arange(100) / 7.0)
    save_dance(tmp_path / "new.npz", small_dance(body))
    np.testing.assert_array_equal(load_dance(tmp_path / "new.npz").body_targets, body)

    # A format 1 file: no body_targets, no format key -> zeros.
    assert small_dance(None).body_targets.shape == (100, 4)
    save_dance(tmp_path / "old.npz", small_dance(None))
    with np.load(tmp_path / "old.npz") as npz:
        arrays = {k: npz[k] for k in npz.files if k not in ("body_targets", "format")}
    np.savez(tmp_path / "v1.npz", **arrays)
    loaded = load_dance(tmp_path / "v1.npz")
    assert loaded.body_targets.shape == (100, 4) and not loaded.body_targets.any()


@pytest.mark.parametrize(
    ("body", "message"),
    [
        (np.full((100, 4), 0.3) * [1, 0, 0, 0], "height offset reaches 0.3"),
        (np.full((100, 4), 1.5) * [0, 0, 1, 0], r"outside \[-1, 1\]"),
        (np.full((100, 4), np.nan), "NaN"),
        (np.zeros((99, 4)), r"body_targets must have shape \(100, 4\)"),
        (np.zeros((100, 4), dtype=bool), "real numbers"),
    ],
)
def test_bad_body_targets_in_a_file_are_refused(tmp_path, body, message):
    save_dance(tmp_path / "d.npz", small_dance(None))
    with np.load(tmp_path / "d.npz") as npz:
        arrays = {k: npz[k] for k in npz.files}
    arrays["body_targets"] = body
    np.savez(tmp_path / "bad.npz", **arrays)
    with pytest.raises(InputFileError, match=message) as err:
        load_dance(tmp_path / "bad.npz")
    assert "bad.npz" in str(err.value) and "\n" not in str(err.value)


# --- moves files and the CLI -----------------------------------------------------------------

GOOD_MOVES = """
[moves.wiggle]
n_beats = 2
weight_quiet = 0.0
weight_loud = 5.0
gestures = [ { column = "yaw_rad", amplitude = 0.1, every_beats = 0.5, shape = "swing" } ]

[styles.wiggly]
wiggle = 100.0
still = 0.0
run = 2.0
"""


def test_a_moves_file_adds_moves_and_styles(tmp_path):
    path = tmp_path / "moves.toml"
    path.write_text("\ufeff" + GOOD_MOVES)  # with the byte-order mark Windows editors write
    moves = load_moves(path)
    assert [m.name for m in moves.body_moves] == [m.name for m in BODY_MOVES] + ["wiggle"]
    grid = energetic_grid(20.0)
    feet = choreograph(grid, seed=0, fps=CHOREO_FPS, style="wiggly", moves=moves)
    body = choreograph_body(grid, feet, CHOREO_FPS, seed=0, style="wiggly", moves=moves)
    # The wiggle swings yaw every half beat: many yaw reversals.
    yaw_turns = np.count_nonzero(np.diff(np.sign(np.diff(body[:, 3]))) != 0)
    assert yaw_turns > grid.beats_s.size
    np.testing.assert_array_equal(
        body, choreograph_body(grid, feet, CHOREO_FPS, seed=0, style="wiggly", moves=moves)
    )


def test_a_built_in_style_re_weighted_in_a_file_keeps_what_the_file_does_not_name(tmp_path):
    """[styles.calm] with paw moves only keeps calm's trunk; with body moves only, its paws."""
    path = tmp_path / "moves.toml"
    path.write_text("[styles.calm]\nrun = 2.0\n\n[styles.energetic]\nsway = 3.0\n")
    moves = load_moves(path)
    assert moves.body_style("calm") == BODY_STYLES["calm"]
    assert moves.paw_styles()["calm"] == {"run": 2.0}
    assert moves.body_style("energetic") == {"sway": 3.0}
    assert moves.paw_styles()["energetic"] == STYLES["energetic"]


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[moves.x]\ngestures = [{column = 'roll_rad', amplitude = 0.5}]", "beyond the robot"),
        ("[moves.x]\ngestures = [{column = 'height_offset_m', amplitude = 0.05}]", "beyond"),
        ("[moves.x]\ngestures = [{column = 'tail', amplitude = 0.1}]", "unknown column 'tail'"),
        ("[moves.x]\ngestures = [{column = 'yaw_rad', amplitude = 0.1, spin = 1}]", "unknown key"),
        ("[moves.x]\ngestures = []\ntempo = 3", "unknown key 'tempo'"),
        ("[moves.x]\ngestures = [{column = 'yaw_rad', amplitude = 'big'}]", "must be a number"),
        ("[moves.x]\ngestures = [{column = 'yaw_rad', amplitude = nan}]", "amplitude is nan"),
        ("[moves.x]\nn_beats = 0\ngestures = []", "n_beats is 0"),
        ("[moves.x]\nn_beats = 2.5\ngestures = []", "whole number"),
        ("[moves.x]\nweight_loud = -1\ngestures = []", "weight_loud is -1"),
        ("[moves.x]\ngestures = [{column = 'yaw_rad', amplitude = 0.1, shape = 'loop'}]", "shape"),
        ("[moves.x]\nn_beats = 2", "missing 'gestures'"),
        ("[styles.s]\nmoonwalk = 1.0", "unknown move 'moonwalk'"),
        ("[styles.s]\nbounce = -2.0", "bounce is -2"),
        ("[dances.x]\na = 1", "unknown section 'dances'"),
        ("[moves.x\n", "not valid TOML"),
        (
            "[styles.none]\n" + "\n".join(f"{m.name} = 0" for m in MOVES),
            "styles.none gives every paw move weight 0",
        ),
    ],
)
def test_bad_moves_files_are_one_line_errors(tmp_path, text, message):
    path = tmp_path / "moves.toml"
    path.write_text(text)
    with pytest.raises(InputFileError, match=message) as err:
        load_moves(path)
    assert "moves.toml" in str(err.value) and "\n" not in str(err.value)


def test_choreograph_check_and_moves_on_the_command_line(tmp_path, demo_song):
    song, _ = demo_song
    moves = tmp_path / "moves.toml"
    moves.write_text(GOOD_MOVES)
    out = tmp_path / "dance.npz"
    runner = CliRunner()
    result = runner.invoke(
        app,
        [
            "choreograph",
            str(song),
            "-o",
            str(out),
            "--check",
            "--moves",
            str(moves),
            "--style",
            "wiggly",
        ],
    )
    assert result.exit_code == 0, result.output
    assert "clamp check" in result.output and "roll_rad" in result.output
    assert not out.exists()  # --check writes nothing
    result = runner.invoke(app, ["choreograph", str(song), "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert np.ptp(load_dance(out).body_targets[:, 0]) > 0.01

    bad = tmp_path / "bad.toml"
    bad.write_text("[moves.x]\ngestures = [{column = 'roll_rad', amplitude = 0.9}]")
    result = runner.invoke(app, ["choreograph", str(song), "--check", "--moves", str(bad)])
    # The installed command turns this into "quaddance: error: ..." and exit status 2.
    assert isinstance(result.exception, InputFileError)
    assert "bad.toml" in str(result.exception) and "beyond the robot" in str(result.exception)


def test_make_dance_takes_moves(tmp_path, demo_song):
    song, _ = demo_song
    path: Path = tmp_path / "moves.toml"
    path.write_text(GOOD_MOVES)
    dance, _ = make_dance(song, None, DanceSpec(style="wiggly", moves=load_moves(path)))
    assert "moves.toml" in dance.source
    assert np.ptp(dance.body_targets[:, 3]) > 0.05
