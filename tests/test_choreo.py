"""The beat grid and the built-in choreographer: human plausibility, timing, determinism."""

from __future__ import annotations

import itertools
import subprocess
import sys
from types import SimpleNamespace

import numpy as np
import pytest

from quaddance.choreo.choreographer import (
    LIFTS,
    MAX_FOOT_SPEED_M_S,
    MAX_HEIGHT_M,
    MIN_GROUND_S,
    MOVES,
    STYLES,
    choreograph,
    plan_dance,
)
from quaddance.choreo.grid import MusicGrid, synthetic_grid
from quaddance.errors import QuaddanceError

FPS = 60.0


def segments(h: np.ndarray) -> list[tuple[int, int]]:
    """(start, stop) frame ranges where ``h`` > 0."""
    up = np.concatenate([[0], (h > 0).astype(np.int8), [0]])
    edges = np.diff(up)
    return list(zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1), strict=True))


def peak_times_s(feet: np.ndarray, fps: float) -> np.ndarray:
    """Time of the highest frame of every lift of either foot, s."""
    out = [
        (a + int(np.argmax(feet[a:b, k]))) / fps for k in (0, 1) for a, b in segments(feet[:, k])
    ]
    return np.sort(np.asarray(out))


def two_level_grid(quiet_first: bool = True) -> MusicGrid:
    """120 BPM for 64 s; one section quiet (energy 0.1), the other loud (1.0), cut at 32 s."""
    beats = 0.5 + 0.5 * np.arange(126)
    t = np.arange(64 * 50) / 50.0
    quiet = t < 32.0 if quiet_first else t >= 32.0
    return MusicGrid(
        duration_s=64.0,
        beats_s=beats,
        downbeats_s=beats[::4],
        energy=np.where(quiet, 0.1, 1.0),
        energy_fps=50.0,
        sections_s=np.array([0.0, 32.0]),
    )


# --- grid -------------------------------------------------------------------------------------


def test_synthetic_grid_structure():
    grid = synthetic_grid(100.0, 90.0, np.random.default_rng(3), beats_per_bar=3, n_sections=4)
    period = 60.0 / 100.0
    np.testing.assert_allclose(np.diff(grid.beats_s), period)
    assert grid.beats_s[0] > 0 and grid.beats_s[-1] <= 90.0
    assert abs(grid.tempo_bpm - 100.0) < 1e-6
    # Downbeats are every third beat, taken from the beats.
    idx = np.searchsorted(grid.beats_s, grid.downbeats_s)
    np.testing.assert_allclose(grid.beats_s[idx], grid.downbeats_s)
    assert np.all(np.diff(idx) == 3)
    # Sections start at 0 and then on downbeats.
    assert grid.sections_s[0] == 0.0 and 2 <= grid.sections_s.size <= 4
    assert np.all(np.isin(grid.sections_s[1:], grid.downbeats_s))
    assert grid.energy.shape == (int(np.ceil(90.0 * grid.energy_fps)),)
    assert np.all(grid.energy > 0)


def test_synthetic_grid_swing_and_determinism():
    straight = synthetic_grid(120.0, 30.0, np.random.default_rng(1))
    again = synthetic_grid(120.0, 30.0, np.random.default_rng(1))
    np.testing.assert_array_equal(straight.beats_s, again.beats_s)
    np.testing.assert_array_equal(straight.energy, again.energy)
    swung = synthetic_grid(120.0, 30.0, np.random.default_rng(1), swing=0.2)
    gaps = np.diff(swung.beats_s)
    # Every second beat is late by 20 % of a beat: long gap, short gap, alternating.
    np.testing.assert_allclose(gaps[0::2], 0.5 * 1.2)
    np.testing.assert_allclose(gaps[1::2], 0.5 * 0.8)


def test_synthetic_grid_sections_change_loudness():
    grid = synthetic_grid(120.0, 120.0, np.random.default_rng(5), n_sections=6)
    e = grid.energy_at(np.arange(0, 120, 0.5))
    means = np.bincount(grid.section_of(np.arange(0, 120, 0.5)), weights=e)
    means /= np.bincount(grid.section_of(np.arange(0, 120, 0.5)))
    assert means.size == grid.sections_s.size
    assert means.max() - means.min() > 0.2


def test_grid_normalises_energy_and_reads_analysis():
    analysis = SimpleNamespace(
        duration_s=10.0,
        beats_s=np.array([1.5, 0.5, 1.0]),  # unsorted on purpose
        downbeats_s=np.array([0.5]),
        rms_env=np.linspace(-60.0, -6.0, 430),  # dB: any scale is fine
        env_fps=43.0,
        sections_s=np.array([0.0, 5.0]),
        tempo_bpm=120.0,
    )
    grid = MusicGrid.from_analysis(analysis)
    np.testing.assert_array_equal(grid.beats_s, [0.5, 1.0, 1.5])
    e = grid.normalized_energy()
    assert e.min() >= 0.0 and e.max() <= 1.0
    assert grid.energy_at(np.array([9.0]))[0] > 0.8 > 0.2 > grid.energy_at(np.array([0.5]))[0]
    np.testing.assert_array_equal(grid.section_of(np.array([1.0, 5.0, 9.0])), [0, 1, 1])
    flat = MusicGrid(10.0, [1.0], [], np.ones(100), 10.0, [])
    np.testing.assert_allclose(flat.normalized_energy(), 0.5)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"duration_s": 0.0},
        {"beats_s": np.array([1.0, np.nan])},
        {"energy": np.ones((3, 2))},
        {"energy_fps": -1.0},
    ],
)
def test_grid_rejects_bad_values(kwargs):
    base = {
        "duration_s": 10.0,
        "beats_s": np.array([1.0, 2.0]),
        "downbeats_s": np.array([1.0]),
        "energy": np.ones(100),
        "energy_fps": 10.0,
        "sections_s": np.array([0.0]),
    }
    with pytest.raises(QuaddanceError):
        MusicGrid(**{**base, **kwargs})


# --- choreographer ----------------------------------------------------------------------------

CASES = [
    (tempo, seed, swing)
    for tempo in (70.0, 100.0, 128.0, 160.0, 190.0)
    for seed in (0, 1, 2)
    for swing in (0.0, 0.12)
]


@pytest.mark.parametrize(("tempo", "seed", "swing"), CASES)
def test_dance_is_humanly_plausible(tempo, seed, swing):
    grid = synthetic_grid(tempo, 40.0, np.random.default_rng(seed + 100), swing=swing)
    feet = choreograph(grid, seed=seed, fps=FPS)
    assert feet.shape == (int(np.ceil(40.0 * FPS)), 2)
    # Never both feet up.
    assert np.all(np.minimum(feet[:, 0], feet[:, 1]) <= 1e-12)
    # Heights within a human range, and the dancer does dance.
    assert feet.min() >= 0.0 and feet.max() <= MAX_HEIGHT_M + 1e-12
    assert feet.max() > 0.08
    # No jumps: per-frame change within the speed limit.
    assert np.abs(np.diff(feet, axis=0)).max() * FPS <= MAX_FOOT_SPEED_M_S * 1.001
    # Every lift starts and ends on the floor, with both feet down for a while in between.
    all_up = np.any(feet > 0, axis=1)
    runs = segments(all_up.astype(float))
    gaps = [b2 - b1 for (_, b1), (b2, _) in itertools.pairwise(runs)]
    assert min(gaps) >= np.floor(MIN_GROUND_S * FPS)


def test_dance_is_smooth_c1():
    """At a fine sampling the velocity changes little per step: no kinks, only curves."""
    grid = synthetic_grid(150.0, 12.0, np.random.default_rng(7))
    fps = 4000.0
    feet = choreograph(grid, seed=4, fps=fps)
    velocity = np.diff(feet, axis=0) * fps
    # A kink of even 0.3 m/s would show as one step; C1 curves change by acc * dt only.
    assert np.abs(np.diff(velocity, axis=0)).max() < 0.2
    # And the ends of each lift are at rest (velocity ~ 0 entering and leaving the floor).
    for k in (0, 1):
        for a, b in segments(feet[:, k]):
            assert abs(velocity[max(a - 1, 0), k]) < 0.05
            assert abs(velocity[min(b - 1, velocity.shape[0] - 1), k]) < 0.05


@pytest.mark.parametrize("tempo", [84.0, 120.0, 172.0])
def test_lifts_peak_on_beats(tempo):
    grid = synthetic_grid(tempo, 60.0, np.random.default_rng(int(tempo)))
    feet = choreograph(grid, seed=2, fps=FPS)
    peaks = peak_times_s(feet, FPS)
    beats = grid.beats_s
    half_beats = 0.5 * (beats[:-1] + beats[1:])
    to_beat = np.abs(peaks[:, None] - beats[None, :]).min(axis=1)
    to_half = np.abs(peaks[:, None] - half_beats[None, :]).min(axis=1)
    assert peaks.size > 0.4 * beats.size  # a lively dance, not a statue
    # Every peak sits within a frame of a beat or (double-time moves) a half beat.
    assert np.all(np.minimum(to_beat, to_half) <= 1.0 / FPS + 1e-9)
    assert np.mean(to_beat <= 1.0 / FPS + 1e-9) > 0.6


def test_accents_on_downbeats():
    heights_down, heights_other = [], []
    for seed in range(6):
        grid = synthetic_grid(110.0, 60.0, np.random.default_rng(seed))
        plan = plan_dance(grid, seed=seed)
        near_down = np.abs(plan.peak_s[:, None] - grid.downbeats_s[None, :]).min(axis=1) < 1e-6
        on_beat = np.abs(plan.peak_s[:, None] - grid.beats_s[None, :]).min(axis=1) < 1e-6
        heights_down.extend(plan.height_m[near_down])
        heights_other.extend(plan.height_m[on_beat & ~near_down])
    assert np.mean(heights_down) > 1.1 * np.mean(heights_other)


def test_deterministic_per_seed_and_different_otherwise():
    grid = synthetic_grid(118.0, 30.0, np.random.default_rng(0))
    other_song = synthetic_grid(118.0, 30.0, np.random.default_rng(1))
    a = choreograph(grid, seed=5)
    np.testing.assert_array_equal(a, choreograph(grid, seed=5))
    assert not np.allclose(a, choreograph(grid, seed=6))
    assert not np.allclose(a, choreograph(other_song, seed=5))
    assert not np.allclose(a, choreograph(grid, seed=5, style="energetic"))


def test_song_fingerprint_reads_beats_to_the_millisecond():
    """The paw and body choreographers seed with one fingerprint of the song: a beat moved
    under half a millisecond keeps the dance's moves, one moved by a millisecond draws others."""
    grid = synthetic_grid(118.0, 30.0, np.random.default_rng(0))

    def moved(shift_s: float) -> MusicGrid:
        beats = grid.beats_s.copy()
        beats[10] += shift_s
        return grid.with_beats(beats, grid.downbeats_s)

    feet = plan_dance(grid, seed=5).foot
    assert moved(0.0004).fingerprint() == grid.fingerprint()
    np.testing.assert_array_equal(plan_dance(moved(0.0004), seed=5).foot, feet)
    assert moved(0.0015).fingerprint() != grid.fingerprint()
    other = plan_dance(moved(0.0015), seed=5).foot
    assert other.shape != feet.shape or not np.array_equal(other, feet)


def test_same_beats_other_song_other_dance():
    """Two songs with the same beats but other loudness get other moves for one seed."""
    quiet_first, loud_first = two_level_grid(True), two_level_grid(False)
    assert not np.allclose(choreograph(quiet_first, seed=1), choreograph(loud_first, seed=1))


def test_louder_sections_have_bigger_and_more_moves():
    counts = {"quiet": 0, "loud": 0}
    heights: dict[str, list[float]] = {"quiet": [], "loud": []}
    for quiet_first in (True, False):
        grid = two_level_grid(quiet_first)
        for seed in range(8):
            plan = plan_dance(grid, seed=seed)
            # Skip the 4 s around the cut where the smoothed loudness crossfades.
            first = plan.peak_s < 30.0
            second = plan.peak_s > 34.0
            quiet, loud = (first, second) if quiet_first else (second, first)
            counts["quiet"] += int(quiet.sum())
            counts["loud"] += int(loud.sum())
            heights["quiet"].extend(plan.height_m[quiet])
            heights["loud"].extend(plan.height_m[loud])
    assert counts["loud"] > 1.3 * counts["quiet"]
    assert np.mean(heights["loud"]) > 1.3 * np.mean(heights["quiet"])


def test_styles_reweight_moves():
    grid = synthetic_grid(120.0, 120.0, np.random.default_rng(9))
    calm = sum(len(plan_dance(grid, seed=s, style="calm")) for s in range(4))
    energetic = sum(len(plan_dance(grid, seed=s, style="energetic")) for s in range(4))
    assert energetic > 1.2 * calm


def test_typical_heights_are_human():
    grid = synthetic_grid(110.0, 120.0, np.random.default_rng(11))
    plan = plan_dance(grid, seed=3)
    assert 0.05 <= np.median(plan.height_m) <= 0.15
    assert plan.height_m.max() > 0.25  # knee lifts and kicks show up in two minutes


def test_vocabulary_is_consistent():
    """Every step names a known lift, sits inside its move, and moves are in time order."""
    for move in MOVES:
        offsets = [step.at_beats for step in move.steps]
        assert offsets == sorted(offsets)
        assert all(0 <= o < move.n_beats for o in offsets)
        assert all(step.lift in LIFTS for step in move.steps)
    for weights in STYLES.values():
        assert set(weights) <= {m.name for m in MOVES}


def test_no_beats_no_dance_and_bad_arguments():
    silent = MusicGrid(5.0, [], [], np.zeros(50), 10.0, [])
    feet = choreograph(silent, seed=0, fps=30.0)
    assert feet.shape == (150, 2) and not feet.any()
    grid = synthetic_grid(120.0, 10.0, np.random.default_rng(0))
    with pytest.raises(QuaddanceError, match="style"):
        choreograph(grid, style="ballet")
    with pytest.raises(QuaddanceError, match="fps"):
        choreograph(grid, fps=0.0)


def test_choreo_and_targets_do_not_import_audio_stack():
    code = (
        "import sys\n"
        "import quaddance.choreo.grid, quaddance.choreo.choreographer\n"
        "import quaddance.targets, quaddance.dancefile, quaddance.pipeline\n"
        "from quaddance.pipeline import target_bank\n"
        "target_bank(2, 5.0, seed=0)\n"
        "bad = [m for m in sys.modules if m.startswith(('librosa', 'quaddance.music'))]\n"
        "assert not bad, bad\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)
