"""Beat-tracking accuracy: our analyser against librosa's default on songs with exact beats.

The songs are General MIDI files written here with ``mido`` (tempi 70-180 BPM, swing,
syncopation, an abrupt and a gradual tempo change, quiet intros) and rendered to audio with
fluidsynth and a General MIDI soundfont; their beats come from the MIDI tempo map, so they are
exact. A few songs from ``music.synth`` are added. None of them is the demo song.

The score is the beat F-measure with a +-70 ms window and one-to-one matching (mir_eval style;
no beats are trimmed from the start).
"""

from __future__ import annotations

import shutil
import subprocess
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from quaddance.errors import QuaddanceError

F_MEASURE_WINDOW_S = 0.07
"""Half-width of the beat hit window, seconds (mir_eval's default)."""

TICKS_PER_BEAT = 480
SOUNDFONT_PATHS = (
    "/usr/share/sounds/sf2/default-GM.sf2",
    "/usr/share/sounds/sf2/FluidR3_GM.sf2",
    "/usr/share/sounds/sf2/TimGM6mb.sf2",
)
INSTALL_HINT = "apt-get install -y fluidsynth fluid-soundfont-gm"


def beat_f_measure(
    reference_s: np.ndarray, estimated_s: np.ndarray, window_s: float = F_MEASURE_WINDOW_S
) -> float:
    """Beat F-measure: 2PR / (P + R) with each estimate matched to at most one reference beat.

    Args:
        reference_s: (n_ref,) true beat times, seconds.
        estimated_s: (n_est,) estimated beat times, seconds.
        window_s: an estimate hits a reference beat when they are at most this far apart.

    Returns:
        F-measure in [0, 1]; 0 when either list is empty.
    """
    ref = np.sort(np.asarray(reference_s, dtype=float))
    est = np.sort(np.asarray(estimated_s, dtype=float))
    if len(ref) == 0 or len(est) == 0:
        return 0.0
    # All windows have the same width, so the graph of possible pairs is an interval graph and
    # matching each reference beat, in time order, to the earliest free estimate in its window
    # gives a maximum one-to-one matching (the same count as mir_eval's bipartite matching).
    hits = 0
    j = 0
    for r in ref:
        while j < len(est) and est[j] < r - window_s - 1e-12:
            j += 1
        if j < len(est) and est[j] <= r + window_s + 1e-12:
            hits += 1
            j += 1
    if hits == 0:
        return 0.0
    precision = hits / len(est)
    recall = hits / len(ref)
    return 2.0 * precision * recall / (precision + recall)


# --- the MIDI songs ---------------------------------------------------------------------------

# Drum patterns as General MIDI drum notes -> onsets in sixteenths of a 4/4 bar (0..15).
KICK, SNARE, CLOSED_HAT, OPEN_HAT, CRASH, RIDE, CLAP = 36, 38, 42, 46, 49, 51, 39
CLAVES, HIGH_CONGA, LOW_CONGA = 75, 63, 64
DRUM_PATTERNS: dict[str, dict[int, list[int]]] = {
    "ballad": {KICK: [0, 10], SNARE: [4, 12], CLOSED_HAT: [0, 2, 4, 6, 8, 10, 12, 14]},
    "shuffle": {KICK: [0, 8], SNARE: [4, 12], RIDE: [0, 2, 4, 6, 8, 10, 12, 14]},
    "hiphop": {KICK: [0, 6, 10], SNARE: [4, 12], CLOSED_HAT: [0, 2, 4, 6, 8, 10, 12, 14]},
    "dembow": {KICK: [0, 4, 8, 12], SNARE: [3, 6, 11, 14], CLOSED_HAT: [0, 4, 8, 12]},
    "rock": {KICK: [0, 8, 10], SNARE: [4, 12], CLOSED_HAT: [0, 2, 4, 6, 8, 10, 12, 14]},
    "house": {KICK: [0, 4, 8, 12], CLAP: [4, 12], OPEN_HAT: [2, 6, 10, 14]},
    "skank": {KICK: [0, 8], SNARE: [4, 12], CLOSED_HAT: [0, 2, 4, 6, 8, 10, 12, 14]},
    "funk": {KICK: [0, 3, 10], SNARE: [4, 7, 12], CLOSED_HAT: list(range(16))},
    "disco": {KICK: [0, 4, 8, 12], SNARE: [4, 12], OPEN_HAT: [2, 6, 10, 14]},
    "dnb": {KICK: [0, 10], SNARE: [4, 12], CLOSED_HAT: [0, 2, 4, 6, 8, 10, 12, 14]},
    "punk": {KICK: [0, 8], SNARE: [4, 12], CRASH: [0, 4, 8, 12]},
    "latin": {CLAVES: [0, 6, 12], HIGH_CONGA: [2, 6, 10, 14], LOW_CONGA: [4, 12], KICK: [6]},
    "none": {},
}
# Chord and bass rhythms, in sixteenths; the offbeat and syncopated ones are the hard cases.
CHORD_RHYTHMS: dict[str, list[int]] = {
    "sustain": [0],
    "quarters": [0, 4, 8, 12],
    "offbeats": [2, 6, 10, 14],
    "syncopated": [0, 6, 12],
    "eighths": [0, 2, 4, 6, 8, 10, 12, 14],
    "arpeggio": list(range(16)),
}
BASS_RHYTHMS: dict[str, list[int]] = {
    "half": [0, 8],
    "quarters": [0, 4, 8, 12],
    "eighths": [0, 2, 4, 6, 8, 10, 12, 14],
    "offbeats": [2, 6, 10, 14],
    "syncopated": [0, 3, 6, 10],
}
_PROGRESSION = ((57, 45), (53, 41), (48, 48), (55, 43))  # Am F C G: chord root, bass note
_MINOR_PENTATONIC = (0, 3, 5, 7, 10)


@dataclass(frozen=True)
class MidiSongSpec:
    """One benchmark song written as General MIDI.

    ``tempo_change`` = (bar, bpm) switches tempo abruptly at that bar; ``tempo_ramp`` =
    (first_bar, last_bar, bpm) changes it beat by beat to reach ``bpm`` at ``last_bar``.
    ``swing`` delays off-beat eighths (1 = triplet swing). Programs are General MIDI numbers.
    """

    name: str
    tempo_bpm: float
    style: str
    chords: str
    bass: str
    chord_program: int
    bass_program: int
    seed: int
    swing: float = 0.0
    intro_bars: int = 0
    tempo_change: tuple[int, float] | None = None
    tempo_ramp: tuple[int, int, float] | None = None
    duration_s: float = 24.0


BENCH_SONGS: tuple[MidiSongSpec, ...] = (
    MidiSongSpec("ballad_70_intro", 70, "ballad", "quarters", "half", 0, 32, 1, intro_bars=1),
    MidiSongSpec("shuffle_76_swing", 76, "shuffle", "syncopated", "half", 26, 33, 2, swing=1.0),
    MidiSongSpec("hiphop_90_swing", 90, "hiphop", "sustain", "syncopated", 4, 38, 3, swing=0.6),
    MidiSongSpec("dembow_96_sync", 96, "dembow", "syncopated", "half", 81, 38, 4),
    MidiSongSpec(
        "pop_100_to_128", 100, "rock", "quarters", "eighths", 0, 33, 5, tempo_change=(6, 128.0)
    ),
    MidiSongSpec(
        "rock_110_ramp_130",
        110,
        "rock",
        "eighths",
        "eighths",
        29,
        34,
        6,
        tempo_ramp=(3, 9, 130.0),
    ),
    MidiSongSpec("house_124_intro", 124, "house", "offbeats", "offbeats", 17, 38, 7, intro_bars=2),
    MidiSongSpec("skank_132_sync", 132, "skank", "offbeats", "syncopated", 27, 33, 8),
    MidiSongSpec("funk_104_sync", 104, "funk", "syncopated", "syncopated", 7, 36, 9),
    MidiSongSpec("disco_118_intro", 118, "disco", "sustain", "eighths", 48, 38, 10, intro_bars=2),
    MidiSongSpec("dnb_174", 174, "dnb", "sustain", "syncopated", 89, 38, 11),
    MidiSongSpec("punk_180", 180, "punk", "eighths", "eighths", 30, 34, 12),
    MidiSongSpec("piano_72_arpeggio", 72, "none", "arpeggio", "half", 0, 32, 13),
    MidiSongSpec("pizzicato_150", 150, "none", "eighths", "quarters", 45, 43, 14),
    MidiSongSpec("latin_160_clave", 160, "latin", "syncopated", "syncopated", 0, 32, 15),
)


def _tempo_map(spec: MidiSongSpec, n_beats: int) -> list[tuple[int, float]]:
    """[(tick, bpm), ...]: the tempo in force from each tick on."""
    changes = [(0, float(spec.tempo_bpm))]
    if spec.tempo_change is not None:
        bar, bpm = spec.tempo_change
        changes.append((bar * 4 * TICKS_PER_BEAT, float(bpm)))
    if spec.tempo_ramp is not None:
        first, last, bpm = spec.tempo_ramp
        beats = np.arange(first * 4, last * 4 + 1)
        for k, beat in enumerate(beats):
            frac = k / (len(beats) - 1)
            changes.append(
                (int(beat) * TICKS_PER_BEAT, spec.tempo_bpm + frac * (bpm - spec.tempo_bpm))
            )
    return [c for c in changes if c[0] <= n_beats * TICKS_PER_BEAT]


def _tick_times_s(ticks: np.ndarray, tempo_map: list[tuple[int, float]]) -> np.ndarray:
    """Seconds at each tick under a piecewise-constant tempo map."""
    starts = np.array([t for t, _ in tempo_map], dtype=float)
    s_per_tick = np.array([60.0 / bpm / TICKS_PER_BEAT for _, bpm in tempo_map])
    seg_s = np.concatenate([[0.0], np.cumsum(np.diff(starts) * s_per_tick[:-1])])
    idx = np.searchsorted(starts, ticks, side="right") - 1
    return seg_s[idx] + (ticks - starts[idx]) * s_per_tick[idx]


def _n_bars(spec: MidiSongSpec) -> int:
    """Whole bars that fit in ``spec.duration_s`` (at the song's varying tempo)."""
    for bars in range(1, 200):
        tmap = _tempo_map(spec, (bars + 1) * 4)
        if _tick_times_s(np.array([(bars + 1) * 4 * TICKS_PER_BEAT]), tmap)[0] > spec.duration_s:
            return bars
    return 200


def write_midi(spec: MidiSongSpec, path: Path) -> np.ndarray:
    """Write ``spec`` as a type-1 MIDI file; return its (n_beats,) beat times, seconds."""
    try:
        import mido
    except ImportError as err:
        raise QuaddanceError("the beat benchmark needs mido: pip install mido") from err
    rng = np.random.default_rng(spec.seed)
    n_bars = _n_bars(spec)
    n_beats = n_bars * 4
    tmap = _tempo_map(spec, n_beats)
    sixteenth = TICKS_PER_BEAT // 4
    events: list[tuple[int, int, Any]] = []  # (tick, order, message); note-offs sort first

    def tick_of(bar: int, pos16: int) -> int:
        tick = (bar * 16 + pos16) * sixteenth
        if pos16 % 4 == 2:  # off-beat eighth: swing delays it towards the last triplet
            tick += round(spec.swing / 6.0 * TICKS_PER_BEAT)
        return tick

    def note(channel: int, pitch: int, velocity: int, start: int, length: int) -> None:
        velocity = int(np.clip(velocity + rng.integers(-6, 7), 1, 127))
        if channel != 9:  # players are not quantised: a few ms of timing spread (not drums)
            start = max(0, start + int(rng.integers(-4, 5)))
        events.append(
            (start, 1, mido.Message("note_on", channel=channel, note=pitch, velocity=velocity))
        )
        events.append((start + length, 0, mido.Message("note_off", channel=channel, note=pitch)))

    drums = DRUM_PATTERNS[spec.style]
    for bar in range(n_bars):
        chord_root, bass_note = _PROGRESSION[bar % len(_PROGRESSION)]
        triad = (chord_root, chord_root + 3 if bar % 4 == 0 else chord_root + 4, chord_root + 7)
        intro = bar < spec.intro_bars
        chord_rhythm = CHORD_RHYTHMS["quarters" if intro else spec.chords]
        for i, pos in enumerate(chord_rhythm):
            nxt = chord_rhythm[i + 1] if i + 1 < len(chord_rhythm) else 16
            length = tick_of(bar, nxt) - tick_of(bar, pos) - sixteenth // 2
            # An arpeggio plays the chord one note at a time; the other rhythms strum it.
            pitches = [triad[i % 3] + 12 * (i // 3 % 2)] if spec.chords == "arpeggio" else triad
            for pitch in pitches:
                note(1, pitch, 40 if intro else 72, tick_of(bar, pos), length)
        if intro:  # a quiet intro: soft chords only, drums and bass come in later
            continue
        for drum, positions in drums.items():
            for pos in positions:
                accent = 100 if pos % 4 == 0 else 80
                note(
                    9,
                    drum,
                    accent if drum != CLOSED_HAT else accent - 30,
                    tick_of(bar, pos),
                    sixteenth,
                )
        bass_rhythm = BASS_RHYTHMS[spec.bass]
        for i, pos in enumerate(bass_rhythm):
            nxt = bass_rhythm[i + 1] if i + 1 < len(bass_rhythm) else 16
            length = tick_of(bar, nxt) - tick_of(bar, pos) - sixteenth // 2
            note(2, bass_note, 95, tick_of(bar, pos), length)
        # A sparse melody on eighths: it adds onsets that are not on the beat.
        for pos in range(0, 16, 2):
            if rng.random() < 0.45:
                pitch = 69 + _MINOR_PENTATONIC[rng.integers(0, 5)] + 12 * int(rng.integers(0, 2))
                note(3, pitch, 70, tick_of(bar, pos), 2 * sixteenth - 20)

    meta = mido.MidiTrack()
    meta.append(mido.MetaMessage("time_signature", numerator=4, denominator=4, time=0))
    last = 0
    for tick, bpm in tmap:
        meta.append(mido.MetaMessage("set_tempo", tempo=mido.bpm2tempo(bpm), time=tick - last))
        last = tick
    music = mido.MidiTrack()
    for channel, program in ((1, spec.chord_program), (2, spec.bass_program), (3, 73)):
        music.append(mido.Message("program_change", channel=channel, program=program, time=0))
    last = 0
    for tick, _, msg in sorted(events, key=lambda e: (e[0], e[1])):
        music.append(msg.copy(time=tick - last))
        last = tick
    # End the song on the bar line, so that the last beat lasts a whole beat.
    end_tick = max(last, n_beats * TICKS_PER_BEAT)
    music.append(mido.MetaMessage("end_of_track", time=end_tick - last))
    midi = mido.MidiFile(type=1, ticks_per_beat=TICKS_PER_BEAT)
    midi.tracks.extend([meta, music])
    midi.save(str(path))
    return _tick_times_s(np.arange(n_beats) * TICKS_PER_BEAT, tmap)


def find_soundfont() -> Path:
    """The General MIDI soundfont to render with, or a clear error naming the apt package."""
    for candidate in SOUNDFONT_PATHS:
        if Path(candidate).is_file():
            return Path(candidate)
    raise QuaddanceError(f"no General MIDI soundfont found; install one: {INSTALL_HINT}")


def render_midi(midi_path: Path, wav_path: Path, soundfont: Path, sr: int = 22050) -> None:
    """Render a MIDI file to a wav file with fluidsynth (offline, faster than real time)."""
    if shutil.which("fluidsynth") is None:
        raise QuaddanceError(f"the beat benchmark needs fluidsynth: {INSTALL_HINT}")
    cmd = ["fluidsynth", "-ni", "-q", "-r", str(sr), "-F", str(wav_path), str(soundfont)]
    result = subprocess.run([*cmd, str(midi_path)], capture_output=True, text=True, check=False)
    if result.returncode != 0 or not wav_path.is_file():
        raise QuaddanceError(f"fluidsynth failed on {midi_path}: {result.stderr.strip()[:300]}")


# --- the benchmark ----------------------------------------------------------------------------

SYNTH_SONGS: tuple[dict[str, Any], ...] = (
    {"name": "synth_84_swing", "tempo_bpm": 84.0, "seed": 21, "swing": 0.8},
    {"name": "synth_128_sync", "tempo_bpm": 128.0, "seed": 22, "syncopation": True},
    {"name": "synth_100_intro", "tempo_bpm": 100.0, "seed": 23, "intro_s": 5.0},
    {"name": "synth_95_to_120", "tempo_bpm": 95.0, "seed": 24, "tempo_change": (12.0, 120.0)},
)


def random_midi_songs(n: int, seed: int = 99) -> list[MidiSongSpec]:
    """``n`` songs with random style, tempo (70-180 BPM), rhythms, swing, intro and tempo
    change: a check that the analyser was not tuned to the designed songs above."""
    rng = np.random.default_rng(seed)
    styles, chords, basses = list(DRUM_PATTERNS), list(CHORD_RHYTHMS), list(BASS_RHYTHMS)
    songs = []
    for i in range(n):
        style = styles[rng.integers(len(styles))]
        change = (int(rng.integers(3, 6)), float(rng.integers(80, 150)))
        songs.append(
            MidiSongSpec(
                name=f"random{i:02d}_{style}",
                tempo_bpm=float(rng.integers(70, 181)),
                style=style,
                chords=chords[rng.integers(len(chords))],
                bass=basses[rng.integers(len(basses))],
                chord_program=int(rng.integers(0, 100)),
                bass_program=int(rng.integers(32, 40)),
                seed=1000 + i,
                swing=float(rng.choice([0.0, 0.0, 0.6, 1.0])),
                intro_bars=int(rng.choice([0, 0, 1, 2])),
                tempo_change=change if rng.random() < 0.2 else None,
            )
        )
    return songs


def _librosa_default_beats_s(y: np.ndarray, sr: int) -> tuple[float, np.ndarray]:
    import librosa

    tempo, frames = librosa.beat.beat_track(y=y, sr=sr)
    return float(np.atleast_1d(tempo)[0]), librosa.frames_to_time(frames, sr=sr)


def run_beat_bench(
    out_path: str | Path,
    sr: int = 22050,
    n_random: int = 12,
    progress: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Score our beat tracker and librosa's default on every benchmark song; write JSON.

    Args:
        out_path: where the JSON results go (written atomically).
        sr: analysis sample rate, Hz.
        n_random: how many random MIDI songs (``random_midi_songs``) to add; reported apart.
        progress: called with each song's name before it is scored.

    Returns:
        The results written: per-song F-measures and tempi, and the means.
    """
    from quaddance.fileio import write_json
    from quaddance.music.analysis import analyze
    from quaddance.music.audio import load_audio
    from quaddance.music.synth import render_song

    if shutil.which("fluidsynth") is None:
        raise QuaddanceError(f"the beat benchmark needs fluidsynth: {INSTALL_HINT}")
    soundfont = find_soundfont()
    rows: list[dict[str, Any]] = []
    analysis_s = 0.0
    baseline_s = 0.0

    def score(name: str, source: str, y: np.ndarray, beats_s: np.ndarray, tempo: float) -> None:
        nonlocal analysis_s, baseline_s
        t0 = time.perf_counter()
        ours = analyze(y, sr)
        t1 = time.perf_counter()
        lib_tempo, lib_beats_s = _librosa_default_beats_s(y, sr)
        analysis_s += t1 - t0
        baseline_s += time.perf_counter() - t1
        rows.append(
            {
                "name": name,
                "source": source,
                "true_tempo_bpm": tempo,
                "duration_s": round(len(y) / sr, 3),
                "n_beats": len(beats_s),
                "f_quaddance": round(beat_f_measure(beats_s, ours.beats_s), 4),
                "f_librosa_default": round(beat_f_measure(beats_s, lib_beats_s), 4),
                "tempo_quaddance_bpm": round(ours.tempo_bpm, 2),
                "tempo_librosa_default_bpm": round(lib_tempo, 2),
            }
        )

    with tempfile.TemporaryDirectory(prefix="quaddance-beats-") as tmp:
        specs = [(spec, "midi+fluidsynth") for spec in BENCH_SONGS]
        specs += [(spec, "midi-random") for spec in random_midi_songs(n_random)]
        for spec, source in specs:
            if progress is not None:
                progress(spec.name)
            midi_path = Path(tmp) / f"{spec.name}.mid"
            wav_path = Path(tmp) / f"{spec.name}.wav"
            beats_s = write_midi(spec, midi_path)
            render_midi(midi_path, wav_path, soundfont, sr)
            y, _ = load_audio(wav_path, sr=sr)
            # Cut the reverb tail after the last bar so that every second has true beats.
            end_s = beats_s[-1] + (beats_s[-1] - beats_s[-2])
            y = y[: round(end_s * sr)]
            score(spec.name, source, y, beats_s, spec.tempo_bpm)
    for song in SYNTH_SONGS:
        if progress is not None:
            progress(song["name"])
        kwargs = {k: v for k, v in song.items() if k != "name"}
        y, truth = render_song(duration_s=24.0, sr=sr, **kwargs)
        score(song["name"], "music.synth", y, truth.beats_s, truth.tempo_bpm)

    def mean(key: str, *sources: str) -> float | None:
        vals = [r[key] for r in rows if r["source"] in sources]
        return round(float(np.mean(vals)), 4) if vals else None

    results = {
        "benchmark": "beats",
        "metric": f"beat F-measure, +-{F_MEASURE_WINDOW_S * 1000:.0f} ms, one-to-one, no trim",
        "soundfont": str(soundfont),
        "sr_hz": sr,
        # The designed set (MIDI + music.synth) is the one the analyser was tuned on; the
        # random set was not looked at while tuning.
        "mean_f_quaddance": mean("f_quaddance", "midi+fluidsynth", "music.synth"),
        "mean_f_librosa_default": mean("f_librosa_default", "midi+fluidsynth", "music.synth"),
        "mean_f_quaddance_midi": mean("f_quaddance", "midi+fluidsynth"),
        "mean_f_librosa_default_midi": mean("f_librosa_default", "midi+fluidsynth"),
        "mean_f_quaddance_random": mean("f_quaddance", "midi-random"),
        "mean_f_librosa_default_random": mean("f_librosa_default", "midi-random"),
        "analysis_s_total": round(analysis_s, 2),
        "librosa_default_s_total": round(baseline_s, 2),
        "songs": rows,
    }
    write_json(out_path, results)
    return results
