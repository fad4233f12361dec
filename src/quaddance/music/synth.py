"""Songs made by code, with exactly known beats: the built-in demo song, test and benchmark songs.

Everything here is synthesised from sine waves and seeded noise, so there is no copyrighted
audio and the ground truth (beat, downbeat and section-change times) is exact by construction.

A song is a sequence of 4/4 bars. Its parts are:

- an optional quiet intro (soft plucked chords on every beat, soft hats on eighths, no kick
  or bass);
- then ``sections`` equal parts that alternate between a calm arrangement (kick on 1 and 3,
  hats on the beat, bass on 1 and 3, sustained chords) and a loud, denser one (kick on every
  beat, hats on eighths, bass on eighths, chord stabs, a crash on the first downbeat).

``swing`` delays every off-beat eighth note; ``syncopation`` moves kick, bass and chord stabs
onto off-beats (the classic trap for beat trackers); ``tempo_change`` switches tempo mid-song.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from quaddance.layout import BEATS_PER_BAR

DEMO_TEMPO_BPM = 118.0
"""Tempo of the built-in demo song: the middle of the dance range (AIST++ 80-130 BPM)."""

DEMO_DURATION_S = 30.0
"""Length of the built-in demo song: the length of one EDGE output clip (30 s, FACTS.md §3)."""

DEMO_SEED = 7

# A minor, I-V-vi-IV in C major order starting on Am: (root MIDI note, chord MIDI notes).
_PROGRESSIONS: tuple[tuple[tuple[int, tuple[int, ...]], ...], ...] = (
    ((45, (57, 60, 64)), (41, (53, 57, 60)), (48, (55, 60, 64)), (43, (55, 59, 62))),
    ((38, (57, 62, 65)), (46, (58, 62, 65)), (41, (57, 60, 65)), (45, (57, 61, 64))),
    ((40, (59, 64, 67)), (48, (60, 64, 67)), (43, (59, 62, 67)), (47, (59, 63, 66))),
)


@dataclass
class SongTruth:
    """The exact musical grid of a synthesised song.

    Attributes:
        tempo_bpm: tempo at the start of the song, beats per minute.
        beats_s: (n_beats,) beat times, seconds, every beat from the first to the song's end.
        downbeats_s: (n_bars,) times of beat 1 of every bar, seconds (a subset of ``beats_s``).
        section_change_s: (n_changes,) downbeat times where a new section starts, seconds
            (the song start itself is not listed).
        duration_s: length of the audio, seconds.
    """

    tempo_bpm: float
    beats_s: np.ndarray
    downbeats_s: np.ndarray
    section_change_s: np.ndarray
    duration_s: float
    extra: dict[str, float] = field(default_factory=dict)


def _midi_hz(note: float) -> float:
    return 440.0 * 2.0 ** ((note - 69.0) / 12.0)


def _beat_grid_s(
    tempo_bpm: float, duration_s: float, tempo_change: tuple[float, float] | None
) -> np.ndarray:
    """(n + 1,) beat times from 0 past ``duration_s``; the tempo switches on the first beat at
    or after ``tempo_change[0]`` seconds to ``tempo_change[1]`` BPM."""
    times = [0.0]
    bpm = tempo_bpm
    while times[-1] <= duration_s + 2.0 * 60.0 / min(tempo_bpm, 40.0):
        if tempo_change is not None and times[-1] >= tempo_change[0]:
            bpm = tempo_change[1]
        times.append(times[-1] + 60.0 / bpm)
    return np.asarray(times)


class _Voices:
    """One-shot instrument sounds rendered into a shared buffer (all mono float64)."""

    def __init__(self, n_samples: int, sr: int, rng: np.random.Generator) -> None:
        self.sr = sr
        self.out = np.zeros(n_samples)
        self.rng = rng

    def _add(self, t_s: float, sound: np.ndarray) -> None:
        start = round(t_s * self.sr)
        if start >= len(self.out) or start < 0:
            return
        end = min(len(self.out), start + len(sound))
        self.out[start:end] += sound[: end - start]

    def _t(self, length_s: float) -> np.ndarray:
        return np.arange(round(length_s * self.sr)) / self.sr

    def kick(self, t_s: float, gain: float) -> None:
        t = self._t(0.35)
        # A fast downward pitch sweep (120 -> 45 Hz) is what makes a synthetic kick read as one.
        freq = 45.0 + 75.0 * np.exp(-t / 0.03)
        phase = 2.0 * np.pi * np.cumsum(freq) / self.sr
        self._add(t_s, gain * np.sin(phase) * np.exp(-t / 0.12))

    def snare(self, t_s: float, gain: float) -> None:
        t = self._t(0.2)
        noise = self.rng.standard_normal(len(t)) * np.exp(-t / 0.05)
        tone = np.sin(2.0 * np.pi * 190.0 * t) * np.exp(-t / 0.04)
        self._add(t_s, gain * (0.45 * noise + 0.6 * tone))

    def hat(self, t_s: float, gain: float, open_hat: bool = False) -> None:
        t = self._t(0.25 if open_hat else 0.05)
        # Differencing white noise tilts it towards the treble, a cheap high-pass.
        noise = np.diff(self.rng.standard_normal(len(t) + 1))
        self._add(t_s, gain * 0.5 * noise * np.exp(-t / (0.08 if open_hat else 0.012)))

    def crash(self, t_s: float, gain: float) -> None:
        t = self._t(1.2)
        noise = np.diff(self.rng.standard_normal(len(t) + 1))
        self._add(t_s, gain * 0.35 * noise * np.exp(-t / 0.4))

    def bass(self, t_s: float, note: int, length_s: float, gain: float) -> None:
        t = self._t(length_s)
        f = _midi_hz(note)
        env = np.minimum(1.0, t / 0.005) * np.exp(-t / 0.35)
        env[-min(len(t), 64) :] *= np.linspace(1.0, 0.0, min(len(t), 64))
        wave = np.sin(2 * np.pi * f * t) + 0.35 * np.sin(4 * np.pi * f * t)
        self._add(t_s, gain * wave * env)

    def chord(
        self, t_s: float, notes: tuple[int, ...], length_s: float, gain: float, pluck: bool
    ) -> None:
        t = self._t(length_s)
        attack_s = 0.004 if pluck else 0.06
        decay = np.exp(-t / 0.18) if pluck else np.ones_like(t)
        env = np.minimum(1.0, t / attack_s) * decay
        env[-min(len(t), 256) :] *= np.linspace(1.0, 0.0, min(len(t), 256))
        wave = np.zeros_like(t)
        for note in notes:
            f = _midi_hz(note)
            wave += np.sin(2 * np.pi * f * t) + 0.3 * np.sin(4 * np.pi * f * t)
        self._add(t_s, gain * wave * env / len(notes))


def render_song(
    tempo_bpm: float,
    duration_s: float,
    seed: int,
    swing: float = 0.0,
    syncopation: bool = False,
    intro_s: float = 0.0,
    tempo_change: tuple[float, float] | None = None,
    sections: int = 2,
    sr: int = 22050,
) -> tuple[np.ndarray, SongTruth]:
    """Synthesise a drums + bass + chords song with exactly known beats.

    Args:
        tempo_bpm: tempo at the start, beats per minute.
        duration_s: length of the audio, seconds.
        seed: picks the chord progression and the noise of the drums; same seed, same audio.
        swing: 0 plays straight eighths, 1 delays every off-beat eighth to the last triplet
            (2/3 of the beat).
        syncopation: put kick, bass and chord stabs on off-beats.
        intro_s: length of a quiet intro (rounded up to whole bars), seconds; 0 for none.
        tempo_change: ``(at_s, new_tempo_bpm)``: from the first beat at or after ``at_s``
            the song plays at ``new_tempo_bpm``.
        sections: number of parts after the intro; they alternate calm, loud, calm, ...
            (at least 2, so that there is at least one section change).
        sr: sample rate, Hz.

    Returns:
        ``(y, truth)``: ``y`` is (n,) float32 mono audio at ``sr`` with peak 0.9; ``truth``
        holds the exact beats, downbeats and section changes.
    """
    if not 0.0 <= swing <= 1.0:
        raise ValueError(f"swing must be in [0, 1], got {swing}")
    if sections < 2:
        raise ValueError(f"sections must be >= 2 so that the song has a change, got {sections}")
    rng = np.random.default_rng(seed)
    grid_s = _beat_grid_s(tempo_bpm, duration_s, tempo_change)
    n_samples = round(duration_s * sr)
    voices = _Voices(n_samples, sr, rng)
    progression = _PROGRESSIONS[seed % len(_PROGRESSIONS)]
    n_bars = (len(grid_s) - 1) // BEATS_PER_BAR
    intro_bars = 0
    if intro_s > 0.0:
        bar_s = BEATS_PER_BAR * 60.0 / tempo_bpm
        intro_bars = int(np.ceil(intro_s / bar_s - 1e-9))
    bars_in_song = max(1, sum(grid_s[::BEATS_PER_BAR] < duration_s) - intro_bars)
    section_bars = max(1, round(bars_in_song / sections))
    offbeat = 0.5 + swing / 6.0

    def time_at(beat: float) -> float:
        # The last bar's end can be the grid's last beat: extend its final interval.
        whole = min(int(np.floor(beat)), len(grid_s) - 2)
        return float(grid_s[whole] + (beat - whole) * (grid_s[whole + 1] - grid_s[whole]))

    section_change_s: list[float] = []
    for bar in range(n_bars):
        b0 = bar * BEATS_PER_BAR
        if grid_s[b0] >= duration_s:
            break
        root, notes = progression[bar % len(progression)]
        bar_len_s = grid_s[b0 + BEATS_PER_BAR] - grid_s[b0]
        velocity = 1.0 + 0.05 * rng.standard_normal()
        if bar < intro_bars:
            for beat in range(BEATS_PER_BAR):
                voices.chord(time_at(b0 + beat), notes, 0.4, 0.12 * velocity, pluck=True)
                voices.hat(time_at(b0 + beat), 0.06)
                voices.hat(time_at(b0 + beat + offbeat), 0.04)
            continue
        part = min(sections - 1, (bar - intro_bars) // section_bars)
        if bar > 0 and (bar == intro_bars or (bar - intro_bars) == part * section_bars):
            section_change_s.append(float(grid_s[b0]))
        loud = part % 2 == 1
        gain = 1.0 if loud else 0.55
        if loud and (bar - intro_bars) % section_bars == 0:
            voices.crash(time_at(b0), gain)
        kicks = [0.0, 1.0, 2.0, 3.0] if loud else [0.0, 2.0]
        bass_hits = [b + f for b in range(4) for f in (0.0, offbeat)] if loud else [0.0, 2.0]
        if syncopation:
            kicks = [0.0, 1.0 + offbeat, 2.0 + offbeat] + ([3.0] if loud else [])
            bass_hits = [0.0, 1.0 + offbeat, 2.0 + offbeat, 3.0 + offbeat]
        for k in kicks:
            voices.kick(time_at(b0 + k), gain * velocity)
        for s in (1.0, 3.0):
            voices.snare(time_at(b0 + s), 0.8 * gain * velocity)
        hats = [b + f for b in range(4) for f in (0.0, offbeat)] if loud else [0.0, 1.0, 2.0, 3.0]
        for h in hats:
            accent = 1.0 if h == int(h) else 0.6
            voices.hat(time_at(b0 + h), 0.35 * gain * accent)
        for i, b in enumerate(bass_hits):
            next_b = bass_hits[i + 1] if i + 1 < len(bass_hits) else 4.0
            length_s = 0.9 * (time_at(b0 + next_b) - time_at(b0 + b))
            voices.bass(time_at(b0 + b), root, length_s, 0.7 * gain)
        if loud or syncopation:
            if syncopation:  # off-beat skank, as in reggae and ska
                stabs = [b + offbeat for b in range(4)]
            else:
                stabs = [0.0, 1.0, 1.0 + offbeat, 2.0, 3.0, 3.0 + offbeat]
            for s in stabs:
                voices.chord(time_at(b0 + s), notes, 0.25 * bar_len_s, 0.5 * gain, pluck=True)
        else:
            voices.chord(time_at(b0), notes, bar_len_s, 0.35 * gain, pluck=False)

    y = voices.out
    y *= 0.9 / max(float(np.max(np.abs(y))), 1e-9)
    beats_s = grid_s[grid_s < duration_s - 1e-9]
    truth = SongTruth(
        tempo_bpm=float(tempo_bpm),
        beats_s=beats_s,
        downbeats_s=beats_s[::BEATS_PER_BAR].copy(),
        section_change_s=np.asarray(section_change_s),
        duration_s=float(duration_s),
        extra={"final_tempo_bpm": float(tempo_change[1] if tempo_change else tempo_bpm)},
    )
    return y.astype(np.float32), truth


def demo_song(sr: int = 22050) -> tuple[np.ndarray, SongTruth]:
    """The built-in demo song: 30 s at 118 BPM, drums + bass + chords, calm then loud."""
    return render_song(DEMO_TEMPO_BPM, DEMO_DURATION_S, seed=DEMO_SEED, sections=2, sr=sr)


def write_demo_song(path: str | Path, sr: int = 22050) -> SongTruth:
    """Write the built-in demo song to ``path`` (format from its suffix, e.g. ``.wav``).

    The song is deterministic: the same file every time. Returns its exact grid.
    """
    from quaddance.music.audio import write_audio

    y, truth = demo_song(sr)
    write_audio(path, y, sr)
    return truth
