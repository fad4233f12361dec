"""Whether each special rule of the online beat tracker pays for itself, song by song.

The online tracker (`music.online_beats`) keeps rules beyond its tempo filter and beat score:
the three-four test, the backbeat test, the swing test, the metrical-level hold and the fast
tempo re-estimate after a change. This tracks every song of the real-music sets (tuning and
held-out parts) and of each ``--also`` set as ``bench beats --sets real`` does (decoded and
tracked as `track_file` does), with the tracker as it ships and with each rule switched off in
turn, and reports its F at the metrical level after its lock, and its lock time. It measures
rules that stay; nothing is tuned by it.

    python -m benchmarks.online_rules [--also ROOT ...] [--rule NAME ...] [--jobs N] [--out FILE]
"""

from __future__ import annotations

import contextlib
import functools
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.beats import metrical_level_f_measure
from benchmarks.real_music import (
    REAL_SET_ROOTS,
    SPLITS,
    RealSong,
    load_songs,
    run_as_script,
    score_sets,
    script_command,
    set_script_parser,
    write_set_results,
)
from quaddance.music import online_beats
from quaddance.music.live import FileSource, track_samples
from quaddance.music.online_beats import SR_HZ

RESULTS = "benchmarks/results/online_rules.json"

RULES_OFF: dict[str, dict[str, Any]] = {
    "three-four test": {"THREE_FOUR_VOTES": 10**9},
    "backbeat test": {"MAX_DOUBLED_BPM": 0.0},
    "swing test": {"SWING_SHIFT_RANGE": (2.0, 2.0)},
    "metrical-level hold": {"HELD_LEVEL_RATIOS": ()},
    "fast tempo re-estimate": {"FAST_MISSES": 10**9},
}
"""Each rule by name, and the constants of `music.online_beats` that switch it off: a vote count
never reached, a doubled tempo always too fast, a swing shift outside any beat, no level held,
misses never counted."""
SHIPPED = "as shipped"


@contextlib.contextmanager
def rule_off(name: str) -> Iterator[None]:
    """The tracker with rule ``name`` switched off (`RULES_OFF`); ``SHIPPED``: as it ships."""
    saved = {}
    try:
        for constant, value in RULES_OFF.get(name, {}).items():
            saved[constant] = getattr(online_beats, constant)
            setattr(online_beats, constant, value)
        yield
    finally:
        for constant, value in saved.items():
            setattr(online_beats, constant, value)


def decode(song: RealSong) -> np.ndarray:
    """The song's audio as ``bench beats --sets real`` hands it to the tracker (`track_file`
    decodes it so), once for all the ways it is tracked."""
    return FileSource(song.audio_path, realtime=False).y


def score(song: RealSong, y: np.ndarray) -> dict[str, float | None]:
    """The online tracker's F at the metrical level after its lock (0 without one) and its lock
    time on ``y`` (`decode`), as ``bench beats --sets real`` scores it."""
    track = track_samples(y, SR_HZ)
    lock_s = track.first_lock_s()
    if lock_s is None:
        return {"f_metrical": 0.0, "lock_s": None}
    ref, est = song.beats_s, track.beats_s
    f = metrical_level_f_measure(ref[ref >= lock_s], est[est >= lock_s])
    return {"f_metrical": round(f, 4), "lock_s": round(lock_s, 3)}


def summary(rows: list[dict[str, Any]], rules: list[str]) -> dict[str, Any]:
    """Per way of running: the mean F, the songs locked within 6 s, and the songs whose F moved
    by more than 0.02 against the shipped tracker, up and down."""
    out: dict[str, Any] = {"n_songs": len(rows)}
    for rule in [SHIPPED, *rules]:
        f = np.array([r[rule]["f_metrical"] for r in rows])
        base = np.array([r[SHIPPED]["f_metrical"] for r in rows])
        locks = [r[rule]["lock_s"] for r in rows]
        out[rule] = {
            "f_metrical": round(float(f.mean()), 4) if rows else None,
            "locked_within_6s": sum(1 for s in locks if s is not None and s <= 6.0),
            "songs_up": int(np.sum(f > base + 0.02)),
            "songs_down": int(np.sum(f < base - 0.02)),
        }
    return out


def score_ways(song: RealSong, rules: list[str]) -> dict[str, dict[str, float | None]]:
    """`score` of ``song`` as shipped and with each of ``rules`` off."""
    y = decode(song)
    row = {}
    for rule in [SHIPPED, *rules]:
        with rule_off(rule):
            row[rule] = score(song, y)
    print(song.name, {r: v["f_metrical"] for r, v in row.items()}, flush=True)
    return row


def run(roots: dict[str, Path], rules: list[str], jobs: int = 1) -> dict[str, Any]:
    """Every song of ``roots`` (set name -> root), each split, each way, in ``jobs`` processes;
    summaries per split."""
    by_set = {name: load_songs(root, SPLITS) for name, root in roots.items()}
    songs, splits = score_sets(by_set, functools.partial(score_ways, rules=rules), jobs)
    return {
        "benchmark": "online_rules",
        "metric": "the online tracker's beat F (+-70 ms) at its metrical level after its first "
        "lock (0 without a lock), as shipped and with each rule off",
        "rules_off": {r: {k: repr(v) for k, v in RULES_OFF[r].items()} for r in rules},
        "summary": {s: summary(rows, rules) for s, rows in splits.items()},
        "songs": songs,
    }


def main(argv: list[str] | None = None) -> None:
    parser = set_script_parser("benchmarks.online_rules", __doc__, RESULTS, jobs=True)
    parser.add_argument(
        "--rule", action="append", choices=list(RULES_OFF), help="only this rule (repeatable)"
    )
    args = parser.parse_args(argv)
    rules = args.rule or list(RULES_OFF)
    result = run({**REAL_SET_ROOTS, **{root.name: root for root in args.also}}, rules, args.jobs)
    flags = [f for rule in args.rule or () for f in ("--rule", rule)]
    if args.jobs > 1:  # the same results, sooner
        flags += ["--jobs", str(args.jobs)]
    command = script_command("benchmarks.online_rules", args.also, flags, args.out, RESULTS)
    write_set_results(command, args.out, result)


if __name__ == "__main__":
    run_as_script(main)
