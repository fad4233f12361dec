"""The offline analyser's beat decoder against the field's: its dynamic program, and a beat-pointer
HMM (madmom's ``DBNBeatTrackingProcessor`` model and settings) over the same envelope.

The analyser places beats with a dynamic program (Ellis 2007) that holds a tempo path it
measured first (`analysis._track_beats`). The field's offline trackers decode their activation
with an HMM that finds tempo and beats together (Krebs, Böck and Widmer 2015;
`benchmarks.bar_hmm` with one beat per bar). This analyses every song of the real-music sets
(tuning and held-out parts) and of each ``--also`` set twice, as shipped and with the HMM in
the DP's place, everything else the same: the envelope (learned activations mixed in), the
silence trim, the off-beat harmony test, the dance-range fold and the downbeats. The envelope
is no probability; the HMM sees it divided by its `ACTIVATION_PERCENTILE` and clipped to
[0, `MAX_ACTIVATION`]. Both decode on `analysis.AnalysisConfig.beat_steps_per_frame` steps per
frame. It measures a choice; nothing is tuned by it.

    python -m benchmarks.analyser_decoder [--also ROOT ...] [--jobs N] [--out FILE]
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.analyser_mix import analysis_scores, beatnet_once_per_speed
from benchmarks.bar_hmm import DecoderConfig, decode
from benchmarks.real_music import (
    REAL_SET_ROOTS,
    SPLITS,
    RealSong,
    load_audio_at,
    load_songs,
    run_as_script,
    score_sets,
    script_command,
    set_script_parser,
    write_set_results,
)
from quaddance.music import analysis

RESULTS = "benchmarks/results/analyser_decoder.json"
SR_HZ = 22050
FPS = SR_HZ / analysis.AnalysisConfig().hop_length
WAYS = ("dp", "hmm")
ACTIVATION_PERCENTILE = 99.0
"""The envelope's value that the HMM reads as a certain beat (the analyser's envelope has no
fixed scale: it is divided by its local level)."""
MAX_ACTIVATION = 0.95
"""The highest beat probability the HMM sees: below 1, so that every state stays possible."""
HMM = DecoderConfig(min_bpm=55.0, max_bpm=215.0, beats_per_bar=(1,), num_tempi=10_000)
"""madmom's ``DBNBeatTrackingProcessor`` defaults: 55-215 BPM, transition lambda 100,
observation lambda 16, every whole-step beat interval a tempo."""


def hmm_track_beats(
    onset: np.ndarray, period: np.ndarray, tightness: float, steps_per_frame: int = 1
) -> np.ndarray:
    """`analysis._track_beats`' contract, by the HMM: (n_beats,) increasing frames of ``onset``.
    ``period`` and ``tightness`` are the DP's and are not read: the HMM finds its own tempo."""
    del period, tightness
    if len(onset) == 0:
        return np.zeros(0, dtype=int)
    scale = max(float(np.percentile(onset, ACTIVATION_PERCENTILE)), 1e-9)
    p = np.clip(onset / scale, 0.0, MAX_ACTIVATION)
    fine = np.interp(np.arange(len(p) * steps_per_frame) / steps_per_frame, np.arange(len(p)), p)
    # With one beat per bar every beat is the bar's first, whose activation is column 1.
    act = np.stack([np.zeros_like(fine), fine], axis=1)
    steps = decode(act, FPS * steps_per_frame, HMM).beat_frames
    return np.unique(np.clip(np.round(steps / steps_per_frame).astype(int), 0, len(p) - 1))


@contextlib.contextmanager
def decoder(way: str) -> Iterator[None]:
    """While open, `analysis.analyze` places its beats with ``way``: "dp" (as shipped) or
    "hmm" (`hmm_track_beats`)."""
    if way not in WAYS:
        raise ValueError(f"unknown decoder {way!r}; choose from {', '.join(WAYS)}")
    shipped = analysis._track_beats
    if way == "hmm":
        analysis._track_beats = hmm_track_beats
    try:
        yield
    finally:
        analysis._track_beats = shipped


def score_song(song: RealSong) -> dict[str, dict[str, float]]:
    """The analyser's scores on ``song`` with each decoder."""
    y = np.asarray(load_audio_at(song, SR_HZ), dtype=np.float32)
    row = {}
    with beatnet_once_per_speed(y):
        for way in WAYS:
            with decoder(way):
                row[way] = analysis_scores(song, analysis.analyze(y, SR_HZ))
    print(song.name, {w: s["f_metrical"] for w, s in row.items()}, flush=True)
    return row


def summary(rows: list[dict[str, dict[str, float]]]) -> dict[str, Any]:
    """Mean scores each way, and the songs on which the HMM scores 0.01 or more below or
    above the DP (F at the metrical level)."""
    out: dict[str, Any] = {"n_songs": len(rows)}
    for way in WAYS:
        for key in ("f_metrical", "f", "downbeat_f"):
            values = [r[way][key] for r in rows]
            out[f"{key}_{way}"] = round(float(np.mean(values)), 4) if values else None
    diff = [r["hmm"]["f_metrical"] - r["dp"]["f_metrical"] for r in rows]
    out["hmm_lower"] = sum(d <= -0.01 for d in diff)
    out["hmm_higher"] = sum(d >= 0.01 for d in diff)
    return out


def run(roots: dict[str, Path], jobs: int = 1) -> dict[str, Any]:
    """Every song of ``roots`` (set name -> root), each split, in ``jobs`` processes; summaries
    per split."""
    by_set = {name: load_songs(root, SPLITS) for name, root in roots.items()}
    songs, splits = score_sets(by_set, score_song, jobs)
    return {
        "benchmark": "analyser_decoder",
        "metric": "the offline analyser's beat F (+-70 ms) at its metrical level and strict, and "
        "its downbeat F, with its DP (as shipped) and with a beat-pointer HMM in its place",
        "hmm": {
            "min_bpm": HMM.min_bpm,
            "max_bpm": HMM.max_bpm,
            "transition_lambda": HMM.transition_lambda,
            "observation_lambda": HMM.observation_lambda,
            "activation_percentile": ACTIVATION_PERCENTILE,
            "max_activation": MAX_ACTIVATION,
        },
        "summary": {s: summary(rows) for s, rows in splits.items()},
        "songs": songs,
    }


def main(argv: list[str] | None = None) -> None:
    parser = set_script_parser("benchmarks.analyser_decoder", __doc__, RESULTS, jobs=True)
    args = parser.parse_args(argv)
    result = run({**REAL_SET_ROOTS, **{root.name: root for root in args.also}}, args.jobs)
    extra = ["--jobs", str(args.jobs)] if args.jobs > 1 else []
    command = script_command("benchmarks.analyser_decoder", args.also, extra, args.out, RESULTS)
    write_set_results(command, args.out, result)


if __name__ == "__main__":
    run_as_script(main)
