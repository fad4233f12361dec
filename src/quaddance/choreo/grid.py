"""What the choreographer needs from music: beats, downbeats, a loudness envelope, sections.

A `MusicGrid` comes either from an audio analysis (`MusicGrid.from_analysis`) or from
`synthetic_grid`, which invents a plausible song structure without any audio; the trainer
uses the latter to build thousands of target sequences on a machine without an audio stack.
This module must not import librosa or `quaddance.music`.
"""

from __future__ import annotations

import dataclasses
import zlib
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from quaddance.errors import QuaddanceError
from quaddance.layout import BEATS_PER_BAR

#: Window over which loudness is averaged before it steers the dance, s. About two beats:
#: moves follow the feel of a passage, not single drum hits.
ENERGY_SMOOTH_S = 1.0


def _as_times(name: str, values: Any) -> np.ndarray:
    """Return ``values`` as a sorted, unique, finite float64 vector of times, s."""
    arr = np.asarray(values, dtype=np.float64)
    if arr.ndim != 1:
        raise QuaddanceError(
            f"MusicGrid.{name} must be a 1-D array of times, got shape {arr.shape}"
        )
    if not np.all(np.isfinite(arr)):
        raise QuaddanceError(f"MusicGrid.{name} contains NaN or infinite times")
    return np.unique(arr)


def _moving_average(x: np.ndarray, width: int) -> np.ndarray:
    """Centred moving average over ``width`` samples; edge padding keeps the ends at their
    own level and the length unchanged."""
    if width <= 1 or x.size == 0:
        return x
    padded = np.pad(x, (width // 2, width - 1 - width // 2), mode="edge")
    return np.convolve(padded, np.full(width, 1.0 / width), mode="valid")


@dataclass
class MusicGrid:
    """The timing and loudness of a piece of music, all times in seconds from its start.

    Attributes:
        duration_s: length of the piece, s (> 0).
        beats_s: (B,) beat times, s; sorted and de-duplicated on construction.
        downbeats_s: (D,) times of the first beat of each bar, s (may be empty).
        energy: (E,) loudness envelope sampled at ``energy_fps``; any scale (RMS, dB, ...):
            it is normalised to [0, 1] by `normalized_energy`.
        energy_fps: sample rate of ``energy``, Hz (> 0).
        sections_s: (S,) start times of the song's sections, s; a start at 0 is optional.
    """

    duration_s: float
    beats_s: np.ndarray
    downbeats_s: np.ndarray
    energy: np.ndarray
    energy_fps: float
    sections_s: np.ndarray

    def __post_init__(self) -> None:
        self.duration_s = float(self.duration_s)
        if not np.isfinite(self.duration_s) or self.duration_s <= 0:
            raise QuaddanceError(f"MusicGrid.duration_s must be > 0, got {self.duration_s}")
        self.energy_fps = float(self.energy_fps)
        if not np.isfinite(self.energy_fps) or self.energy_fps <= 0:
            raise QuaddanceError(f"MusicGrid.energy_fps must be > 0, got {self.energy_fps}")
        self.beats_s = _as_times("beats_s", self.beats_s)
        self.downbeats_s = _as_times("downbeats_s", self.downbeats_s)
        self.sections_s = _as_times("sections_s", self.sections_s)
        energy = np.asarray(self.energy, dtype=np.float64)
        if energy.ndim != 1 or not np.all(np.isfinite(energy)):
            raise QuaddanceError("MusicGrid.energy must be a finite 1-D envelope")
        self.energy = energy

    @classmethod
    def from_analysis(cls, analysis: Any) -> MusicGrid:
        """Build a grid from a `quaddance.music.analysis.Analysis` (duck-typed: only its
        ``duration_s``, ``beats_s``, ``downbeats_s``, ``rms_env``, ``env_fps`` and
        ``sections_s`` are read, so this module never imports the audio stack)."""
        return cls(
            duration_s=analysis.duration_s,
            beats_s=analysis.beats_s,
            downbeats_s=analysis.downbeats_s,
            energy=analysis.rms_env,
            energy_fps=analysis.env_fps,
            sections_s=analysis.sections_s,
        )

    def with_beats(
        self, beats_s: Sequence[float], downbeats_s: Sequence[float] | None = None
    ) -> MusicGrid:
        """This grid with other beats (a beat file's, `quaddance.music.beat_file`): loudness
        and sections stay. Downbeats are ``downbeats_s``, else every `BEATS_PER_BAR`-th beat
        from the first; the tempo follows from the beats (`tempo_bpm`)."""
        beats = np.asarray(beats_s, dtype=np.float64)
        downbeats = beats[::BEATS_PER_BAR] if downbeats_s is None else downbeats_s
        return dataclasses.replace(self, beats_s=beats, downbeats_s=downbeats)

    def normalized_energy(self, smooth_s: float = ENERGY_SMOOTH_S) -> np.ndarray:
        """Loudness mapped to [0, 1] by its 5th and 95th percentiles, then averaged over
        ``smooth_s`` seconds. Returns (E,); a flat or empty envelope reads as 0.5."""
        e = self.energy
        if e.size == 0:
            return np.full(1, 0.5)
        lo, hi = np.percentile(e, [5.0, 95.0])
        if hi - lo <= 1e-12 * max(1.0, abs(hi)):
            return np.full(e.shape, 0.5)
        unit = np.clip((e - lo) / (hi - lo), 0.0, 1.0)
        # Clip again: the float sum of the average can overshoot 1 by an ulp.
        return np.clip(_moving_average(unit, round(smooth_s * self.energy_fps)), 0.0, 1.0)

    def energy_at(self, t_s: np.ndarray, smooth_s: float = ENERGY_SMOOTH_S) -> np.ndarray:
        """Normalised, smoothed loudness in [0, 1] at times ``t_s`` (any shape), s."""
        unit = self.normalized_energy(smooth_s)
        frame_t = np.arange(unit.size) / self.energy_fps
        return np.interp(np.asarray(t_s, dtype=np.float64), frame_t, unit)

    def section_of(self, t_s: np.ndarray) -> np.ndarray:
        """Index of the section each time in ``t_s`` falls in (0 = the first section)."""
        starts = self.sections_s[self.sections_s > 0]
        return np.searchsorted(starts, np.asarray(t_s, dtype=np.float64), side="right")

    def fingerprint(self) -> int:
        """A number that differs between songs, mixed into the choreographers' seeds: same
        seed, other song, other dance. It reads the beats to the millisecond, so a beat
        tracker that moves a beat by a millisecond draws another dance."""
        beats_ms = np.round(self.beats_s * 1000.0).astype(np.int64)
        return zlib.crc32(beats_ms.tobytes() + np.float64(self.duration_s).tobytes())

    @property
    def tempo_bpm(self) -> float:
        """Tempo from the median beat period, BPM; 0 when there are fewer than two beats."""
        if self.beats_s.size < 2:
            return 0.0
        return float(60.0 / np.median(np.diff(self.beats_s)))


def synthetic_grid(
    tempo_bpm: float,
    duration_s: float,
    rng: np.random.Generator,
    swing: float = 0.0,
    beats_per_bar: int = 4,
    n_sections: int | None = None,
    energy_fps: float = 50.0,
) -> MusicGrid:
    """Invent a song's grid: steady beats, bars, sections on phrase boundaries, loudness.

    Parameters:
        tempo_bpm: beats per minute (> 0).
        duration_s: song length, s (> 0).
        rng: the only source of randomness, so a seeded generator gives the same grid.
        swing: delay of every second beat as a fraction of the beat period, in [0, 0.5)
            (0 = straight; 0.1 = a lazy backbeat).
        beats_per_bar: beats in a bar (>= 1); downbeats fall on every such beat.
        n_sections: number of sections; default one per 20 s or so (pop songs change part
            every 8 bars at about 100 BPM), at least one.
        energy_fps: sample rate of the generated loudness envelope, Hz.

    Returns:
        A `MusicGrid` whose loudness holds a level per section (drawn in [0.15, 1]),
        crossfades between levels over half a second, pulses on each beat, and carries a
        little slow noise, like an RMS envelope of a produced song.
    """
    if not tempo_bpm > 0:
        raise QuaddanceError(f"tempo_bpm must be > 0, got {tempo_bpm}")
    if not duration_s > 0:
        raise QuaddanceError(f"duration_s must be > 0, got {duration_s}")
    if not 0.0 <= swing < 0.5:
        raise QuaddanceError(f"swing must be in [0, 0.5), got {swing}")
    if beats_per_bar < 1:
        raise QuaddanceError(f"beats_per_bar must be >= 1, got {beats_per_bar}")
    period_s = 60.0 / tempo_bpm
    # Songs rarely start exactly on a beat: leave a short lead-in before the first one.
    first_s = rng.uniform(0.05, 0.05 + period_s)
    n_beats = max(0, int(np.floor((duration_s - first_s - swing * period_s) / period_s)) + 1)
    k = np.arange(n_beats)
    beats_s = first_s + k * period_s + swing * period_s * (k % 2)
    bar_offset = int(rng.integers(beats_per_bar))  # the song may open with a pickup
    downbeat_idx = np.arange(bar_offset, n_beats, beats_per_bar)
    downbeats_s = beats_s[downbeat_idx]

    if n_sections is None:
        n_sections = max(1, round(duration_s / 20.0))
    # Sections start on phrase boundaries (every 4 bars) when there are enough of them,
    # each near an even share of the song moved by up to a third of a share.
    phrase_starts = downbeats_s[4::4]
    if phrase_starts.size < n_sections - 1:
        phrase_starts = downbeats_s[1:]
    share_s = duration_s / n_sections
    ideal_s = share_s * (np.arange(1, n_sections) + rng.uniform(-1 / 3, 1 / 3, n_sections - 1))
    cuts = np.zeros(0)
    if phrase_starts.size and n_sections > 1:
        nearest = np.abs(phrase_starts[None, :] - ideal_s[:, None]).argmin(axis=1)
        cuts = np.unique(phrase_starts[nearest])
    sections_s = np.concatenate([[0.0], cuts])

    n_env = int(np.ceil(duration_s * energy_fps))
    t = np.arange(n_env) / energy_fps
    levels = rng.uniform(0.15, 1.0, size=sections_s.size)
    section = np.searchsorted(sections_s[1:], t, side="right")
    level = levels[section]
    level = _moving_average(level, round(0.5 * energy_fps))
    # Each beat is a drum hit: a fast attack and a 0.1 s decay on top of the level.
    pulse = np.zeros(n_env)
    if n_beats:
        last_beat = np.searchsorted(beats_s, t, side="right") - 1
        since_beat_s = t - beats_s[np.clip(last_beat, 0, None)]
        pulse = np.where(last_beat >= 0, np.exp(-np.abs(since_beat_s) / 0.1), 0.0)
    noise = _moving_average(rng.normal(0.0, 0.04, n_env), round(0.5 * energy_fps))
    energy = np.clip(level * (0.8 + 0.3 * pulse) + noise, 0.01, None)
    return MusicGrid(
        duration_s=duration_s,
        beats_s=beats_s,
        downbeats_s=downbeats_s,
        energy=energy,
        energy_fps=energy_fps,
        sections_s=sections_s,
    )
