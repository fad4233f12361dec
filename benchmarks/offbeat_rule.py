"""Whether the offline analyser's off-beat harmony test pays for itself, song by song.

`analysis.offbeat_harmony` moves all of a song's beats by half a beat when its bass line
changes pitch far more often between the beats than at them. This analyses every song of the
real-music sets (tuning and held-out parts) and of each ``--also`` set with the analyser as it
ships and, on the songs where the test fires, again with the test off
(``offbeat_harmony_ratio`` = inf; elsewhere the two analyses are the same by construction), and
reports the analyser's beat F at its metrical level and its downbeat F both ways. It measures a
rule that stays; nothing is tuned by it.

    python -m benchmarks.offbeat_rule [--also ROOT ...] [--out FILE]
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.analyser_mix import beatnet_once_per_speed
from benchmarks.beats import metrical_level_f_measure
from benchmarks.real_music import (
    REAL_SET_ROOTS,
    SPLITS,
    RealSong,
    downbeat_f,
    load_audio_at,
    load_songs,
    run_as_script,
    score_sets,
    script_command,
    set_script_parser,
    write_set_results,
)
from quaddance.music import analysis

RESULTS = "benchmarks/results/offbeat_rule.json"
SR_HZ = 22050
RULE_OFF = dataclasses.replace(analysis.AnalysisConfig(), offbeat_harmony_ratio=float("inf"))


def _scores(song: RealSong, a: analysis.Analysis) -> dict[str, float]:
    return {
        "f_metrical": round(metrical_level_f_measure(song.beats_s, a.beats_s), 4),
        "downbeat_f": downbeat_f(song, a.downbeats_s),
    }


def score_song(song: RealSong) -> dict[str, Any]:
    """The shipped analyser's scores on ``song``, whether the test fired, and where it did,
    the scores with the test off."""
    y = np.asarray(load_audio_at(song, SR_HZ), dtype=np.float32)
    with beatnet_once_per_speed(y):
        shipped = analysis.analyze(y, SR_HZ)
        fired = bool(shipped.extra["offbeat_shift"])
        without = analysis.analyze(y, SR_HZ, RULE_OFF) if fired else shipped
    row = {"fired": fired, "with": _scores(song, shipped), "without": _scores(song, without)}
    print(song.name, row, flush=True)
    return row


def summary(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """How many songs, on how many the test fired, and the mean scores with and without it."""
    out: dict[str, Any] = {"n_songs": len(rows), "n_fired": sum(r["fired"] for r in rows)}
    for way in ("with", "without"):
        for key in ("f_metrical", "downbeat_f"):
            values = [r[way][key] for r in rows]
            out[f"{key}_{way}"] = round(float(np.mean(values)), 4) if values else None
    return out


def run(roots: dict[str, Path]) -> dict[str, Any]:
    """Every song of ``roots`` (set name -> root), each split; summaries per split."""
    by_set = {name: load_songs(root, SPLITS) for name, root in roots.items()}
    songs, splits = score_sets(by_set, score_song)
    return {
        "benchmark": "offbeat_rule",
        "metric": "the offline analyser's beat F (+-70 ms) at its metrical level and downbeat F, "
        "with the off-beat harmony test (as shipped) and without it",
        "summary": {s: summary(rows) for s, rows in splits.items()},
        "fired": sorted(k for k, r in songs.items() if r["fired"]),
        "songs": songs,
    }


def main(argv: list[str] | None = None) -> None:
    args = set_script_parser("benchmarks.offbeat_rule", __doc__, RESULTS).parse_args(argv)
    result = run({**REAL_SET_ROOTS, **{root.name: root for root in args.also}})
    command = script_command("benchmarks.offbeat_rule", args.also, [], args.out, RESULTS)
    write_set_results(command, args.out, result)


if __name__ == "__main__":
    run_as_script(main)
