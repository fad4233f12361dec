"""Music analysis: tempo, beats, downbeats, onset and loudness envelopes, sections.

The beat tracker follows the classic recipe (onset envelope -> tempo -> dynamic programming,
Ellis 2007) with the changes that matter for dance music:

1. Two onset envelopes from a mel spectrogram, each divided by its local level so that a quiet
   intro counts as much as a loud chorus: one for tempo (dB flux, full band + kick/bass band)
   and one for placing beats (dB flux + treble flux with gentler compression, where snare, hats
   and cymbals make drum hits stand out from off-beat bass notes and chord stabs). A quarter
   of each is a learned beat activation (`music.beat_activation`, fitted on real music with
   exact beats), which tells the bands that carry the beat from those that carry off-beats;
   three quarters of the result is BeatNet's beat activation (`music.beatnet`, recurrent
   networks trained on annotated real music, CC BY 4.0), which hears the beat where the bands
   alone put it on the off-beats of electronic music. BeatNet hears the song five times, a
   little faster and slower, and its activations are averaged: its phase errors depend on the
   tempo it hears.
2. The tempo is the lag whose first four multiples carry the most autocorrelation (which rules
   out the "2/3 tempo" error), times a broad log-normal prior centred on the usual dance
   tempi (80-160 BPM), which settles the half/double-tempo choice where the music leaves it
   open: octave errors dominate beat-tracking errors (FACTS.md §4).
3. The tempo may change: a local tempo curve (Viterbi over windowed autocorrelation near the
   global tempo, with drift and jumps) guides the dynamic program, which places beats on half
   frames and holds their phase stiffly, as a dancer keeps the step through a passage of
   louder off-beats.
4. Off-beats: beats move by half a beat when the bass line changes pitch at their midpoints
   rather than at them (off-beat hats, skanking keys pull the tracker; harmony does not move).
   Then beats faster than the dance range (`DANCE_TEMPO_BPM`, 60-180 BPM) are halved and
   slower ones doubled, so that the beat level reported is one a robot dances. Each beat stays
   on its onset frame: moving it to the envelope's nearby peak gained nothing on real music.
5. Downbeats: the 4/4 bar phase with the most bass onsets, chord changes and BeatNet's
   downbeat probability on beat 1.
6. Sections: checkerboard novelty on bar-synchronous loudness, onset density and harmony.

Envelopes are sampled at ``env_fps = sr / hop_length`` (43.07 frames/s at 22.05 kHz, hop 512).
"""

from __future__ import annotations

import itertools
import json
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from quaddance.errors import InputFileError, not_a_file
from quaddance.layout import BEATS_PER_BAR, DANCE_TEMPO_BPM
from quaddance.music import beat_activation

TEMPO_SPAN_BEATS = 4
"""Beats per span over which `median_beat_period_s` measures the reported tempo."""
ANALYSIS_PEAK = 0.9
"""`analyze` hears every file at this peak level, so that a file's level does not move its
beats, downbeats or sections (a copy 3 dB quieter moved them, and the dance with them). It is
the level `synth` renders songs at: those are heard as they are."""
MIN_BEAT_GAP_S = 0.2
"""Beats are at least this far apart, seconds (300 BPM, above any dance tempo): the offline
analyser and the online tracker (`music.online_beats`) drop a beat that would come sooner
after the one before, so their beats always increase."""


@dataclass(frozen=True)
class AnalysisConfig:
    """Settings of the analyser. Weights and costs marked "tuned" were set on the code-made
    songs of ``bench/beats.py`` (not the demo song); the rest are librosa's defaults or
    physical ranges."""

    hop_length: int = 512
    """Samples between envelope frames (librosa default; 23.2 ms at 22.05 kHz)."""
    n_fft: int = 2048
    """FFT size (librosa default; 93 ms at 22.05 kHz)."""
    n_mels: int = 96
    """Mel bands of the onset spectrogram."""
    low_band_hz: float = 160.0
    """Upper edge of the kick/bass band, Hz (kick fundamentals lie at 40-120 Hz)."""
    low_band_weight: float = 1.0
    """Weight of the low-band flux added to the full-band flux for tempo estimation (tuned)."""
    high_band_hz: float = 3000.0
    """Lower edge of the treble band, Hz (snare noise, hats and cymbals)."""
    high_band_weight: float = 1.0
    """Weight of the treble flux in the beat-placement onset envelope (tuned)."""
    log_compression: float = 1e5
    """Gain inside log1p(gain * mel / max) of the treble onset: about 50 dB of range."""
    local_norm_s: float = 3.0
    """Window of the local level that the onset envelope is divided by, seconds."""
    min_bpm: float = 50.0
    """Slowest tempo searched, BPM: the dance range with a margin, so that a clear pulse just
    outside it is found (its beats are then folded into the range)."""
    max_bpm: float = 220.0
    """Fastest tempo searched, BPM."""
    prior_center_bpm: float = 120.0
    """Centre of the tempo prior: the middle of the usual dance tempi 80-160 BPM (FACTS.md §4)."""
    prior_sigma_octaves: float = 1.2
    """Width of the log-normal tempo prior, octaves (tuned)."""
    tempo_harmonics: int = 4
    """Multiples of a beat period whose autocorrelation counts towards its salience."""
    tempo_window_s: float = 8.0
    """Autocorrelation window of the local tempo curve, seconds."""
    max_tempo_ratio: float = 1.3
    """Local tempo may stray this far (ratio) from the global tempo."""
    tempo_jump_cost: float = 3.0
    """Cost of a sudden tempo change, in units of one 0.25 s step of clear evidence (tuned)."""
    tempo_deviation_cost: float = 2.0
    """Cost of local tempo deviating from the global tempo, per squared octave (tuned)."""
    bass_chroma_max_hz: float = 300.0
    """Upper edge of the bass-line chroma, Hz (bass fundamentals; chords lie above)."""
    offbeat_harmony_ratio: float = 2.0
    """Beats move by half a beat when the bass line changes pitch this many times more at the
    midpoints between them than at the beats (tuned)."""
    tightness: float = 3000.0
    """Penalty on beat intervals off the local period (outside the periods at the interval's
    two beats, so that a sudden tempo change costs nothing), per squared log ratio, in standard
    deviations of the beat envelope (librosa's 100 is looser; our local tempo curve already
    follows tempo changes). High, so that the beats keep their phase through a passage whose
    off-beats are louder, as a dancer keeps the step: sliding half a beat over 8 beats costs
    8 * 3000 * ln(17/16)^2 = 88 (tuned with ``beat_steps_per_frame`` on songs outside the
    held-out parts)."""
    beat_steps_per_frame: int = 2
    """The beat tracker's dynamic program places beats on this many steps per envelope frame
    (the envelope interpolated between frames). On whole frames (23 ms) a beat interval can
    only be 19 or 20 frames where the period is 19.4, so a high ``tightness`` charges every
    beat for that rounding rather than for drifting off the phase; on half frames it can be
    three times higher (tuned with ``tightness``). The beats are then rounded to frames."""
    min_beat_clarity: float = 0.25
    """Below this `beat_clarity` the audio has no clear steady beat: its beats are still
    returned, and `Analysis.notes` says so. Beatless audio (noise, speech) scores at most 0.14,
    the 79 songs outside the held-out parts of the real-music sets 0.39 or more
    (`python -m benchmarks.beat_clarity`)."""
    section_kernel_bars: int = 4
    """Bars compared on each side of a candidate section boundary."""
    section_min_bars: int = 2
    """Shortest section, bars."""
    section_threshold: float = 1.0
    """Novelty a boundary needs; one unit = 3 dB louder or 50 % more onsets (tuned)."""
    activation_weight: float = 0.25
    """Share of the learned beat activation (`music.beat_activation`) in both onset envelopes;
    0 leaves them as measured (tuned with ``beatnet_weight``)."""
    activation_model: Path | None = None
    """The activation's weights file; None: the shipped ``data/beat_activation.json``."""
    beatnet_weight: float = 0.75
    """Share of BeatNet's beat activation (`music.beatnet`: networks trained on annotated real
    music, CC BY 4.0) in both onset envelopes, after the learned activation's; 0 leaves it out.
    Tuned with ``activation_weight`` and ``beatnet_stretches`` on songs outside the held-out
    parts (the real-music sets' tuning songs and 60 more songs with exact beats: ``python -m
    benchmarks.analyser_mix``)."""
    beatnet_stretches: tuple[float, ...] = (0.9, 0.93, 1.0, 1.07, 1.1)
    """BeatNet hears the song at each of these lengths (0.9: 10 % shorter, played faster); its
    activations, mapped back to the song's time, are averaged: the network's phase errors
    depend on the tempo it hears and part cancel (test-time augmentation; tuned as
    ``beatnet_weight``). ``(1.0,)`` runs it once."""


@dataclass
class Analysis:
    """What the rest of quaddance needs to know about a piece of music.

    Attributes:
        tempo_bpm: main tempo, beats per minute.
        beats_s: (n_beats,) beat times, seconds, each at least `MIN_BEAT_GAP_S` after the
            one before.
        downbeats_s: (n_bars,) times of beat 1 of each bar (4/4 assumed), seconds: every
            fourth of ``beats_s``.
        onset_env: (n_frames,) onset strength, scaled to a maximum of 1, at ``env_fps``.
        rms_env: (n_frames,) loudness as linear RMS amplitude (full scale = 1), at ``env_fps``.
        env_fps: frame rate of both envelopes, frames per second (``sr / hop_length``).
        sections_s: (n_sections,) start time of each section, seconds; the first is 0.0.
        duration_s: length of the audio, seconds.
        source: the file analysed, or "" for an array.
        beat_clarity: how clearly the music pulses at a dance tempo (`beat_clarity`); None
            where not measured (an analysis file written before it was).
        extra: diagnostics that are not saved (``global_tempo_bpm``: tempo before tracking;
            ``offbeat_shift``: whether the beats moved by half a beat).
    """

    tempo_bpm: float
    beats_s: np.ndarray
    downbeats_s: np.ndarray
    onset_env: np.ndarray
    rms_env: np.ndarray
    env_fps: float
    sections_s: np.ndarray
    duration_s: float
    source: str = ""
    beat_clarity: float | None = None
    extra: dict[str, Any] = field(default_factory=dict)

    def to_json_dict(self) -> dict[str, Any]:
        """Plain-JSON form: lists of floats, times rounded to 0.1 ms."""
        return {
            "tempo_bpm": round(float(self.tempo_bpm), 3),
            "beats_s": [round(float(t), 4) for t in self.beats_s],
            "downbeats_s": [round(float(t), 4) for t in self.downbeats_s],
            "onset_env": [round(float(v), 5) for v in self.onset_env],
            "rms_env": [round(float(v), 6) for v in self.rms_env],
            "env_fps": float(self.env_fps),
            "sections_s": [round(float(t), 4) for t in self.sections_s],
            "duration_s": round(float(self.duration_s), 4),
            "source": self.source,
            **({} if self.beat_clarity is None else {"beat_clarity": round(self.beat_clarity, 3)}),
        }

    def summary(self) -> str:
        """One line for a person: length, tempo, beats, bars and where the sections start."""
        starts = ", ".join(f"{t:.1f}" for t in self.sections_s)
        return (
            f"{self.duration_s:.1f} s, tempo {self.tempo_bpm:.1f} BPM, "
            f"{self.beats_s.size} beats, {self.downbeats_s.size} bars, "
            f"{self.sections_s.size} sections (starting at {starts} s)"
        )

    def notes(self, name: str, cfg: AnalysisConfig | None = None) -> list[str]:
        """What a user should know before a robot dances to these beats: one line where the
        music has no clear steady beat (``beat_clarity`` under ``cfg.min_beat_clarity``)."""
        threshold = (cfg or AnalysisConfig()).min_beat_clarity
        if self.beat_clarity is None or self.beat_clarity >= threshold:
            return []
        return [
            f"{name}: no clear steady beat (beat clarity {self.beat_clarity:.2f}, under "
            f"{threshold:.2f}); the {self.beats_s.size} beats found at {self.tempo_bpm:.0f} BPM "
            "may not be what you hear (--beats FILE gives yours)"
        ]

    def save_json(self, path: str | Path) -> None:
        """Write the analysis as JSON, atomically."""
        from quaddance.fileio import write_json

        write_json(path, self.to_json_dict())

    @classmethod
    def load_json(cls, path: str | Path) -> Analysis:
        """Read an analysis written by ``save_json``; bad files raise ``InputFileError``."""
        path = Path(path)
        if not path.is_file():
            raise not_a_file(path)
        try:
            data = json.loads(path.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError) as err:
            raise InputFileError(path, f"is not valid JSON ({err})") from err
        if not isinstance(data, dict):
            raise InputFileError(path, "is not a quaddance analysis (not a JSON object)")
        array_keys = ("beats_s", "downbeats_s", "onset_env", "rms_env", "sections_s")
        missing = [k for k in ("tempo_bpm", "env_fps", *array_keys) if k not in data]
        if missing:
            raise InputFileError(path, f"is not a quaddance analysis (missing {missing})")
        try:
            arrays = {k: np.asarray(data[k], dtype=float) for k in array_keys}
            env_fps = float(data["env_fps"])
            tempo_bpm = float(data["tempo_bpm"])
        except (TypeError, ValueError) as err:
            raise InputFileError(path, f"has a malformed field ({err})") from err
        if not env_fps > 0 or any(a.ndim != 1 for a in arrays.values()):
            raise InputFileError(path, "has a non-positive env_fps or a field that is not a list")
        try:
            duration_s = float(data.get("duration_s", len(arrays["rms_env"]) / env_fps))
            clarity = data.get("beat_clarity")
            clarity = None if clarity is None else float(clarity)
        except (TypeError, ValueError) as err:
            raise InputFileError(
                path, f"has a malformed duration_s or beat_clarity ({err})"
            ) from err
        return cls(
            tempo_bpm=tempo_bpm,
            env_fps=env_fps,
            duration_s=duration_s,
            source=str(data.get("source", "")),
            beat_clarity=clarity,
            **arrays,
        )


# --- features ---------------------------------------------------------------------------------


@dataclass
class _Features:
    tempo_onset: np.ndarray  # (n,) onset envelope for tempo: full band + kick/bass band
    beat_onset: np.ndarray  # (n,) onset envelope for beat placement: full band + treble band
    low_onset: np.ndarray  # (n,) kick/bass band flux, dB
    raw_onset: np.ndarray  # (n,) full-band flux, dB
    rms: np.ndarray  # (n,) linear RMS
    hit_onset: np.ndarray  # (n,) full-band log1p flux: loud hits count more than soft notes
    chroma: np.ndarray  # (12, n)
    bass_chroma: np.ndarray  # (12, n) chroma of 30-300 Hz: the bass line's pitch
    band_rows: np.ndarray  # (16, n) the learned activation's input (`beat_activation`)
    fps: float
    beatnet: np.ndarray  # (n, 2) BeatNet's P(beat), P(downbeat) per frame; (n, 0) if unused


def _moving_average(x: np.ndarray, width: int) -> np.ndarray:
    import scipy.ndimage

    # Reflecting (not repeating) the edge keeps a hit at 0 s from inflating its own average.
    return scipy.ndimage.uniform_filter1d(x, size=max(1, width), mode="reflect")


def _local_normalise(x: np.ndarray, fps: float, cfg: AnalysisConfig) -> np.ndarray:
    """Remove the slowly varying floor, then divide by the local level, so that a quiet intro
    yields beats as clear as a loud chorus. The floor on the divisor keeps silence silent."""
    x = np.maximum(0.0, x - _moving_average(x, round(0.5 * fps)))
    level = _moving_average(x, round(cfg.local_norm_s * fps))
    return x / np.maximum(level, 0.1 * float(np.mean(level)) + 1e-9)


def _features(y: np.ndarray, sr: int, cfg: AnalysisConfig) -> _Features:
    from quaddance.music.spectral import (
        filterbanks,
        normalize_peak,
        power_to_db,
        rms_from_stft,
        stft_magnitude,
    )

    banks = filterbanks(sr, cfg.n_fft, cfg.n_mels)
    fps = sr / cfg.hop_length
    unpadded = y  # BeatNet frames the audio its own way
    # Lead the audio with silence so that a song starting on a hit gets a normal onset; the
    # extra frames are dropped again below.
    lead = -(-cfg.n_fft // cfg.hop_length)
    y = np.concatenate([np.zeros(lead * cfg.hop_length, dtype=y.dtype), y])
    stft = stft_magnitude(y, cfg.n_fft, cfg.hop_length)
    power = stft**2
    mel = banks.mel @ power
    low, high = banks.mel_hz <= cfg.low_band_hz, banks.mel_hz >= cfg.high_band_hz

    def flux(spec: np.ndarray) -> np.ndarray:
        full = np.maximum(0.0, np.diff(spec, axis=1, prepend=spec[:, :1]))
        out = full[:, lead:].copy()
        # A window centred before 0 s already hears a hit at 0 s: keep that onset at frame 0.
        out[:, 0] = full[:, : lead + 1].max(axis=1)
        return out

    # dB flux (80 dB range) hears every note start; the gentler log1p compression keeps loud
    # hits louder than soft ones, which is what separates drum hits from hats and stabs.
    flux_db = flux(power_to_db(mel, top_db=80.0))
    flux_log = flux(np.log1p(cfg.log_compression * mel / max(float(mel.max()), 1e-12)))
    stft, power = stft[:, lead:], power[:, lead:]
    raw = flux_db.mean(axis=0)
    low_onset = flux_db[low].mean(axis=0) if low.any() else np.zeros_like(raw)
    high_onset = flux_log[high].mean(axis=0) if high.any() else np.zeros_like(raw)

    def unit_mean(x: np.ndarray) -> np.ndarray:
        return x / max(float(x.mean()), 1e-9)

    tempo_onset = _local_normalise(raw + cfg.low_band_weight * low_onset, fps, cfg)
    beat_onset = _local_normalise(
        unit_mean(raw) + cfg.high_band_weight * unit_mean(high_onset), fps, cfg
    )
    bands = beat_activation.band_flux(flux_db, flux_log)
    band_rows = np.log1p(np.stack([_local_normalise(row, fps, cfg) for row in bands]))
    if cfg.activation_weight > 0.0:
        model = beat_activation.load_model(cfg.activation_model)
        act = unit_mean(_local_normalise(model.activation(band_rows), fps, cfg))
        tempo_onset = blend(unit_mean(tempo_onset), act, cfg.activation_weight)
        beat_onset = blend(unit_mean(beat_onset), act, cfg.activation_weight)
    learned = np.zeros((len(raw), 0))
    if cfg.beatnet_weight > 0.0:
        learned = _beatnet_frames(unpadded, sr, len(raw), fps, cfg.beatnet_stretches)
        act = unit_mean(learned.sum(axis=1))
        tempo_onset = blend(unit_mean(tempo_onset), act, cfg.beatnet_weight)
        beat_onset = blend(unit_mean(beat_onset), act, cfg.beatnet_weight)
    rms = rms_from_stft(stft, cfg.n_fft)
    chroma = normalize_peak(banks.chroma @ power, axis=0)
    bass = (banks.freqs_hz >= 30.0) & (banks.freqs_hz <= cfg.bass_chroma_max_hz)
    bass_chroma = banks.chroma[:, bass] @ power[bass]
    hit = flux_log.mean(axis=0)
    return _Features(
        tempo_onset, beat_onset, low_onset, raw, rms, hit, chroma, bass_chroma, band_rows, fps,
        learned,
    )  # fmt: skip


Envelope = TypeVar("Envelope", float, np.ndarray)


def blend(envelope: Envelope, activation: Envelope, share: float) -> Envelope:
    """``envelope`` with ``share`` of it replaced by ``activation`` (both on one scale): how
    both trackers mix a learned activation into an onset envelope."""
    return (1.0 - share) * envelope + share * activation


def _beatnet_frames(
    y: np.ndarray, sr: int, n_frames: int, fps: float, stretches: Iterable[float] = (1.0,)
) -> np.ndarray:
    """(n_frames, 2) BeatNet's P(beat), P(downbeat) at the onset frames (frame i at i / fps s),
    interpolated from its own 50 frames/s, averaged over the song heard at each of
    ``stretches`` lengths (`AnalysisConfig.beatnet_stretches`)."""
    from quaddance.music import beatnet

    t_s = np.arange(n_frames) / fps
    runs = []
    for stretch in stretches:
        probs = beatnet.beat_activation(y, sr, stretch)
        if len(probs):
            at_s = np.arange(len(probs)) / (beatnet.FPS * stretch)
            runs.append(np.stack([np.interp(t_s, at_s, probs[:, k]) for k in range(2)], axis=1))
    return np.mean(runs, axis=0) if runs else np.zeros((n_frames, 2))


def activation_rows(y: np.ndarray, sr: int, cfg: AnalysisConfig | None = None) -> np.ndarray:
    """(16, n) the learned beat activation's input rows for mono audio ``y``, one column per
    onset frame (what ``python -m benchmarks.train_beat_activation`` fits on)."""
    cfg = AnalysisConfig(activation_weight=0.0, beatnet_weight=0.0) if cfg is None else cfg
    return _features(np.asarray(y, dtype=np.float32), sr, cfg).band_rows


# --- tempo ------------------------------------------------------------------------------------


def autocorrelation(x: np.ndarray, max_lag: int, demean: bool = True) -> np.ndarray:
    """(max_lag + 1,) unbiased autocorrelation (divided by the overlap length), lag 0 = 1."""
    if demean:
        x = x - x.mean()
    n = len(x)
    spec = np.fft.rfft(x, 2 * n)
    ac = np.fft.irfft(np.abs(spec) ** 2)[: max_lag + 1]
    ac /= np.maximum(n - np.arange(max_lag + 1), 1)
    return ac / max(ac[0], 1e-12)


def harmonic_salience(ac: np.ndarray, lags: np.ndarray, multiples: Iterable[int]) -> np.ndarray:
    """Mean autocorrelation ``ac`` at the ``multiples`` of each lag (frames) within its range
    (1, 2, ... ``tempo_harmonics`` for the tempo's salience).

    A true beat period repeats at all its multiples; a period of 1.5 beats (the usual
    "2/3 tempo" error) lines up with the beats only at every other multiple, so it scores lower.
    """
    idx = np.arange(len(ac))
    total = np.zeros(len(lags))
    count = np.zeros(len(lags))
    for k in multiples:
        ok = k * lags <= idx[-1]
        total[ok] += np.interp(k * lags[ok], idx, ac)
        count[ok] += 1
    return total / np.maximum(count, 1)


def _prior(bpm: np.ndarray | float, cfg: AnalysisConfig) -> np.ndarray:
    """Log-normal tempo prior (peak 1 at ``cfg.prior_center_bpm``)."""
    z = np.log2(np.asarray(bpm) / cfg.prior_center_bpm) / cfg.prior_sigma_octaves
    return np.exp(-0.5 * z * z)


def _global_tempo(onset: np.ndarray, fps: float, cfg: AnalysisConfig) -> float:
    """Main tempo, BPM: the lag whose harmonics carry the most autocorrelation, times the prior."""
    n_harmonics = cfg.tempo_harmonics
    max_lag = min(len(onset) - 1, int(n_harmonics * fps * 60.0 / cfg.min_bpm) + 2)
    ac = autocorrelation(onset, max_lag)
    # Quarter-frame lag steps: at 43 frames/s a whole frame is 4 % of a 120 BPM period.
    lags = np.arange(fps * 60.0 / cfg.max_bpm, min(fps * 60.0 / cfg.min_bpm, max_lag), 0.25)
    if len(lags) == 0:
        return cfg.prior_center_bpm
    bpm = 60.0 * fps / lags
    score = harmonic_salience(ac, lags, range(1, n_harmonics + 1)) * _prior(bpm, cfg)
    return float(bpm[int(np.argmax(score))])


def _local_period(
    onset: np.ndarray, fps: float, tempo_bpm: float, cfg: AnalysisConfig
) -> np.ndarray:
    """(n,) beat period per frame, frames: a smooth tempo path near ``tempo_bpm``.

    Each 0.25 s, the harmonic salience of periods within ``cfg.max_tempo_ratio`` of the global
    period is measured in a ``cfg.tempo_window_s`` window; a Viterbi pass then picks a path
    that changes slowly and stays near the global tempo unless the music clearly moves away.
    """
    n = len(onset)
    period = 60.0 * fps / tempo_bpm
    win = round(cfg.tempo_window_s * fps)
    if n < 2 * win:
        return np.full(n, period)
    # Candidate periods on a log grid of 1 % steps around the global period.
    log_ratio = np.arange(-np.log(cfg.max_tempo_ratio), np.log(cfg.max_tempo_ratio), 0.01)
    periods = period * np.exp(log_ratio)
    hop = max(1, round(fps / 4))
    centers = np.arange(win // 2, n - win + win // 2 + 1, hop)
    max_lag = min(win - 1, int(np.ceil(periods.max() * cfg.tempo_harmonics)) + 2)
    window = np.hanning(win)
    # The window's own autocorrelation falls with lag and would pull the peaks to shorter lags
    # (faster tempi, by about 1 %); dividing by it removes that bias.
    window_ac = autocorrelation(window, max_lag, demean=False)
    emis = np.zeros((len(centers), len(periods)))
    for k, c in enumerate(centers):
        seg = onset[c - win // 2 : c - win // 2 + win]
        ac = autocorrelation((seg - seg.mean()) * window, max_lag) / np.maximum(window_ac, 0.05)
        emis[k] = harmonic_salience(ac, periods, range(1, cfg.tempo_harmonics + 1))
    emis = emis / (np.abs(emis).max(axis=1, keepdims=True) + 1e-9)
    # Staying near the global tempo is preferred: a change has to be clear to be followed.
    emis -= cfg.tempo_deviation_cost * (log_ratio / np.log(2.0)) ** 2
    step = np.arange(len(periods))
    # Tempo drifts by about 2 % per 0.25 s, or jumps (at a fixed cost) where a new part starts.
    drift = -0.5 * ((step[:, None] - step[None, :]) / 2.0) ** 2
    trans = np.maximum(drift, -cfg.tempo_jump_cost)
    score = emis[0].copy()
    back = np.zeros((len(centers), len(periods)), dtype=int)
    for k in range(1, len(centers)):
        cand = score[:, None] + trans
        back[k] = np.argmax(cand, axis=0)
        score = cand[back[k], step] + emis[k]
    path = np.zeros(len(centers), dtype=int)
    path[-1] = int(np.argmax(score))
    for k in range(len(centers) - 1, 0, -1):
        path[k - 1] = back[k, path[k]]
    return np.interp(np.arange(n), centers, periods[path])


# --- beats ------------------------------------------------------------------------------------


def _track_beats(
    onset: np.ndarray, period: np.ndarray, tightness: float, steps_per_frame: int = 1
) -> np.ndarray:
    """Beat frames by dynamic programming (Ellis 2007) with a per-frame beat period.

    Args:
        onset: (n,) onset envelope.
        period: (n,) expected beat period at each frame, frames.
        tightness: weight of the squared log-ratio penalty on an interval outside the range of
            the periods at its two beats.
        steps_per_frame: beats are placed on this many steps per frame, on ``onset`` and
            ``period`` interpolated linearly (`AnalysisConfig.beat_steps_per_frame`).

    Returns:
        (n_beats,) increasing frame indices.
    """
    if steps_per_frame > 1:
        fine = np.arange(len(onset) * steps_per_frame) / steps_per_frame
        frames = np.arange(len(onset))
        steps = _track_beats(
            np.interp(fine, frames, onset), np.interp(fine, frames, period) * steps_per_frame,
            tightness,
        )  # fmt: skip
        # Beats are half a period (6 frames or more) apart: rounding keeps them increasing.
        return np.minimum(np.round(steps / steps_per_frame).astype(int), len(onset) - 1)
    n = len(onset)
    o = onset / (onset.std() + 1e-9)
    score = o.copy()
    back = np.full(n, -1)
    for t in range(n):
        p = period[t]
        lo, hi = int(t - 2.0 * p), int(t - 0.5 * p)
        if hi < 0:
            continue
        lo = max(lo, 0)
        prev = np.arange(lo, hi + 1)
        # An interval is charged only for what lies outside the periods at its two beats:
        # across an abrupt tempo change, charging it against the later period alone makes
        # a stiff DP cheaper on the off-beats.
        short = np.minimum(period[prev], p)
        long = np.maximum(period[prev], p)
        interval = (t - prev).astype(float)
        off = np.log(np.clip(interval, short, long) / interval)
        cand = score[prev] - tightness * off**2
        j = int(np.argmax(cand))
        if cand[j] > 0:
            score[t] = o[t] + cand[j]
            back[t] = prev[j]
    # Start backtracking at the best score in the last period.
    tail = max(0, n - round(float(period[-1])))
    t = tail + int(np.argmax(score[tail:]))
    beats = [t]
    while back[t] >= 0:
        t = int(back[t])
        beats.append(t)
    return np.array(beats[::-1])


SILENT_CHROMA_RATIO = 1e-4
"""`_chroma_change` counts no change where the mean chroma on either side has less than this
fraction of the loudest side's norm (-40 dB of chroma power)."""


def _chroma_change(chroma: np.ndarray, at: np.ndarray, half_width: np.ndarray) -> np.ndarray:
    """(m,) cosine distance between the mean chroma just before and just after each frame
    (0 where either side is silent in the chroma's band, `SILENT_CHROMA_RATIO`).

    Args:
        chroma: (12, n) chroma frames.
        at: (m,) frames (fractional) to measure at.
        half_width: (m,) frames averaged on each side.
    """
    n = chroma.shape[1]
    cum = np.concatenate([np.zeros((12, 1)), np.cumsum(chroma, axis=1)], axis=1)
    mid = np.clip(np.round(at).astype(int), 1, n - 1)
    lo = np.clip(np.round(at - half_width).astype(int), 0, mid - 1)
    hi = np.clip(np.round(at + half_width).astype(int), mid + 1, n)
    before = (cum[:, mid] - cum[:, lo]) / (mid - lo)
    after = (cum[:, hi] - cum[:, mid]) / (hi - mid)
    norm_before, norm_after = np.linalg.norm(before, axis=0), np.linalg.norm(after, axis=0)
    cosine = np.sum(before * after, axis=0) / np.maximum(norm_before * norm_after, 1e-30)
    # A side without sound in the band (the digital silence between clicks) has no pitch to
    # change: the cosine of a near-empty chroma is noise (of an empty one, a change of 1).
    loudest = max(float(norm_before.max(initial=0.0)), float(norm_after.max(initial=0.0)))
    heard = np.minimum(norm_before, norm_after) > SILENT_CHROMA_RATIO * loudest
    return np.where(heard, 1.0 - cosine, 0.0)


def offbeat_harmony(bass_chroma: np.ndarray, beat_frames: np.ndarray, cfg: AnalysisConfig) -> bool:
    """True when the beats sit on the off-beats: the bass line changes pitch at the midpoints
    between them far more often than at them (``cfg.offbeat_harmony_ratio``).

    Bass notes change with the harmony, and harmony changes on the beat (mostly on beat 1);
    drums or keys that hit the off-beats (offbeat hats, skanks, pushes) can pull a tracker
    half a beat off, but they do not move where the chords change. Shared by this analyser
    and the online tracker (`music.online_beats`).

    Args:
        bass_chroma: (12, n) chroma of the bass band (as ``_Features.bass_chroma``).
        beat_frames: (m,) ascending beat frames of ``bass_chroma``, at least two; a change is
            measured at each beat but the last and at each midpoint, over half a beat on
            either side.
    """
    starts = beat_frames[:-1].astype(float)
    half = 0.5 * np.diff(beat_frames)
    on = _chroma_change(bass_chroma, starts, half).mean()
    mid = _chroma_change(bass_chroma, starts + half, half).mean()
    return bool(mid > cfg.offbeat_harmony_ratio * on and mid > 0.05)


def beat_clarity(
    envelope: np.ndarray, fps: float, tempo_range_bpm: tuple[float, float] = DANCE_TEMPO_BPM
) -> float:
    """How clearly ``envelope`` pulses at a tempo in ``tempo_range_bpm``: the highest
    normalised autocorrelation (`autocorrelation`) of its deviation from its mean at a lag of
    one beat in that range ("pulse clarity", Lartillot et al. 2008); 0 for a flat envelope.

    Args:
        envelope: (n,) onset or beat envelope.
        fps: its frame rate, frames per second.
        tempo_range_bpm: (slowest, fastest) beat, beats per minute.

    Returns:
        In [-1, 1]: about 0 for noise, 0.1 for speech, 0.4-0.9 for songs with a beat.
    """
    lo_lag = max(1, int(np.ceil(60.0 * fps / tempo_range_bpm[1])))
    hi_lag = int(60.0 * fps / tempo_range_bpm[0])
    if len(envelope) <= hi_lag:
        return 0.0
    return float(autocorrelation(np.asarray(envelope, dtype=float), hi_lag)[lo_lag:].max())


def dance_level(beats_s: np.ndarray, strength: np.ndarray) -> np.ndarray:
    """``beats_s`` (increasing, seconds) at a level inside `DANCE_TEMPO_BPM`: every other beat
    (the phase whose beats are stronger, ``strength`` at each beat) when their median tempo is
    above it, the midpoints added when below. The range spans more than an octave, so one step
    lands inside for any tempo the analyser tracks (its search, 50-220 BPM, give or take the
    local tempo's 30 %)."""
    lo_bpm, hi_bpm = DANCE_TEMPO_BPM
    if len(beats_s) < 4:
        return beats_s
    bpm = 60.0 / float(np.median(np.diff(beats_s)))
    if bpm > hi_bpm:
        phase = int(np.argmax([strength[0::2].mean(), strength[1::2].mean()]))
        return beats_s[phase::2]
    if bpm < lo_bpm:
        return with_midpoints(beats_s)
    return beats_s


def with_midpoints(beats: np.ndarray) -> np.ndarray:
    """(2 n - 1,) increasing ``beats`` and the midpoints between them: the beat at twice the
    rate (`dance_level`'s doubling)."""
    return np.sort(np.concatenate([beats, 0.5 * (beats[1:] + beats[:-1])]))


def _spaced(times_s: np.ndarray) -> np.ndarray:
    """(n,) mask of the ``times_s`` kept so that each comes at least `MIN_BEAT_GAP_S` after the
    last one kept (the first is kept): strictly increasing, whatever their order."""
    keep = np.zeros(len(times_s), dtype=bool)
    last_s = -np.inf
    for i, t in enumerate(times_s):
        if t >= last_s + MIN_BEAT_GAP_S:
            keep[i], last_s = True, t
    return keep


def _downbeat_phase(beat_frames: np.ndarray, feats: _Features) -> int:
    """Index (0-3) of the first downbeat: the bar phase with most bass onsets and chord changes
    (and, where the analyser runs it, BeatNet's downbeat probability)."""
    if len(beat_frames) < 2 * BEATS_PER_BAR:
        return 0
    idx = np.clip(beat_frames, 0, len(feats.low_onset) - 1)
    low = feats.low_onset[idx]
    low = low / (low.mean() + 1e-9)
    # Chords change on downbeats: distance between the mean chroma of the beats either side.
    bounds = np.append(idx, len(feats.rms))
    chroma = np.stack(
        [feats.chroma[:, a : max(b, a + 1)].mean(axis=1) for a, b in itertools.pairwise(bounds)],
        axis=1,
    )
    chroma = chroma / (np.linalg.norm(chroma, axis=0, keepdims=True) + 1e-9)
    change = np.zeros(len(idx))
    change[1:] = 1.0 - np.sum(chroma[:, 1:] * chroma[:, :-1], axis=0)
    change = change / (change.mean() + 1e-9)
    evidence = low + change
    if feats.beatnet.shape[1] == 2:  # BeatNet's downbeat probability, as one more vote
        down = feats.beatnet[idx, 1]
        evidence = evidence + down / (down.mean() + 1e-9)
    scores = [evidence[p::BEATS_PER_BAR].mean() for p in range(BEATS_PER_BAR)]
    return int(np.argmax(scores))


# --- sections ---------------------------------------------------------------------------------


def _sections(downbeat_frames: np.ndarray, feats: _Features, cfg: AnalysisConfig) -> np.ndarray:
    """Section start frames (the first is 0): downbeats where the music changes character.

    Each bar gets a feature vector in fixed units (loudness, onset density, bass density,
    harmony); a boundary before bar i scores the mean distance between the bars just before
    and just after it minus the mean distance within each side (Foote's checkerboard novelty
    on bar-synchronous features). The strongest boundary above ``cfg.section_threshold`` is
    taken, then the next within the parts it leaves, each part at least
    ``cfg.section_min_bars`` long.
    """
    n_bars = len(downbeat_frames) - 1
    k = cfg.section_kernel_bars
    if n_bars < 2 * cfg.section_min_bars:
        return np.array([0])
    rms_db = 20.0 * np.log10(feats.rms + 1e-5)
    rows = []
    for a, b in itertools.pairwise(downbeat_frames):
        chroma = feats.chroma[:, a:b].mean(axis=1)
        rows.append(
            np.concatenate(
                [
                    # 3 dB louder, or 50 % more onsets, counts as one unit of change.
                    [rms_db[a:b].mean() / 3.0],
                    [np.log(feats.raw_onset[a:b].mean() + 1e-3) / np.log(1.5)],
                    [np.log(feats.low_onset[a:b].mean() + 1e-3) / np.log(1.5)],
                    chroma / (np.linalg.norm(chroma) + 1e-9),
                ]
            )
        )
    f = np.array(rows)
    dist = np.linalg.norm(f[:, None, :] - f[None, :, :], axis=-1)
    m = cfg.section_min_bars
    chosen: list[int] = []
    while True:
        # Blocks stop at boundaries already found, so one big change (say, the end of a quiet
        # intro) does not spill its novelty onto the bars next to it.
        bounds = [0, *sorted(chosen), n_bars]
        best, best_i = -np.inf, -1
        for i in range(m, n_bars - m + 1):
            j = int(np.searchsorted(bounds, i, side="right"))
            lo, hi = bounds[j - 1], bounds[j]
            if i - lo < m or hi - i < m:
                continue
            before, after = slice(max(lo, i - k), i), slice(i, min(hi, i + k))
            within = 0.5 * (dist[before, before].mean() + dist[after, after].mean())
            novelty = dist[before, after].mean() - within
            if novelty > best:
                best, best_i = novelty, i
        if best < cfg.section_threshold:
            break
        chosen.append(best_i)
    starts = [0]
    starts += [int(downbeat_frames[i]) for i in sorted(chosen)]
    return np.array(starts)


# --- entry points -----------------------------------------------------------------------------


def analyze(y: np.ndarray, sr: int, cfg: AnalysisConfig | None = None) -> Analysis:
    """Analyse mono audio.

    Args:
        y: (n,) mono audio samples.
        sr: sample rate, Hz.
        cfg: analyser settings; ``AnalysisConfig()`` if omitted.

    Returns:
        The tempo, beats, downbeats, envelopes (at ``sr / cfg.hop_length`` frames/s) and
        section starts.
    """
    cfg = cfg or AnalysisConfig()
    y = np.asarray(y, dtype=np.float32)
    if y.ndim != 1:
        raise ValueError(f"y must be mono (1-D), got shape {y.shape}")
    y = at_analysis_level(y)
    feats = _features(y, sr, cfg)
    fps = feats.fps
    tempo_bpm = _global_tempo(feats.tempo_onset, fps, cfg)
    global_bpm = tempo_bpm
    period = _local_period(feats.tempo_onset, fps, tempo_bpm, cfg)
    beat_frames = _track_beats(feats.beat_onset, period, cfg.tightness, cfg.beat_steps_per_frame)
    beat_frames = _trim_silence(beat_frames, feats.rms)
    # Fewer than 8 beats are too few to tell where the harmony changes.
    offbeat_shift = len(beat_frames) >= 8 and offbeat_harmony(feats.bass_chroma, beat_frames, cfg)
    if offbeat_shift:
        intervals = np.diff(beat_frames, append=2 * beat_frames[-1] - beat_frames[-2])
        beat_frames = np.round(beat_frames + 0.5 * intervals).astype(int)
        beat_frames = beat_frames[beat_frames < len(feats.beat_onset)]
    beats_s = beat_frames / fps
    keep = _spaced(beats_s)
    beat_frames, beats_s = beat_frames[keep], beats_s[keep]
    strength = np.interp(beats_s * fps, np.arange(len(feats.beat_onset)), feats.beat_onset)
    folded = dance_level(beats_s, strength)
    if len(folded) != len(beats_s):  # halved or doubled into the dance range
        beats_s, beat_frames = folded, np.round(folded * fps).astype(int)
    phase = _downbeat_phase(beat_frames, feats)
    downbeat_frames = beat_frames[phase::BEATS_PER_BAR]
    section_frames = _sections(downbeat_frames, feats, cfg)
    if len(beats_s) > 1:
        tempo_bpm = 60.0 / median_beat_period_s(beats_s)
    return Analysis(
        tempo_bpm=tempo_bpm,
        beats_s=beats_s,
        downbeats_s=beats_s[phase::BEATS_PER_BAR],
        onset_env=feats.raw_onset / max(float(feats.raw_onset.max()), 1e-9),
        rms_env=feats.rms.astype(float),
        env_fps=fps,
        sections_s=section_frames / fps,
        duration_s=len(y) / sr,
        beat_clarity=beat_clarity(feats.beat_onset, fps),
        extra={
            "global_tempo_bpm": global_bpm,
            "offbeat_shift": offbeat_shift,
        },
    )


def at_analysis_level(y: np.ndarray) -> np.ndarray:
    """``y`` scaled to peak `ANALYSIS_PEAK`; silence, and audio already within 1e-4 of that
    level (a 16-bit file of a song `synth` made), as it is."""
    peak = float(np.max(np.abs(y))) if y.size else 0.0
    if peak == 0.0 or abs(peak - ANALYSIS_PEAK) <= 1e-4 * ANALYSIS_PEAK:
        return y
    return y * np.float32(ANALYSIS_PEAK / peak)  # float32 times float32: no second copy


def median_beat_period_s(beats_s: np.ndarray) -> float:
    """The median beat period of increasing ``beats_s`` (two or more), seconds, over spans of
    `TEMPO_SPAN_BEATS` beats: the beats lie on whole envelope frames (23.2 ms), so the median
    of single intervals moves in whole frames (140 BPM reads 136.0 or 143.6), while a span's
    length divided by its beats moves in a quarter of one. A span across a silent break is an
    outlier that the median leaves out."""
    k = min(TEMPO_SPAN_BEATS, len(beats_s) - 1)
    return float(np.median((beats_s[k:] - beats_s[:-k]) / k))


def _trim_silence(beat_frames: np.ndarray, rms: np.ndarray) -> np.ndarray:
    """Drop beats before the music starts and after it ends (RMS below -50 dB of the peak)."""
    import scipy.ndimage

    loud = scipy.ndimage.maximum_filter1d(rms, size=9) > 10 ** (-50 / 20) * rms.max()
    if not loud.any():  # digital silence has no beats
        return beat_frames[:0]
    first, last = np.argmax(loud), len(loud) - 1 - np.argmax(loud[::-1])
    return beat_frames[(beat_frames >= first - 2) & (beat_frames <= last + 2)]


def analyze_file(path: str | Path, cfg: AnalysisConfig | None = None) -> Analysis:
    """Load an audio file (see ``load_audio``) and analyse it; ``source`` is set to its path."""
    from quaddance.music.audio import DEFAULT_SR, load_audio

    y, sr = load_audio(path, sr=DEFAULT_SR)
    result = analyze(y, sr, cfg)
    result.source = str(path)
    return result
