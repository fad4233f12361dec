"""Beat-tracking accuracy: our analyser against librosa's default (and, optionally, madmom's
DBN tracker) on songs with exact beats.

The songs are General MIDI files written here with ``mido`` and rendered to audio with
fluidsynth and a General MIDI soundfont; their beats come from the MIDI tempo map, so they are
exact. Three sets (``SETS``), reported apart: ``tuning`` (the designed songs, 56-180 BPM, plus
a few from ``music.synth``; the analyser was tuned on them), ``random`` (random styles and
tempi) and ``untuned`` (``UNTUNED_SONGS``: fast and slow notations, tempo changes, drums or
keys off the beat, 140-160 BPM rock; fixed before any tuning and never tuned on). None of them
is the demo song.

Two scores, both with a +-70 ms window and one-to-one matching (mir_eval style; no beats are
trimmed from the start): the strict beat F-measure, and the F-measure at the tracker's own
metrical level (``metrical_level_f_measure``: half or double tempo is not counted as an error,
beats on the off-beats are).
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
MIN_NOTE_TICKS = TICKS_PER_BEAT // 16
"""Length given to a note whose computed length is not positive, ticks (a 64th note)."""
RENDER_TIMEOUT_S = 300.0
"""fluidsynth renders a benchmark song (under a minute of music) in a few seconds; one that
takes this long never ends."""


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
# The untuned set's extra patterns: drums that do not mark the beat (offbeat hats only, reggae
# one-drop, clave, bossa), half-time and fast feels, and pushed (anticipated) keys and bass.
# Kept apart from the dicts above so that ``random_midi_songs`` draws exactly what it always did.
PEDAL_HAT, SIDE_STICK, COWBELL, SHAKER = 44, 37, 56, 70
UNTUNED_DRUM_PATTERNS: dict[str, dict[int, list[int]]] = {
    "two_step": {KICK: [0, 8], SNARE: [4, 12], RIDE: [0, 4, 8, 12]},
    "dnb_offhats": {KICK: [0, 10], SNARE: [4, 12], CLOSED_HAT: [2, 6, 10, 14]},
    "jazz_ride": {RIDE: [0, 4, 6, 8, 12, 14], PEDAL_HAT: [4, 12]},
    "ska": {KICK: [0, 8], SNARE: [4, 12], CLOSED_HAT: [2, 6, 10, 14]},
    "halftime": {KICK: [0, 3], SNARE: [8], CLOSED_HAT: list(range(16))},
    "trap": {KICK: [0, 7, 10], SNARE: [8], CLOSED_HAT: list(range(16))},
    "one_drop": {KICK: [8], SIDE_STICK: [8], CLOSED_HAT: [2, 6, 10, 14]},
    "offbeat_hats": {OPEN_HAT: [2, 6, 10, 14]},
    "clave": {CLAVES: [0, 3, 6, 10, 12]},
    "bossa": {KICK: [0, 3, 4, 7, 8, 11, 12, 15], SIDE_STICK: [0, 3, 6, 10, 13], SHAKER: [2, 6]},
    "backbeat": {KICK: [0, 6, 8], SNARE: [4, 12], CLOSED_HAT: [0, 2, 4, 6, 8, 10, 12, 14]},
    "cowbell_sync": {COWBELL: [3, 6, 11, 14], KICK: [6, 14]},
}
UNTUNED_CHORD_RHYTHMS: dict[str, list[int]] = {
    "charleston": [0, 6],
    "pushes": [3, 7, 11, 14],
    "anticipated": [0, 6, 14],
}
UNTUNED_BASS_RHYTHMS: dict[str, list[int]] = {
    "tresillo": [0, 6, 12],
    "reggae": [2, 3, 8, 10],
    "pushed": [6, 14],
}
_ALL_DRUMS = {**DRUM_PATTERNS, **UNTUNED_DRUM_PATTERNS}
_ALL_CHORDS = {**CHORD_RHYTHMS, **UNTUNED_CHORD_RHYTHMS}
_ALL_BASS = {**BASS_RHYTHMS, **UNTUNED_BASS_RHYTHMS}
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


# Songs added to the tuning set for the tempo-octave and beat-phase checks of the analyser
# (backbeat rock heard at half tempo, keys that skank on the off-beats), with fast and slow
# notations and a large tempo change; their before/after figures are part of the tuning set's.
EXTRA_TUNING_SONGS: tuple[MidiSongSpec, ...] = (
    MidiSongSpec("tune_rock_152", 152, "rock", "eighths", "eighths", 29, 34, 31),
    MidiSongSpec("tune_disco_146", 146, "disco", "quarters", "quarters", 30, 33, 32),
    MidiSongSpec("tune_punk_156", 156, "punk", "sustain", "eighths", 27, 34, 33),
    MidiSongSpec("tune_skank_100_nodrums", 100, "none", "offbeats", "syncopated", 16, 33, 34),
    MidiSongSpec("tune_latin_108", 108, "latin", "syncopated", "syncopated", 0, 32, 35),
    MidiSongSpec("tune_dnb_176", 176, "dnb", "sustain", "syncopated", 89, 38, 36),
    MidiSongSpec("tune_ballad_56", 56, "ballad", "arpeggio", "half", 0, 32, 37, duration_s=32.0),
    MidiSongSpec(
        "tune_pop_96_to_150", 96, "rock", "quarters", "eighths", 0, 33, 38, tempo_change=(4, 150.0)
    ),
    MidiSongSpec("tune_hiphop_64", 64, "hiphop", "sustain", "syncopated", 4, 38, 39),
    MidiSongSpec("tune_house_120", 120, "house", "offbeats", "offbeats", 17, 38, 40),
)


# The untuned set, fixed (names, tempi, styles, seeds) on 2026-12-01 before any tuning of the
# analyser against it; never tune on it. Kinds: fast notations (170-200 BPM), slow notations
# (40-70 BPM, often with sixteenth-note hats), tempo changes, drums or keys that do not mark the
# beat, and 140-160 BPM rock with a strong backbeat (the tempo-octave trap).
def song_spec(
    name: str,
    bpm: float,
    style: str,
    chords: str,
    bass: str,
    programs: tuple[int, int],
    seed: int,
    **kw: Any,
) -> MidiSongSpec:
    """A `MidiSongSpec` written on one line: ``programs`` = (chord program, bass program)."""
    return MidiSongSpec(name, bpm, style, chords, bass, programs[0], programs[1], seed, **kw)


UNTUNED_SONGS: tuple[MidiSongSpec, ...] = (
    # fast notations
    song_spec("fast_twostep_184", 184, "two_step", "offbeats", "half", (21, 32), 2001),
    song_spec("fast_dnb_172_offhats", 172, "dnb_offhats", "sustain", "tresillo", (89, 38), 2002),
    song_spec(
        "fast_jazz_200_swing", 200, "jazz_ride", "charleston", "quarters", (0, 32), 2003, swing=1.0
    ),
    song_spec("fast_ska_178", 178, "ska", "offbeats", "quarters", (16, 33), 2004),
    song_spec("fast_keys_188", 188, "none", "pushes", "quarters", (4, 35), 2005),
    # slow notations
    song_spec("slow_halftime_60", 60, "halftime", "sustain", "pushed", (89, 38), 2011),
    song_spec("slow_trap_68", 68, "trap", "sustain", "tresillo", (81, 38), 2012),
    song_spec("slow_ballad_48", 48, "ballad", "arpeggio", "half", (0, 32), 2013, duration_s=32.0),
    song_spec("slow_onedrop_66", 66, "one_drop", "offbeats", "reggae", (16, 33), 2014),
    song_spec("slow_keys_54", 54, "none", "anticipated", "half", (4, 32), 2015, duration_s=32.0),
    song_spec(
        "slow_soul_42",
        42,
        "halftime",
        "eighths",
        "syncopated",
        (48, 33),
        2016,
        swing=0.6,
        duration_s=32.0,
    ),
    # tempo changes
    song_spec(
        "change_rock_90_to_150",
        90,
        "rock",
        "quarters",
        "eighths",
        (29, 34),
        2021,
        tempo_change=(5, 150.0),
    ),
    song_spec(
        "change_house_126_ramp_100",
        126,
        "house",
        "offbeats",
        "offbeats",
        (17, 38),
        2022,
        tempo_ramp=(3, 8, 100.0),
    ),
    song_spec(
        "change_bossa_80_to_64",
        80,
        "bossa",
        "charleston",
        "half",
        (24, 32),
        2023,
        tempo_change=(4, 64.0),
    ),
    song_spec(
        "change_funk_140_ramp_172",
        140,
        "funk",
        "syncopated",
        "syncopated",
        (7, 36),
        2024,
        tempo_ramp=(2, 9, 172.0),
    ),
    # drums or keys that do not mark the beat
    song_spec("offbeat_hats_112", 112, "offbeat_hats", "syncopated", "syncopated", (4, 33), 2031),
    song_spec("keys_sync_96", 96, "none", "pushes", "syncopated", (0, 32), 2032),
    song_spec("clave_120", 120, "clave", "pushes", "tresillo", (11, 35), 2033),
    song_spec("bossa_136", 136, "bossa", "charleston", "half", (24, 32), 2034),
    song_spec("cowbell_sync_104", 104, "cowbell_sync", "anticipated", "pushed", (5, 38), 2035),
    # 140-160 BPM rock with a strong backbeat
    song_spec("rock_150_backbeat", 150, "backbeat", "eighths", "eighths", (30, 34), 2041),
    song_spec("rock_144_backbeat", 144, "rock", "quarters", "eighths", (29, 33), 2042),
    song_spec("rock_158_backbeat", 158, "backbeat", "sustain", "quarters", (27, 34), 2043),
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
        # A strongly swung off-beat lands less than half a sixteenth before the next note, so
        # the "up to the next note" length can come out negative: its note-off would precede
        # its note-on, leave the note hanging, and fluidsynth then renders without end. Only
        # those notes change, so every song that rendered before renders the same.
        if length < 1:
            length = MIN_NOTE_TICKS
        velocity = int(np.clip(velocity + rng.integers(-6, 7), 1, 127))
        if channel != 9:  # players are not quantised: a few ms of timing spread (not drums)
            start = max(0, start + int(rng.integers(-4, 5)))
        events.append(
            (start, 1, mido.Message("note_on", channel=channel, note=pitch, velocity=velocity))
        )
        events.append((start + length, 0, mido.Message("note_off", channel=channel, note=pitch)))

    drums = _ALL_DRUMS[spec.style]
    for bar in range(n_bars):
        chord_root, bass_note = _PROGRESSION[bar % len(_PROGRESSION)]
        triad = (chord_root, chord_root + 3 if bar % 4 == 0 else chord_root + 4, chord_root + 7)
        intro = bar < spec.intro_bars
        chord_rhythm = _ALL_CHORDS["quarters" if intro else spec.chords]
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
        bass_rhythm = _ALL_BASS[spec.bass]
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
    try:
        result = subprocess.run(
            [*cmd, str(midi_path)],
            capture_output=True,
            text=True,
            check=False,
            timeout=RENDER_TIMEOUT_S,
        )
    except subprocess.TimeoutExpired as err:
        wav_path.unlink(missing_ok=True)  # an endless render's partial file grows without bound
        raise QuaddanceError(
            f"fluidsynth did not finish {midi_path} in {RENDER_TIMEOUT_S:.0f} s "
            "(a note that never ends?)"
        ) from err
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


# madmom (Boeck et al. 2016), run in another interpreter: madmom 0.16 needs numpy < 1.24, so it
# cannot live in our environment (scripts/install_madmom.sh builds one). argv[1] lists wav
# paths, argv[2] the trackers; stdout gets {path: {tracker: [times, s]}}. "dbn": the offline
# RNN + DBN beat tracker; "online": the forward RNNs with the DBN in online mode (each beat
# decided when its frame arrives); "downbeats": the RNN + DBN downbeat tracker, 3/4 or 4/4.
_MADMOM_SCRIPT = """
import json, sys, warnings
warnings.simplefilter("ignore")
from madmom.features.beats import DBNBeatTrackingProcessor, RNNBeatProcessor
from madmom.features.downbeats import DBNDownBeatTrackingProcessor, RNNDownBeatProcessor
paths, trackers = json.loads(sys.argv[1]), json.loads(sys.argv[2])
out = {}
for p in paths:
    row = {}
    if "dbn" in trackers:
        row["dbn"] = DBNBeatTrackingProcessor(fps=100)(RNNBeatProcessor()(p)).tolist()
    if "online" in trackers:
        act = RNNBeatProcessor(online=True)(p)
        row["online"] = DBNBeatTrackingProcessor(fps=100, online=True)(act).tolist()
    if "downbeats" in trackers:
        act = RNNDownBeatProcessor()(p)
        beats = DBNDownBeatTrackingProcessor(beats_per_bar=[3, 4], fps=100)(act)
        row["downbeats"] = [float(t) for t, k in beats if int(k) == 1]
    out[p] = row
    print(p, file=sys.stderr, flush=True)
print(json.dumps(out))
"""

MADMOM_TRACKERS = ("dbn", "online", "downbeats")
"""What `madmom_tracks` can run: offline beats, online beats, offline downbeats."""

MADMOM_SR = 44100
"""Sample rate of the audio given to madmom, Hz (its models' rate)."""

MADMOM_VENV = Path(__file__).resolve().parents[1] / ".madmom" / "venv"
"""Where scripts/install_madmom.sh puts madmom's own environment (in the checkout)."""


def default_madmom_python() -> Path | None:
    """The interpreter of scripts/install_madmom.sh's environment, if it was built; else None."""
    python = MADMOM_VENV / "bin" / "python"
    return python if python.is_file() else None


def madmom_tracks(
    python: str | Path, wav_paths: list[Path], trackers: tuple[str, ...] = ("dbn",)
) -> dict[str, dict[str, np.ndarray]]:
    """Run madmom's ``trackers`` (of `MADMOM_TRACKERS`) by ``python`` on each wav file.

    Returns:
        {wav path as str: {tracker: (n,) times, s}}.
    """
    import json

    unknown = sorted(set(trackers) - set(MADMOM_TRACKERS))
    if unknown:
        raise QuaddanceError(f"unknown madmom tracker(s) {unknown}; known: {MADMOM_TRACKERS}")
    cmd = [str(python), "-c", _MADMOM_SCRIPT, json.dumps([str(p) for p in wav_paths]),
           json.dumps(list(trackers))]  # fmt: skip
    try:
        result = subprocess.run(cmd, capture_output=True, text=True, check=False)
    except OSError as e:
        raise QuaddanceError(f"cannot run madmom's interpreter {python}: {e}") from None
    if result.returncode != 0:
        raise QuaddanceError(f"madmom run by {python} failed: {result.stderr.strip()[-300:]}")
    return {
        path: {k: np.asarray(v, dtype=float) for k, v in row.items()}
        for path, row in json.loads(result.stdout).items()
    }


def madmom_beats_s(python: str | Path, wav_paths: list[Path]) -> dict[str, np.ndarray]:
    """Beat times from madmom's offline DBN tracker, run by ``python``: {wav path: (n,) s}."""
    return {p: row["dbn"] for p, row in madmom_tracks(python, wav_paths).items()}


SETS = ("tuning", "random", "untuned")
"""Song sets: ``tuning`` = ``BENCH_SONGS`` + ``EXTRA_TUNING_SONGS`` + ``SYNTH_SONGS`` (the
analyser's settings were tuned on them); ``random`` = ``random_midi_songs`` (not tuned on);
``untuned`` = ``UNTUNED_SONGS`` (fixed before tuning, never tuned on)."""


@dataclass
class BenchSong:
    name: str
    set: str
    tempo_bpm: float
    y: np.ndarray  # (n,) mono audio at the bench's sample rate
    beats_s: np.ndarray  # (n_beats,) exact beat times, s
    spec: MidiSongSpec | dict[str, Any]  # the MIDI song, or render_song's arguments + name


def cached_midi_song(
    spec: MidiSongSpec, set_name: str, soundfont: Path, sr: int, cache_dir: Path
) -> tuple[BenchSong, Path]:
    """Write and render ``spec`` (or reuse the rendering cached under ``cache_dir``); return the
    song and its cached wav file."""
    import hashlib

    import soundfile as sf

    from quaddance.music.audio import load_audio

    cache_dir = cache_dir.resolve()
    cache_dir.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="quaddance-beats-") as tmp:
        midi_path = Path(tmp) / f"{spec.name}.mid"
        beats_s = write_midi(spec, midi_path)
        # The key covers everything that changes the audio: the MIDI bytes, soundfont, rate.
        key = hashlib.sha1(midi_path.read_bytes() + f"{soundfont}:{sr}".encode()).hexdigest()
        wav_path = cache_dir / f"{spec.name}-{key[:12]}.wav"
        if not wav_path.is_file():
            raw = Path(tmp) / "raw.wav"
            render_midi(midi_path, raw, soundfont, sr)
            y, _ = load_audio(raw, sr=sr)
            # Cut the reverb tail after the last bar so that every second has true beats.
            end_s = beats_s[-1] + (beats_s[-1] - beats_s[-2])
            part = cache_dir / f".{wav_path.name}.part"
            sf.write(str(part), y[: round(end_s * sr)], sr, format="WAV", subtype="PCM_16")
            part.replace(wav_path)
    y, _ = load_audio(wav_path, sr=sr)
    return BenchSong(spec.name, set_name, spec.tempo_bpm, y, beats_s, spec), wav_path


def _wav_at(song: BenchSong, soundfont: Path, sr: int, cache_dir: Path) -> Path:
    """A wav file of ``song`` rendered at ``sr`` (cached)."""
    import soundfile as sf

    if isinstance(song.spec, MidiSongSpec):
        return cached_midi_song(song.spec, song.set, soundfont, sr, cache_dir)[1]
    path = cache_dir.resolve() / f"{song.name}-synth-{sr}.wav"
    if not path.is_file():
        y = synth_song(song.spec, sr).y
        path.parent.mkdir(parents=True, exist_ok=True)
        sf.write(str(path), y, sr, subtype="PCM_16")
    return path


def bench_songs(
    sets: tuple[str, ...] = SETS,
    sr: int = 22050,
    n_random: int = 12,
    cache_dir: Path = Path("benchmarks/cache"),
) -> list[BenchSong]:
    """The benchmark songs of ``sets`` (see ``SETS``), rendered or taken from the cache."""
    unknown = set(sets) - set(SETS)
    if unknown:
        raise QuaddanceError(f"unknown beat-bench set(s) {sorted(unknown)}; choose from {SETS}")
    if shutil.which("fluidsynth") is None:
        raise QuaddanceError(f"the beat benchmark needs fluidsynth: {INSTALL_HINT}")
    soundfont = find_soundfont()
    specs: list[tuple[MidiSongSpec, str]] = []
    if "tuning" in sets:
        specs += [(spec, "tuning") for spec in (*BENCH_SONGS, *EXTRA_TUNING_SONGS)]
    if "random" in sets:
        specs += [(spec, "random") for spec in random_midi_songs(n_random)]
    if "untuned" in sets:
        specs += [(spec, "untuned") for spec in UNTUNED_SONGS]
    songs = [cached_midi_song(spec, name, soundfont, sr, cache_dir)[0] for spec, name in specs]
    if "tuning" in sets:
        songs += [synth_song(spec, sr) for spec in SYNTH_SONGS]
    return songs


def synth_song(spec: dict[str, Any], sr: int) -> BenchSong:
    """The tuning song ``spec`` (one of `SYNTH_SONGS`), rendered by ``music.synth``."""
    from quaddance.music.synth import render_song

    kwargs = {k: v for k, v in spec.items() if k != "name"}
    y, truth = render_song(duration_s=24.0, sr=sr, **kwargs)
    return BenchSong(spec["name"], "tuning", truth.tempo_bpm, y, truth.beats_s, spec)


def metrical_level_f_measure(
    reference_s: np.ndarray, estimated_s: np.ndarray, window_s: float = F_MEASURE_WINDOW_S
) -> float:
    """Beat F-measure at the estimate's own metrical level.

    The reference is taken at the level nearest (in log ratio) to the ratio of the median
    estimated and reference beat periods: the same beats, double tempo (the reference plus the
    midpoints between its beats) or half tempo (every other reference beat, in whichever phase
    scores higher). Then ``beat_f_measure``. Beats on the off-beats still score about 0: at the
    same level they miss every reference beat, and at half tempo they miss both phases.

    Args:
        reference_s: (n_ref,) true beat times, seconds.
        estimated_s: (n_est,) estimated beat times, seconds.
        window_s: hit window half-width, seconds.

    Returns:
        F-measure in [0, 1].
    """
    ref = np.sort(np.asarray(reference_s, dtype=float))
    est = np.sort(np.asarray(estimated_s, dtype=float))
    if len(ref) < 2 or len(est) < 2:
        return beat_f_measure(ref, est, window_s)
    ratio = float(np.median(np.diff(est)) / np.median(np.diff(ref)))
    level = min((0.5, 1.0, 2.0), key=lambda k: abs(np.log2(ratio / k)))
    if level == 1.0:
        candidates = [ref]
    elif level == 2.0:  # the estimate is at half tempo
        candidates = [ref[0::2], ref[1::2]]
    else:  # double tempo
        candidates = [np.sort(np.concatenate([ref, 0.5 * (ref[1:] + ref[:-1])]))]
    return max(beat_f_measure(c, est, window_s) for c in candidates)


def _score(ref_s: np.ndarray, est_s: np.ndarray) -> dict[str, float]:
    return {
        "f": round(beat_f_measure(ref_s, est_s), 4),
        "f_metrical": round(metrical_level_f_measure(ref_s, est_s), 4),
        "tempo_bpm": round(float(60.0 / np.median(np.diff(est_s))), 2) if len(est_s) > 1 else 0.0,
    }


def run_beat_bench(
    out_path: str | Path,
    sr: int = 22050,
    n_random: int = 12,
    sets: tuple[str, ...] = SETS,
    madmom_python: str | Path | None = None,
    cache_dir: Path = Path("benchmarks/cache"),
    progress: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Score our beat tracker, librosa's default (and madmom's, if given) on the sets; write JSON.

    Args:
        out_path: where the JSON results go (written atomically).
        sr: analysis sample rate, Hz.
        n_random: how many random MIDI songs (``random_midi_songs``) are in the random set.
        sets: which of ``SETS`` to score.
        madmom_python: an interpreter that can import madmom; None leaves madmom out.
        cache_dir: where rendered songs are kept between runs.
        progress: called with each song's name before it is scored.

    Returns:
        The results written: per-song strict and metrical-level F-measures and tempi, and the
        means per set and tracker.
    """
    from quaddance.fileio import write_json
    from quaddance.music.analysis import analyze

    songs = bench_songs(sets, sr, n_random, cache_dir)
    madmom: dict[str, np.ndarray] = {}
    if madmom_python is not None:
        if progress is not None:
            progress("madmom")
        # madmom's networks were trained on 44.1 kHz audio: give it renderings at that rate.
        soundfont = find_soundfont()
        paths = {s.name: _wav_at(s, soundfont, MADMOM_SR, cache_dir) for s in songs}
        by_path = madmom_beats_s(madmom_python, list(paths.values()))
        madmom = {name: by_path[str(path)] for name, path in paths.items()}
    rows: list[dict[str, Any]] = []
    seconds = {"quaddance": 0.0, "librosa_default": 0.0}
    for song in songs:
        if progress is not None:
            progress(song.name)
        t0 = time.perf_counter()
        ours = analyze(song.y, sr)
        t1 = time.perf_counter()
        _, lib_beats_s = _librosa_default_beats_s(song.y, sr)
        seconds["quaddance"] += t1 - t0
        seconds["librosa_default"] += time.perf_counter() - t1
        row: dict[str, Any] = {
            "name": song.name,
            "set": song.set,
            "true_tempo_bpm": song.tempo_bpm,
            "duration_s": round(len(song.y) / sr, 3),
            "n_beats": len(song.beats_s),
        }
        trackers = {"quaddance": ours.beats_s, "librosa_default": lib_beats_s}
        if song.name in madmom:
            trackers["madmom_dbn"] = madmom[song.name]
        for tracker, est_s in trackers.items():
            for key, val in _score(song.beats_s, est_s).items():
                row[f"{key}_{tracker}"] = val
        rows.append(row)

    means: dict[str, dict[str, Any]] = {}
    for set_name in sets:
        in_set = [r for r in rows if r["set"] == set_name]
        entry: dict[str, Any] = {"n_songs": len(in_set)}
        for tracker in ("quaddance", "librosa_default", "madmom_dbn"):
            for key in ("f", "f_metrical"):
                vals = [r[f"{key}_{tracker}"] for r in in_set if f"{key}_{tracker}" in r]
                if vals and len(vals) == len(in_set):
                    entry[f"{key}_{tracker}"] = round(float(np.mean(vals)), 4)
        means[set_name] = entry
    results = {
        "benchmark": "beats",
        "metric": (
            f"beat F-measure, +-{F_MEASURE_WINDOW_S * 1000:.0f} ms, one-to-one, no trim; "
            "f = strict, f_metrical = at the tracker's own metrical level (same, double or "
            "half tempo reference)"
        ),
        "sets": {
            "tuning": "designed MIDI songs (BENCH_SONGS + EXTRA_TUNING_SONGS) and music.synth "
            "songs: the analyser was tuned on these",
            "random": f"{n_random} random MIDI songs (seed 99): not tuned on",
            "untuned": "UNTUNED_SONGS: fast/slow notations, tempo changes, drums off the beat, "
            "140-160 BPM rock; fixed before tuning, never tuned on",
        },
        "soundfont": str(find_soundfont()),
        "sr_hz": sr,
        # madmom hears 44.1 kHz renderings of the same MIDI files (its models' rate).
        "madmom_python": None if madmom_python is None else str(madmom_python),
        "madmom_sr_hz": None if madmom_python is None else MADMOM_SR,
        "means": means,
        "seconds_total": {k: round(v, 2) for k, v in seconds.items()},
        "songs": rows,
    }
    write_json(out_path, results)
    return results
