"""Online beat tracking against the offline analyser, on songs with exactly known beats.

Each song is fed to the ``OnlineBeatTracker`` block by block by `track_samples`
(``quaddance.music.live``), exactly as ``quaddance live --from-file`` does it but without
waiting for the wall clock. Per song: ``lock_s`` (the first stable lock), the online beat
F-measure after the lock (+-70 ms, at the tracker's own metrical level, as ``bench beats``
scores, each part of a song with silent breaks at its own level: `f_after`), the offline
analyser's F-measure over the same span of the same song, and their difference.

Song sets (``LIVE_SETS``): ``random`` and ``untuned`` are the beat benchmark's sets
(``benchmarks/beats.py``) that the online tracker was never tuned on (its settings were set on
the ``tuning`` set and on click tracks); ``live`` holds songs made here for the live case: a tempo
change and breaks of silence after which the music comes back at another tempo or phase. It
is no longer unseen: the tracker's level hold and backbeat test came from a failure on one of
its first three songs, and its last four (a first held-out set) showed the live choreographer's
seam fault (both front paws up, a fall) and its late first move after a lock. ``heldout``
(`heldout_songs`) holds live-case songs made after those fixes and never tuned on.

``real`` and ``real-tuning`` are the held-out and tuning parts of the real-music set
(``benchmarks/real_music``: band recordings and MIDI songs made by people elsewhere, beats from
their charts), ``real-lmms`` and ``real-lmms-tuning`` those of its LMMS part
(``benchmarks/real_music_lmms``, once built); with madmom installed
(``scripts/install_madmom.sh``), madmom's online tracker is scored on the same span of them.

``tuning`` (asked for by name, not reported by default) is the beat benchmark's tuning set plus
`live_tuning_songs`: songs of the untuned set's hard kinds, random MIDI songs from other
generator seeds and two live-case songs, for tuning the tracker without looking at the sets
above.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.beats import (
    F_MEASURE_WINDOW_S,
    BenchSong,
    MidiSongSpec,
    beat_f_measure,
    bench_songs,
    metrical_level_f_measure,
    song_spec,
)
from benchmarks.beats import SETS as BEAT_SETS
from quaddance.errors import QuaddanceError
from quaddance.music.live import OnlineTrack, track_samples

LIVE_CASE_SETS = ("live", "heldout")
"""The sets of live-case songs (`live_case_songs`), which the whole live loop is run on."""

REAL_SETS = {
    "real": ("real", "heldout"),
    "real-tuning": ("real", "tuning"),
    "real-lmms": ("real-lmms", "heldout"),
    "real-lmms-tuning": ("real-lmms", "tuning"),
    "real-fof-tuning": ("real-fof", "tuning"),
}
"""The real-music sets: the set (``benchmarks.real_music.BENCH_SET_ROOTS``) and the split each
one is."""

LIVE_SETS = (*BEAT_SETS, *LIVE_CASE_SETS, *REAL_SETS)
"""``tuning``, ``random``, ``untuned`` (``benchmarks/beats.py``), ``live`` (``live_songs``),
``heldout`` (``heldout_songs``), ``real``, ``real-tuning``, ``real-lmms``,
``real-lmms-tuning`` and ``real-fof-tuning`` (`real_songs`)."""

DEFAULT_SETS = ("random", "untuned", "live", "heldout")
"""The sets reported by default: all but ``tuning``."""

GOAL_LOCK_S = 6.0
"""Issue 11's goal: the first stable lock within 6 s of the music starting."""
GOAL_F_GAP = 0.1
"""Issue 11's goal: online F-measure within 0.1 of the offline analyser's."""


@dataclass
class LiveSong:
    name: str
    set: str
    y: np.ndarray  # (n,) mono audio at the tracker's rate
    beats_s: np.ndarray  # (n_beats,) exact beat times, s (none inside a silent break)
    downbeats_s: np.ndarray  # (n_bars,) exact downbeat times, s
    music_starts_s: tuple[float, ...] = (0.0,)  # where the music (re)starts after silence

    @classmethod
    def from_bench_song(cls, song: BenchSong) -> LiveSong:
        """A song of the beat benchmark (``benchmarks/beats.py``): every one is in 4/4 and
        starts on a downbeat."""
        return cls(song.name, song.set, song.y, song.beats_s, song.beats_s[::4])


def _concat_with_breaks(
    parts: list[tuple[np.ndarray, np.ndarray]], gap_s: float, sr: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, tuple[float, ...]]:
    """Join songs with ``gap_s`` of digital silence between them; shift their beats.

    Returns (audio, beats s, downbeats s, start of each part s); every part starts on a
    downbeat and is in 4/4."""
    ys, beats, downbeats, starts = [], [], [], []
    t0 = 0.0
    for k, (y, b) in enumerate(parts):
        if k > 0:
            ys.append(np.zeros(round(gap_s * sr), dtype=np.float32))
            t0 += gap_s
        starts.append(t0)
        dur_s = len(y) / sr
        beats.append(b[b < dur_s - 1e-6] + t0)
        downbeats.append(beats[-1][::4])
        ys.append(y.astype(np.float32))
        t0 += dur_s
    return np.concatenate(ys), np.concatenate(beats), np.concatenate(downbeats), tuple(starts)


def _synth_part(
    sr: int, bpm: float, dur_s: float, seed: int, **kw: Any
) -> tuple[np.ndarray, np.ndarray]:
    """(audio, exact beats s) of a ``music.synth`` song."""
    from quaddance.music.synth import render_song

    y, truth = render_song(tempo_bpm=bpm, duration_s=dur_s, seed=seed, sr=sr, **kw)
    return y, truth.beats_s


#: Live-case songs made with ``music.synth`` (seeds used nowhere else): (name, parts, silence
#: between the parts s); each part is `_synth_part`'s arguments.
LIVE_SYNTH_SONGS: tuple[tuple[str, tuple[dict[str, Any], ...], float], ...] = (
    ("live_100_to_132", (dict(bpm=100.0, dur_s=30.0, seed=301, tempo_change=(14.0, 132.0)),), 0),
    (
        "live_112_break_86",
        (dict(bpm=112.0, dur_s=14.0, seed=302), dict(bpm=86.0, dur_s=16.0, seed=303, swing=0.5)),
        3.0,
    ),
    (
        "live_128_break_phase",
        (
            dict(bpm=128.0, dur_s=12.0, seed=304, syncopation=True),
            dict(bpm=128.0, dur_s=14.0, seed=305),
        ),
        2.2,
    ),
    (
        "live_96_swing_to_124",
        (dict(bpm=96.0, dur_s=30.0, seed=411, swing=0.6, tempo_change=(15.0, 124.0)),),
        0,
    ),
    (
        "live_150_break_118_sync",
        (
            dict(bpm=150.0, dur_s=13.0, seed=412),
            dict(bpm=118.0, dur_s=15.0, seed=413, syncopation=True),
        ),
        3.0,
    ),
    ("live_74_sections", (dict(bpm=74.0, dur_s=28.0, seed=414, sections=4),), 0),
)

#: The ``heldout`` set's ``music.synth`` songs, made after the live choreographer's seam fix
#: and never tuned on (the first of them then showed the tracker's phase fault after a tempo
#: change): a tempo change down, a break from a slow syncopated song into a swung one, a fast
#: song in three sections. Its General MIDI pair comes from a seed used nowhere else.
HELDOUT_SYNTH_SONGS: tuple[tuple[str, tuple[dict[str, Any], ...], float], ...] = (
    ("heldout_132_to_108", (dict(bpm=132.0, dur_s=30.0, seed=421, tempo_change=(14.0, 108.0)),), 0),
    (
        "heldout_88_sync_break_104_swing",
        (
            dict(bpm=88.0, dur_s=14.0, seed=422, syncopation=True),
            dict(bpm=104.0, dur_s=16.0, seed=423, swing=0.3),
        ),
        2.0,
    ),
    ("heldout_160_sections", (dict(bpm=160.0, dur_s=28.0, seed=424, sections=3),), 0),
)


#: Songs of the ``tuning`` set of this benchmark only (not ``bench beats``'), for the online
#: tracker: the untuned set's kinds of song (drums or keys that do not mark the
#: beat, a slow swung half-time feel, a ramp in a syncopated groove) at other tempi, with other
#: chord and bass rhythms and seeds, so that those kinds can be tuned on without tuning on the
#: untuned set's songs themselves. The last six were first a validation set that chose between
#: tracker changes; choosing is tuning, so they are tuning songs now.
LIVE_TUNING_MIDI_SONGS: tuple[MidiSongSpec, ...] = (
    song_spec(
        "tune_offbeat_hats_128", 128, "offbeat_hats", "anticipated", "tresillo", (5, 33), 5001
    ),
    song_spec("tune_offbeat_hats_92", 92, "offbeat_hats", "charleston", "half", (0, 32), 5002),
    song_spec("tune_clave_100", 100, "clave", "syncopated", "syncopated", (11, 33), 5003),
    song_spec("tune_clave_138", 138, "clave", "charleston", "tresillo", (24, 35), 5004),
    song_spec("tune_keys_pushes_110", 110, "none", "pushes", "half", (4, 32), 5005),
    song_spec("tune_cowbell_sync_124", 124, "cowbell_sync", "pushes", "tresillo", (16, 38), 5006),
    song_spec("tune_onedrop_76", 76, "one_drop", "offbeats", "reggae", (16, 33), 5007),
    song_spec(
        "tune_slow_soul_46",
        46,
        "halftime",
        "eighths",
        "tresillo",
        (48, 33),
        5008,
        swing=0.5,
        duration_s=32.0,
    ),
    song_spec("tune_skank_118", 118, "skank", "offbeats", "reggae", (16, 34), 5009),
    song_spec(
        "tune_funk_120_ramp_150",
        120,
        "funk",
        "syncopated",
        "syncopated",
        (7, 36),
        5010,
        tempo_ramp=(2, 9, 150.0),
    ),
    song_spec("tune_offbeat_hats_104", 104, "offbeat_hats", "syncopated", "half", (4, 33), 6001),
    song_spec("tune_onedrop_70", 70, "one_drop", "charleston", "reggae", (16, 38), 6002),
    song_spec("tune_dembow_100", 100, "dembow", "offbeats", "syncopated", (81, 38), 6003),
    song_spec("tune_bossa_120", 120, "bossa", "pushes", "half", (24, 32), 6004),
    song_spec("tune_trap_72", 72, "trap", "anticipated", "tresillo", (81, 38), 6005),
    song_spec("tune_ska_168", 168, "ska", "offbeats", "quarters", (16, 33), 6006),
)
LIVE_TUNING_RANDOM = ((8, 5200), (12, 6000))
"""``(n, seed)``: ``random_midi_songs(n, seed)`` added to this benchmark's ``tuning`` set,
renamed ``tune_r<seed>_...``: the random set's generator with other seeds (style, tempo,
rhythms, sounds, swing, intro drawn afresh; the melody and velocity draws repeat the random
set's, which ``random_midi_songs`` seeds by song number whatever its seed)."""
LIVE_TUNING_SYNTH_SONGS: tuple[tuple[str, tuple[dict[str, Any], ...], float], ...] = (
    (
        "tune_92_sync_break_110_swing",
        (
            dict(bpm=92.0, dur_s=14.0, seed=5101, syncopation=True),
            dict(bpm=110.0, dur_s=16.0, seed=5102, swing=0.35),
        ),
        2.0,
    ),
    ("tune_140_to_116", (dict(bpm=140.0, dur_s=30.0, seed=5103, tempo_change=(14.0, 116.0)),), 0),
)
"""Live-case songs (``music.synth``, a break or a tempo change) in this benchmark's ``tuning``
set."""


def live_tuning_midi_specs() -> list[MidiSongSpec]:
    """The General MIDI songs of this benchmark's additions to the ``tuning`` set:
    `LIVE_TUNING_MIDI_SONGS` and the renamed `LIVE_TUNING_RANDOM` songs."""
    import dataclasses

    from benchmarks.beats import random_midi_songs

    randoms = [
        dataclasses.replace(s, name=f"tune_r{seed}_{s.name}")
        for n, seed in LIVE_TUNING_RANDOM
        for s in random_midi_songs(n, seed=seed)
    ]
    return [*LIVE_TUNING_MIDI_SONGS, *randoms]


def live_tuning_songs(sr: int, cache_dir: Path = Path("benchmarks/cache")) -> list[LiveSong]:
    """This benchmark's additions to the ``tuning`` set (see `LIVE_TUNING_MIDI_SONGS`)."""
    from benchmarks.beats import cached_midi_song, find_soundfont

    soundfont = find_soundfont()
    out = [
        LiveSong.from_bench_song(cached_midi_song(spec, "tuning", soundfont, sr, cache_dir)[0])
        for spec in live_tuning_midi_specs()
    ]
    return out + _synth_songs(LIVE_TUNING_SYNTH_SONGS, "tuning", sr)


def _synth_songs(
    table: tuple[tuple[str, tuple[dict[str, Any], ...], float], ...], set_name: str, sr: int
) -> list[LiveSong]:
    out = []
    for name, parts, gap_s in table:
        y, b, db, starts = _concat_with_breaks([_synth_part(sr, **p) for p in parts], gap_s, sr)
        out.append(LiveSong(name, set_name, y, b, db, starts))
    return out


def live_songs(
    sr: int, cache_dir: Path = Path("benchmarks/cache"), midi: bool = True
) -> list[LiveSong]:
    """The ``live`` set: `LIVE_SYNTH_SONGS` and (``midi``; needs fluidsynth) two General MIDI
    songs from `random_midi_songs` joined by a break."""
    out = _synth_songs(LIVE_SYNTH_SONGS, "live", sr)
    if midi:
        y, b, db, starts = _midi_pair(2026, 14.0, 2.5, sr, cache_dir)
        out.append(LiveSong("live_midi_pair", "live", y, b, db, starts))
    return out


def _midi_pair(
    seed: int, keep_s: float, gap_s: float, sr: int, cache_dir: Path
) -> tuple[np.ndarray, np.ndarray, np.ndarray, tuple[float, ...]]:
    """The first ``keep_s`` of two `random_midi_songs(2, seed)` (rendered, cached), joined by
    ``gap_s`` of silence: another generator than ``music.synth``, real instrument sounds."""
    from benchmarks.beats import cached_midi_song, find_soundfont, random_midi_songs

    soundfont = find_soundfont()
    parts = []
    for spec in random_midi_songs(2, seed=seed):
        midi, _ = cached_midi_song(spec, "live", soundfont, sr, cache_dir)
        cut_s = min(keep_s, len(midi.y) / sr)
        parts.append((midi.y[: round(cut_s * sr)], midi.beats_s[midi.beats_s < cut_s]))
    return _concat_with_breaks(parts, gap_s, sr)


def heldout_songs(sr: int, cache_dir: Path = Path("benchmarks/cache")) -> list[LiveSong]:
    """The ``heldout`` set: `HELDOUT_SYNTH_SONGS` and two General MIDI songs from
    `random_midi_songs` (seed 3031) joined by a break."""
    out = _synth_songs(HELDOUT_SYNTH_SONGS, "heldout", sr)
    y, b, db, starts = _midi_pair(3031, 14.0, 2.0, sr, cache_dir)
    out.append(LiveSong("heldout_midi_pair", "heldout", y, b, db, starts))
    return out


LIVE_DANCE_TUNING_SONGS = (
    "tune_140_to_116",
    "tune_92_sync_break_110_swing",
    "tune_r6000_random04_ballad",
    "tune_rock_152",
    "pop_100_to_128",
    "piano_72_arpeggio",
    "tune_skank_118",
    "dembow_96_sync",
)
"""Tuning-set songs that the whole loop also runs on when ``tuning`` is among the sets: the
live choreographer is tuned on these, never on the live-case sets. Two live-case songs (a
break, a tempo change) and six of other styles at 72-152 BPM (~5 min of real time)."""


def live_dance_songs(
    sets: tuple[str, ...], sr: int, cache_dir: Path = Path("benchmarks/cache")
) -> list[LiveSong]:
    """The songs `bench_live_dance` runs on: those of the live-case sets among ``sets`` and,
    with ``tuning``, `LIVE_DANCE_TUNING_SONGS`."""
    songs = live_case_songs(sets, sr, cache_dir)
    if "tuning" in sets:
        tuning = beat_songs(("tuning",), sr, 0, cache_dir) + live_tuning_songs(sr, cache_dir)
        by_name = {s.name: s for s in tuning}
        songs += [by_name[name] for name in LIVE_DANCE_TUNING_SONGS]
    return songs


def live_case_songs(
    sets: tuple[str, ...], sr: int, cache_dir: Path = Path("benchmarks/cache")
) -> list[LiveSong]:
    """The songs of the live-case sets among ``sets`` (see ``LIVE_CASE_SETS``)."""
    songs = live_songs(sr, cache_dir) if "live" in sets else []
    return songs + (heldout_songs(sr, cache_dir) if "heldout" in sets else [])


def real_songs(sets: tuple[str, ...], sr: int) -> list[LiveSong]:
    """The real-music songs of the ``REAL_SETS`` among ``sets``, at ``sr``.

    Raises:
        QuaddanceError: a set's folder is not built (the LMMS part), naming how to build it
            (``benchmarks.real_music.SetFileMissingError``).
    """
    from benchmarks.real_music import load_audio_at

    songs = []
    for set_name in sets:
        if set_name in REAL_SETS:
            songs += [
                LiveSong(s.name, set_name, load_audio_at(s, sr), s.beats_s, s.downbeats_s)
                for s in _real_set(set_name)
            ]
    return songs


def _real_set(set_name: str) -> list:
    """The `RealSong`s of real-music set ``set_name`` (a key of ``REAL_SETS``)."""
    import benchmarks.real_music as real_music

    real_set, split = REAL_SETS[set_name]
    return real_music.load_songs(real_music.BENCH_SET_ROOTS[real_set], splits=(split,))


def madmom_online_tracks(python: str | Path, songs: list[LiveSong]) -> dict[str, np.ndarray]:
    """madmom's online beats of each real-music song (``REAL_SETS``): {name: (n,) s}. madmom
    hears the recording decoded at its models' rate, not our tracker's."""
    from benchmarks.real_music import madmom_song_tracks

    names = {song.name for song in songs}
    real = [s for name in dict.fromkeys(song.set for song in songs)
            for s in _real_set(name) if s.name in names]  # fmt: skip
    tracks = madmom_song_tracks(python, real, ("online",))
    return {name: row["online"] for name, row in tracks.items()}


def beat_songs(sets: tuple[str, ...], sr: int, n_random: int, cache_dir: Path) -> list[LiveSong]:
    """The beat benchmark's songs of ``sets`` (`bench_songs`) as `LiveSong`s."""
    songs = bench_songs(sets, sr=sr, n_random=n_random, cache_dir=cache_dir)
    return [LiveSong.from_bench_song(s) for s in songs]


def _relock_s(track: OnlineTrack, start_s: float) -> float | None:
    """Seconds from ``start_s`` to the first locked block at or after it (None if never)."""
    lock_s = track.first_lock_s(start_s)
    return None if lock_s is None else lock_s - start_s


JOIN_AT = 1.0 / 3.0
"""Joining mid-song: the tracker starts at the first true beat a third into the song ..."""
JOIN_PHASE_BEATS = 0.37
"""... plus this fraction of that beat, so the first sound it hears is neither a beat nor the
song's start. Every song of these sets starts on its first downbeat, which a tracker started
with the song can lean on; music already playing in a room gives it nothing of the kind."""


def join_mid_song(song: LiveSong, sr: int) -> tuple[LiveSong, float]:
    """``song`` as heard by a tracker started part-way through it (`JOIN_AT`,
    `JOIN_PHASE_BEATS`), with its times from the join; and the join's song time, s."""
    b = song.beats_s
    k = min(int(np.searchsorted(b, JOIN_AT * len(song.y) / sr)), len(b) - 2)
    join_s = float(b[k] + JOIN_PHASE_BEATS * (b[k + 1] - b[k]))
    starts = [s - join_s for s in song.music_starts_s if s > join_s]
    joined = LiveSong(
        song.name,
        song.set,
        song.y[round(join_s * sr) :],
        b[b > join_s] - join_s,
        song.downbeats_s[song.downbeats_s > join_s] - join_s,
        (0.0, *starts),
    )
    return joined, join_s


MIC_LEAD_S = 2.0
MIC_HISS_RMS = 3e-5
"""The room heard before the song in the ``silence_`` scores: a microphone started first
(-90 dBFS hiss), the tracker told that music may already be playing."""
NOISY_SNR_DB = 10.0
"""The ``noisy_`` scores: pink noise this far below the song's RMS (a fan in the room)."""


def _score_song(song: LiveSong, sr: int, shifts: int = 1) -> dict[str, Any]:
    """`_score_from_start` of ``song``, plus the same scores of the song joined mid-song
    (`join_mid_song`) under ``join_`` names; the online tracker's lock and F when a
    microphone heard a quiet room first (``silence_``) and with noise (``noisy_``); and, for
    ``shifts`` > 1, under ``shifted``, its lock and F from the start and joined at each of
    ``shifts`` offsets within an onset frame (`shifted_scores`, this row's own first)."""
    row = _score_from_start(song, sr)
    joined, join_s = join_mid_song(song, sr)
    scores = _score_from_start(joined, sr, song_start=False)
    row["join_s"] = round(join_s, 3)
    for key in ("lock_s", "f_online", "f_offline", "f_diff"):
        row[f"join_{key}"] = scores[key]
    hiss = noise_clip("white", 0, MIC_LEAD_S, sr) * (MIC_HISS_RMS / NOISE_RMS)
    row["silence_lock_s"], row["silence_f_online"] = online_scores(
        np.concatenate([hiss, song.y]),
        song.beats_s,
        sr,
        song_start=False,
        lead_s=MIC_LEAD_S,
        parts_s=song.music_starts_s,
    )
    rms = float(np.sqrt(np.mean(song.y.astype(np.float64) ** 2)))
    noise = noise_clip("pink", 1, len(song.y) / sr, sr) * (
        rms * 10 ** (-NOISY_SNR_DB / 20) / NOISE_RMS
    )
    row["noisy_lock_s"], row["noisy_f_online"] = online_scores(
        song.y + noise, song.beats_s, sr, song_start=True, parts_s=song.music_starts_s
    )
    if shifts > 1:
        more = shifted_scores(song, joined, sr, shifts)
        row["shifted"] = {key: [row[key], *more[key]] for key in more}
    return row


SHIFTED_KEYS = ("lock_s", "f_online", "join_lock_s", "join_f_online")


def _in_time(lock_s: float | None) -> bool:
    """Issue 11's lock goal: locked within `GOAL_LOCK_S`."""
    return lock_s is not None and lock_s <= GOAL_LOCK_S


def _in_gap(f_diff: float) -> bool:
    """Issue 11's F goal: online F at most `GOAL_F_GAP` below the offline F."""
    return f_diff >= -GOAL_F_GAP


def shifted_scores(
    song: LiveSong, joined: LiveSong, sr: int, shifts: int
) -> dict[str, list[float | None]]:
    """The online tracker's lock and F (`SHIFTED_KEYS`) on ``song`` from its start and on
    ``joined`` (told that the music may be playing), each moved by k / ``shifts`` of an onset
    frame (k = 1 .. ``shifts`` - 1: that much silence first, the scores in song time). The
    tracker is chaotic to such moves (a song's frame grid against its music): single songs
    lock seconds apart, F 1.0 on one grid and 0.3 on the next, so a tracker change is judged
    better on the means over several."""
    from quaddance.music.online_beats import HOP

    out: dict[str, list[float | None]] = {key: [] for key in SHIFTED_KEYS}
    for k in range(1, shifts):
        lead = np.zeros(k * HOP // shifts, dtype=np.float32)
        for prefix, heard, song_start in (("", song, True), ("join_", joined, False)):
            lock_s, f = online_scores(
                np.concatenate([lead, heard.y]),
                heard.beats_s,
                sr,
                song_start,
                len(lead) / sr,
                heard.music_starts_s,
            )
            out[f"{prefix}lock_s"].append(lock_s)
            out[f"{prefix}f_online"].append(f)
    return out


def _shifted_goals(rows: list[dict[str, Any]], shifts: int) -> dict[str, Any]:
    """The tracker's goals counted at each shift of `shifted_scores` and averaged over the
    shifts (the F gap against the offline F of the unshifted row)."""

    def mean_in_time(key: str) -> float:
        counts = [sum(_in_time(r["shifted"][key][k]) for r in rows) for k in range(shifts)]
        return round(float(np.mean(counts)), 2)

    def mean_in_gap(key: str, offline_key: str) -> float:
        counts = [
            sum(_in_gap(r["shifted"][key][k] - r[offline_key]) for r in rows) for k in range(shifts)
        ]
        return round(float(np.mean(counts)), 2)

    def mean_f(key: str) -> float:
        return round(float(np.mean([r["shifted"][key] for r in rows])), 4)

    return {
        "shifts": shifts,
        "songs_locked_in_time": mean_in_time("lock_s"),
        "songs_within_f_gap": mean_in_gap("f_online", "f_offline"),
        "f_online": mean_f("f_online"),
        "joining_mid_song": {
            "songs_locked_in_time": mean_in_time("join_lock_s"),
            "songs_within_f_gap": mean_in_gap("join_f_online", "join_f_offline"),
            "f_online": mean_f("join_f_online"),
        },
    }


def online_scores(
    y: np.ndarray,
    beats_s: np.ndarray,
    sr: int,
    song_start: bool,
    lead_s: float = 0.0,
    parts_s: tuple[float, ...] = (0.0,),
) -> tuple[float | None, float]:
    """(lock time, song seconds, or None; F after the lock, `f_after` over ``parts_s``) of
    the online tracker on ``y``, the song whose ``beats_s`` start ``lead_s`` into it."""
    track = track_samples(y, sr, song_start)
    lock_s = _relock_s(track, lead_s)
    if lock_s is None:
        return None, 0.0
    online_s = track.beats_s - lead_s
    return round(lock_s, 3), round(f_after(beats_s, online_s, lock_s, parts_s), 4)


def f_after(
    ref_s: np.ndarray, est_s: np.ndarray, start_s: float, parts_s: tuple[float, ...] = (0.0,)
) -> float:
    """`metrical_level_f_measure` of the beats at or after ``start_s`` (the lock), each part of
    the song (``parts_s``: where the music starts again after a silent break) scored at its
    own metrical level, the parts' F weighted by their reference beats. A tracker forgets the
    tempo in a break (it must, to find a new one), so it may choose another level after it:
    scored at one level for the whole song, double time before a break and the beat after it
    was an F of 0.72 where each part alone was within 0.1 of the offline analyser's
    (tune_92_sync_break_110_swing)."""
    ref_s, est_s = ref_s[ref_s >= start_s], est_s[est_s >= start_s]
    edges = [*parts_s[1:], np.inf]
    scores, weights = [], []
    for lo, hi in zip((-np.inf, *parts_s[1:]), edges, strict=True):
        ref = ref_s[(ref_s >= lo) & (ref_s < hi)]
        if len(ref):
            scores.append(metrical_level_f_measure(ref, est_s[(est_s >= lo) & (est_s < hi)]))
            weights.append(len(ref))
    if not weights:
        return metrical_level_f_measure(ref_s, est_s)
    return float(np.average(scores, weights=weights))


def _score_from_start(song: LiveSong, sr: int, song_start: bool = True) -> dict[str, Any]:
    from quaddance.music.analysis import analyze

    track = track_samples(song.y, sr, song_start)
    beats = track.beats
    offline = analyze(song.y, sr)
    offline_s = offline.beats_s
    online_s = track.beats_s
    latency_s = max((b.reported_s - b.time_s for b in beats), default=0.0)
    lock_s = _relock_s(track, 0.0)
    duration_s = len(song.y) / sr
    row: dict[str, Any] = {
        "name": song.name,
        "set": song.set,
        "duration_s": round(duration_s, 2),
        "lock_s": None if lock_s is None else round(lock_s, 3),
    }
    # Scored after the lock, for both trackers, so that the offline analyser is judged on the
    # same stretch of music; a song that never locks scores 0 online.
    start_s = lock_s if lock_s is not None else duration_s
    parts_s = song.music_starts_s
    f_online = f_after(song.beats_s, online_s, start_s, parts_s)
    f_offline = f_after(song.beats_s, offline_s, 0.0 if lock_s is None else start_s, parts_s)
    # Downbeats: strict F-measure (a bar phase one beat off scores 0), same span.
    true_db = song.downbeats_s[song.downbeats_s >= start_s]
    online_db = np.array([b.time_s for b in beats if b.downbeat and b.time_s >= start_s])
    offline_db = offline.downbeats_s[offline.downbeats_s >= start_s]
    row.update(
        {
            "f_online": round(f_online, 4),
            "f_offline": round(f_offline, 4),
            "f_diff": round(f_online - f_offline, 4),
            "f_online_whole_song": round(f_after(song.beats_s, online_s, 0.0, parts_s), 4),
            "f_downbeat_online": round(beat_f_measure(true_db, online_db), 4),
            "f_downbeat_offline": round(beat_f_measure(true_db, offline_db), 4),
            "tempo_bpm_end": round(beats[-1].tempo_bpm, 2) if beats else 0.0,
            "max_report_delay_ms": round(1000.0 * latency_s, 2),
            "cpu_per_audio_s": round(track.tracker_s / duration_s, 4),
        }
    )
    if len(song.music_starts_s) > 1:
        relocks = [_relock_s(track, s) for s in song.music_starts_s[1:]]
        row["relock_s"] = [None if r is None else round(r, 3) for r in relocks]
    return row


def bench_live_tracker(
    sets: tuple[str, ...] = DEFAULT_SETS,
    n_random: int = 12,
    cache_dir: Path = Path("benchmarks/cache"),
    progress: Callable[[str], None] | None = None,
    shifts: int = 1,
    madmom_python: str | Path | None = None,
) -> dict[str, Any]:
    """Score the online tracker and the offline analyser on ``sets``; write nothing.

    Args:
        sets: which of ``LIVE_SETS`` to score (default: the ones not tuned on).
        n_random: songs in the beat benchmark's random set.
        cache_dir: where the beat benchmark keeps its rendered songs.
        progress: called with each song's name before it is scored.
        shifts: also score the online tracker at this many offsets within an onset frame
            (`shifted_scores`), with the goals averaged over them (``goals["shifted"]``).
        madmom_python: an interpreter that imports madmom: its online tracker is scored on
            the real-music songs too (``f_madmom_online``, ``f_madmom_online_whole_song``).

    Returns:
        ``{"songs": [per-song rows], "means": {set: ...}, "goals": {...}, ...}``; a row has
        ``lock_s`` (None if it never locked), ``f_online``, ``f_offline``, ``f_diff``,
        ``relock_s`` (songs with breaks), the largest report delay and the CPU time, and
        ``join_s``, ``join_lock_s``, ``join_f_online``, ``join_f_offline``, ``join_f_diff``:
        the same scores when the tracker joins the song mid-song (`join_mid_song`), told
        that the music may already be playing (``song_start=False``, as `live` from a
        microphone); ``silence_lock_s``, ``silence_f_online`` and ``noisy_lock_s``,
        ``noisy_f_online``: the online tracker heard after a quiet room and with noise
        (`_score_song`). ``noise`` is `noise_locks`.
    """
    from quaddance.music.online_beats import LATENCY_S, SR_HZ

    unknown = set(sets) - set(LIVE_SETS)
    if unknown:
        raise QuaddanceError(f"unknown live-bench set(s) {sorted(unknown)}; choose {LIVE_SETS}")
    beat_sets = tuple(s for s in sets if s in BEAT_SETS)
    songs = beat_songs(beat_sets, SR_HZ, n_random, cache_dir) if beat_sets else []
    if "tuning" in sets:
        songs += live_tuning_songs(SR_HZ, cache_dir)
    songs += live_case_songs(sets, SR_HZ, cache_dir)
    real = real_songs(sets, SR_HZ)
    songs += real
    madmom: dict[str, np.ndarray] = {}
    if madmom_python is not None and real:
        if progress is not None:
            progress("madmom's online tracker")
        madmom = madmom_online_tracks(madmom_python, real)
    rows = []
    for song in songs:
        if progress is not None:
            progress(song.name)
        row = _score_song(song, SR_HZ, shifts)
        if song.name in madmom:
            # Scored on the span ours is (after our lock), and over the whole song.
            start_s = row["lock_s"] if row["lock_s"] is not None else row["duration_s"]
            row["f_madmom_online"] = round(f_after(song.beats_s, madmom[song.name], start_s), 4)
            row["f_madmom_online_whole_song"] = round(
                f_after(song.beats_s, madmom[song.name], 0.0), 4
            )
        rows.append(row)
    means: dict[str, dict[str, Any]] = {}
    for set_name in sets:
        in_set = [r for r in rows if r["set"] == set_name]
        if not in_set:
            continue
        locks = [r["lock_s"] for r in in_set if r["lock_s"] is not None]
        join_locks = [r["join_lock_s"] for r in in_set if r["join_lock_s"] is not None]
        means[set_name] = {
            "n_songs": len(in_set),
            "n_locked": len(locks),
            "lock_s_median": round(float(np.median(locks)), 3) if locks else None,
            "f_online": round(float(np.mean([r["f_online"] for r in in_set])), 4),
            "f_offline": round(float(np.mean([r["f_offline"] for r in in_set])), 4),
            "f_diff": round(float(np.mean([r["f_diff"] for r in in_set])), 4),
            "f_downbeat_online": round(float(np.mean([r["f_downbeat_online"] for r in in_set])), 4),
            "f_downbeat_offline": round(
                float(np.mean([r["f_downbeat_offline"] for r in in_set])), 4
            ),
            "join_lock_s_median": round(float(np.median(join_locks)), 3) if join_locks else None,
            "join_f_online": round(float(np.mean([r["join_f_online"] for r in in_set])), 4),
            "join_f_offline": round(float(np.mean([r["join_f_offline"] for r in in_set])), 4),
            "silence_f_online": round(float(np.mean([r["silence_f_online"] for r in in_set])), 4),
            "noisy_f_online": round(float(np.mean([r["noisy_f_online"] for r in in_set])), 4),
        }
        for key in ("f_online_whole_song", "f_madmom_online", "f_madmom_online_whole_song"):
            if all(key in r for r in in_set):
                means[set_name][key] = round(float(np.mean([r[key] for r in in_set])), 4)

    def in_time(key: str) -> str:
        return f"{sum(_in_time(r[key]) for r in rows)}/{len(rows)}"

    def in_gap(key: str) -> str:
        return f"{sum(_in_gap(r[key]) for r in rows)}/{len(rows)}"

    return {
        "benchmark": "live_tracker",
        "metric": (
            f"beat F-measure, +-{F_MEASURE_WINDOW_S * 1000:.0f} ms, one-to-one, at the "
            "tracker's own metrical level (bench beats' f_metrical; in a song with silent "
            "breaks, each part at its own level, weighted by its beats), over the beats after "
            "the first stable lock, for the online tracker and the offline analyser alike"
        ),
        "latency_s": LATENCY_S,
        "sets": list(sets),
        "goals": {
            "lock_within_s": GOAL_LOCK_S,
            "f_gap_at_most": GOAL_F_GAP,
            "songs_locked_in_time": in_time("lock_s"),
            "songs_within_f_gap": in_gap("f_diff"),
            # The same goals for the songs joined mid-song (`join_mid_song`): music already
            # playing, as in a room, heard by a tracker told so (``song_start=False``); issue
            # 11 states its goals for the songs from their start.
            "joining_mid_song": {
                "songs_locked_in_time": in_time("join_lock_s"),
                "songs_within_f_gap": in_gap("join_f_diff"),
            },
            # Lock only: a microphone that heard a quiet room first
            # (`MIC_LEAD_S`, from the song's start), and pink noise `NOISY_SNR_DB` below.
            "after_silence_locked_in_time": in_time("silence_lock_s"),
            "with_noise_locked_in_time": in_time("noisy_lock_s"),
            **({"shifted": _shifted_goals(rows, shifts)} if shifts > 1 else {}),
        },
        "means": means,
        "songs": rows,
        "noise": noise_locks(SR_HZ),
    }


NOISE_COLOURS = {"white": 0.0, "pink": 0.5, "brown": 1.0}
"""Noise clips of `noise_locks`: amplitude spectrum ~ 1 / f ** exponent."""
NOISE_RMS = 0.1
"""RMS of a `noise_clip` (-20 dBFS)."""


def noise_clip(colour: str, seed: int, duration_s: float, sr: int) -> np.ndarray:
    """(n,) float32 noise of ``colour`` (`NOISE_COLOURS`) at -20 dBFS RMS."""
    white = np.random.default_rng(seed).standard_normal(round(duration_s * sr))
    spec = np.fft.rfft(white)
    spec /= np.maximum(np.arange(len(spec)), 1) ** NOISE_COLOURS[colour]
    y = np.fft.irfft(spec, len(white))
    return (NOISE_RMS * y / np.sqrt(np.mean(y**2))).astype(np.float32)


def noise_locks(sr: int, seeds: int = 6, duration_s: float = 12.0) -> dict[str, Any]:
    """How often the tracker locks on steady noise, which has no beat: ``seeds`` clips of each
    colour, heard from the stream's start (told ``song_start`` and not) and after 3 s of
    silence (a microphone in a quiet room, then a fan)."""
    clips = [noise_clip(c, 100 + k, duration_s, sr) for c in NOISE_COLOURS for k in range(seeds)]
    silence = np.zeros(3 * sr, dtype=np.float32)
    locked: dict[str, int] = {}
    for key, song_start, lead in (
        ("from_start", True, False),
        ("from_start_song_start_false", False, False),
        ("after_3_s_silence", False, True),
    ):
        tracks = [
            track_samples(np.concatenate([silence, y]) if lead else y, sr, song_start)
            for y in clips
        ]
        locked[key] = sum(bool(track.locked.any()) for track in tracks)
    return {
        "clips": len(clips),
        "duration_s": duration_s,
        "colours": list(NOISE_COLOURS),
        "locked": locked,
    }


#: Issue 11's goals for the whole live loop (`bench_live_dance`).
GOAL_ACCENT_COVERAGE = 0.6
GOAL_ACCENT_OFFSET_MS = 60.0
GOAL_LOOP_P99_MS = 20.0


def _accent_stats(accents_s: np.ndarray, beats_s: np.ndarray, tol_s: float) -> tuple[float, float]:
    """(fraction of beats with an accent within tol, median |offset| of those, ms)."""
    from quaddance.choreo.accents import accent_offsets_s

    offsets = accent_offsets_s(accents_s, beats_s)
    hit = offsets <= tol_s
    coverage = float(hit.mean()) if hit.size else 0.0
    median_ms = float(np.median(offsets[hit]) * 1e3) if hit.any() else float("nan")
    return coverage, median_ms


def bench_live_dance(
    work_dir: Path,
    names: tuple[str, ...] | None = None,
    progress: Callable[[str], None] | None = None,
    sets: tuple[str, ...] = LIVE_CASE_SETS,
    cache_dir: Path = Path("benchmarks/cache"),
) -> dict[str, Any]:
    """Run `quaddance live --from-file` (simulated robot, wall clock, shipped policy) on the
    songs of `live_dance_songs` (the live-case ``sets``; `LIVE_DANCE_TUNING_SONGS` with
    ``tuning``), whose beats are known exactly, and score the whole loop per song: the lock,
    falls, the loop time, the audio-to-command latency, and the robot's motion accents
    (measured in the simulator: paw lift peaks and trunk turning points, `choreo.accents`)
    against the true beats after the lock (+-100 ms) with their median offset."""
    import soundfile as sf

    from quaddance.choreo.accents import BEAT_TOLERANCE_S, motion_accents_s
    from quaddance.live.session import LiveJob, run_live
    from quaddance.music.online_beats import SR_HZ

    chosen = tuple(s for s in sets if s in (*LIVE_CASE_SETS, "tuning"))
    songs = [
        s for s in live_dance_songs(chosen, SR_HZ, cache_dir) if names is None or s.name in names
    ]
    rows = []
    for song in songs:
        if progress is not None:
            progress(song.name)
        folder = Path(work_dir) / song.name
        folder.mkdir(parents=True, exist_ok=True)
        wav = folder / f"{song.name}.wav"
        sf.write(wav, song.y, SR_HZ)
        summary, paths = run_live(LiveJob(out_dir=folder, from_file=wav))
        with np.load(paths["rollout"]) as z:
            t, feet = z["time_s"], z["foot_heights_m"]
            body = np.column_stack([z["base_height_m"], z["base_rpy_rad"]])
        body[:, 0] -= np.median(body[:, 0])
        body[:, 3] -= body[0, 3]
        accents = np.sort(motion_accents_s(t, feet, body))
        lock = summary["lock_s"]
        after = song.beats_s[song.beats_s > (lock if lock is not None else np.inf)]
        after = after[after < t[-1] - 0.5]
        coverage, offset_ms = _accent_stats(accents, after, BEAT_TOLERANCE_S)
        rows.append(
            {
                "name": song.name,
                "set": song.set,
                "duration_s": summary["duration_s"],
                "lock_s": lock,
                "falls": summary["falls"],
                "accent_coverage_after_lock": round(coverage, 4),
                "accent_median_offset_ms": None if np.isnan(offset_ms) else round(offset_ms, 1),
                "loop_ms": summary["loop_ms"],
                "latency_ms": summary["latency_ms"],
                "online_beats": len(summary["beats_s"]),
            }
        )
    ok = [
        r["lock_s"] is not None
        and r["lock_s"] <= GOAL_LOCK_S
        and r["falls"] == 0
        and r["accent_coverage_after_lock"] >= GOAL_ACCENT_COVERAGE
        and (r["accent_median_offset_ms"] or 1e9) <= GOAL_ACCENT_OFFSET_MS
        and (r["loop_ms"]["p99"] or 1e9) <= GOAL_LOOP_P99_MS
        for r in rows
    ]
    return {
        "benchmark": "live_dance",
        "what": "quaddance live --from-file, --robot sim, shipped policy, real time",
        "goals": {
            "lock_within_s": GOAL_LOCK_S,
            "accent_coverage_at_least": GOAL_ACCENT_COVERAGE,
            "accent_median_offset_ms_at_most": GOAL_ACCENT_OFFSET_MS,
            "loop_p99_ms_at_most": GOAL_LOOP_P99_MS,
            "falls": 0,
            "songs_meeting_all": f"{sum(ok)}/{len(rows)}",
            "songs_meeting_all_per_set": {
                name: f"{sum(k for k, r in zip(ok, rows, strict=True) if r['set'] == name)}/"
                f"{sum(r['set'] == name for r in rows)}"
                for name in chosen
            },
        },
        "songs": rows,
    }


def machine_info() -> dict[str, Any]:
    """What the figures were measured on, and how busy it was (1-minute load average)."""
    import os
    import platform

    return {
        "cpu": platform.processor() or platform.machine(),
        "cpu_count": os.cpu_count(),
        "python": platform.python_version(),
        "load_1min": round(os.getloadavg()[0], 2),
    }
