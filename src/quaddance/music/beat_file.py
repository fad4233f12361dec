"""Beat times from another tool (``--beats FILE``), for a song where every tracker fails.

Two formats:

- text: one time in seconds a line; blank lines and ``#`` comments are skipped; a line may
  hold more columns, separated by whitespace or commas, of which the first is the time (the
  label exports of Sonic Visualiser and Audacity; Audacity's ``\\`` lines of a label's
  frequency range are skipped). When the second column counts the beats of each bar on every
  line (1, 2, 3, 4, 1, ...: the output of madmom's ``DBNDownBeatTracker``, the beat
  annotations of the Ballroom, GTZAN and Harmonix sets), its 1s are the downbeats;
- JSON (a ``.json`` name, or a file that opens with ``{``): an object with ``beats_s``, a list
  of seconds, and optionally ``downbeats_s``.

`read_beats` checks everything that needs no song and names the file and the problem in one
line (`quaddance.errors.InputFileError`); `BeatList.check_within` checks the song's length, and
`BeatList.notes` says where the beats and the song may not go together (the dance is made).
The dance composer (`quaddance.pipeline.compose`) puts the beats in the choreographer's grid.
"""

from __future__ import annotations

import itertools
import json
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from quaddance.errors import InputFileError, not_a_file
from quaddance.layout import DANCE_TEMPO_BPM
from quaddance.music.analysis import MIN_BEAT_GAP_S

#: Fewest beats a file must give: one bar, the least the choreographer can dance to.
MIN_BEATS = 4
#: Farthest a downbeat may be from the nearest beat, s (a rounding of the same time).
DOWNBEAT_ON_BEAT_S = 0.01
#: Most beats in a bar that a text file's second column may count (12/8 counted in eighths).
MAX_BAR_BEATS = 12
#: Longest stretch of the song before the first beat or after the last that passes without a
#: note, s: the robot stands still there (an intro or an ending of a few bars is common).
UNBEATEN_NOTE_S = 15.0

_SEPARATOR = re.compile(r"[\s,]+")
#: A file whose lines are all "digits,digits" (and no valid bar count) was written with decimal
#: commas.
_DECIMAL_COMMA = re.compile(r"^(\d+,\d+[ \t]*(\r?\n|$)\s*)+$")


@dataclass(frozen=True)
class BeatList:
    """Beats read from a file.

    Attributes:
        path: the file, named in every error.
        beats_s: beat times, s: strictly increasing, at least `MIN_BEAT_GAP_S` apart, >= 0.
        downbeats_s: the file's downbeats, s, each one of ``beats_s``; None where it gives
            none.
    """

    path: Path
    beats_s: tuple[float, ...]
    downbeats_s: tuple[float, ...] | None = None

    @property
    def name(self) -> str:
        """The file's name, as a dance's ``source`` says it."""
        return self.path.name

    def check_within(self, duration_s: float) -> None:
        """One line if a beat falls after the song's end, ``duration_s``."""
        if self.beats_s[-1] > duration_s:
            raise InputFileError(
                self.path,
                f"beat {self.beats_s[-1]:.3f} s is past the song's end ({duration_s:.3f} s)",
            )

    def notes(self, duration_s: float) -> list[str]:
        """What a user may want to know before the robot dances to these beats on a song of
        ``duration_s``: a long stretch with no beat (the robot stands still), or a tempo
        outside the dance range (the beats are danced as they are, not halved or doubled)."""
        beats = np.asarray(self.beats_s)
        notes = []
        bpm = 60.0 / float(np.median(np.diff(beats)))
        lo, hi = DANCE_TEMPO_BPM
        if not lo <= bpm <= hi:
            other = "every second beat" if bpm > hi else "a beat between each two"
            notes.append(
                f"{self.name}: its beats run at {bpm:.0f} BPM, outside the dance range "
                f"{lo:.0f}-{hi:.0f} BPM; they are danced as they are (give {other} to "
                "dance inside it)"
            )
        if beats[0] > UNBEATEN_NOTE_S:
            notes.append(
                f"{self.name}: the first beat is at {beats[0]:.1f} s; the robot stands still "
                "until then"
            )
        if duration_s - beats[-1] > UNBEATEN_NOTE_S:
            notes.append(
                f"{self.name}: the last beat is at {beats[-1]:.1f} s of the {duration_s:.1f} s "
                f"song; the robot stands still for the last {duration_s - beats[-1]:.1f} s"
            )
        return notes


def read_beats(path: Path) -> BeatList:
    """The `BeatList` of a text or JSON beat file (see the module), checked."""
    path = Path(path)
    if not path.is_file():
        raise not_a_file(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError:
        raise InputFileError(path, "not a text file of beat times") from None
    except OSError as exc:
        raise InputFileError(path, f"cannot read it ({exc.strerror or exc})") from None
    if not text.strip():
        raise InputFileError(path, "empty file: no beat times")
    if path.suffix.lower() == ".json" or text.lstrip().startswith("{"):
        beats, downbeats = _json_times(path, text)
    else:
        beats, downbeats = _text_times(path, text)
    _check_times(path, "beat", beats)
    if len(beats) < MIN_BEATS:
        raise InputFileError(path, f"{len(beats)} beats; at least {MIN_BEATS} are needed")
    gaps = np.diff(beats)
    if gaps.min() < MIN_BEAT_GAP_S:
        i = int(np.argmin(gaps))
        raise InputFileError(
            path,
            f"beats {beats[i]:.3f} s and {beats[i + 1]:.3f} s are {gaps[i]:.3f} s apart; "
            f"beats must be at least {MIN_BEAT_GAP_S} s apart",
        )
    if downbeats is not None:
        _check_times(path, "downbeat", downbeats)
        _check_on_beats(path, beats, downbeats)
    return BeatList(path, tuple(beats), None if downbeats is None else tuple(downbeats))


def _text_times(path: Path, text: str) -> tuple[list[float], list[float] | None]:
    """The first column of each line that is not blank, a comment or an Audacity ``\\``
    line, and the downbeats its second column gives (`_bar_downbeats`); one line naming the
    line that is not a number."""
    times, second_column = [], []
    for n, line in enumerate(text.splitlines(), start=1):
        fields = _SEPARATOR.split(line.split("#", 1)[0].strip(), maxsplit=2)
        if fields[0] in ("", "\\"):
            continue
        try:
            times.append(float(fields[0]))
        except ValueError:
            raise InputFileError(path, f"line {n}: {fields[0][:40]!r} is not a number") from None
        second_column.append(fields[1] if len(fields) > 1 else "")
    if not times:
        raise InputFileError(path, "no beat times (only blank lines and comments)")
    downbeats = _bar_downbeats(times, second_column)
    if downbeats is None and _DECIMAL_COMMA.match(text.lstrip()):
        # "0,5" in every line is a time written with a decimal comma, not "0" and a label.
        first = text.lstrip().splitlines()[0].strip()
        raise InputFileError(
            path, f"line {first!r} reads as {times[0]:g} s: write times with a decimal point"
        )
    return times, downbeats


def _bar_downbeats(times: list[float], column: list[str]) -> list[float] | None:
    """The times whose ``column`` entry is 1, where that column counts the beats of each bar
    on every line: whole numbers 1 to `MAX_BAR_BEATS`, each one more than the last or a new
    bar's 1, with at least one new bar (the first bar may start part-way; a count that never
    starts again is a label's numbering); None where it is anything else."""
    if not all(c.isdecimal() for c in column):  # what int() reads (isdigit lets '²' by)
        return None
    counts = [int(c) for c in column]
    if 1 not in counts[1:] or min(counts) < 1 or max(counts) > MAX_BAR_BEATS:
        return None
    if any(b not in (1, a + 1) for a, b in itertools.pairwise(counts)):
        return None
    return [t for t, c in zip(times, counts, strict=True) if c == 1]


def _json_times(path: Path, text: str) -> tuple[list[float], list[float] | None]:
    """``beats_s`` and ``downbeats_s`` (None if absent) of a JSON beat file."""
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputFileError(
            path, f"not readable JSON ({exc.msg}, line {exc.lineno} column {exc.colno})"
        ) from None
    if not isinstance(data, dict) or "beats_s" not in data:
        raise InputFileError(path, 'a JSON beat file is an object with "beats_s", a list of s')
    downbeats = data.get("downbeats_s")
    return (
        _json_numbers(path, "beats_s", data["beats_s"]),
        None if downbeats is None else _json_numbers(path, "downbeats_s", downbeats),
    )


def _json_numbers(path: Path, key: str, values: Any) -> list[float]:
    if not isinstance(values, list):
        raise InputFileError(path, f"{key} is not a list of times in seconds")
    for i, v in enumerate(values):
        if isinstance(v, bool) or not isinstance(v, int | float):
            raise InputFileError(path, f"{key}[{i}] ({str(v)[:40]!r}) is not a number")
    return [float(v) for v in values]


def _check_times(path: Path, what: str, times: Sequence[float]) -> None:
    """One line for the first time that is not finite, is negative, or does not come after
    the one before."""
    for i, t in enumerate(times):
        if not math.isfinite(t):
            raise InputFileError(path, f"{what} {i + 1} ({t}) is not a finite number")
        if t < 0:
            raise InputFileError(path, f"{what} {i + 1} ({t:.3f} s) is negative")
        if i and t <= times[i - 1]:
            raise InputFileError(
                path,
                f"{what} {i + 1} ({t:.3f} s) is not after {what} {i} ({times[i - 1]:.3f} s); "
                "times must be strictly increasing",
            )


def _check_on_beats(path: Path, beats: Sequence[float], downbeats: Sequence[float]) -> None:
    """One line for the first downbeat that is not one of the beats."""
    beats_s = np.asarray(beats)
    for t in downbeats:
        nearest = float(beats_s[np.argmin(np.abs(beats_s - t))])
        if abs(nearest - t) > DOWNBEAT_ON_BEAT_S:
            raise InputFileError(
                path, f"downbeat {t:.3f} s is not one of the beats (nearest {nearest:.3f} s)"
            )
