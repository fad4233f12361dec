"""Fit the analyser's learned beat activation (`quaddance.music.beat_activation`).

It is fitted on the ``tuning`` songs of both real-music sets (``benchmarks/real_music`` and
``benchmarks/real_music_lmms``; build the second with ``apt-get install lmms gcc; python -m
benchmarks.real_music build --root benchmarks/real_music_lmms``), never on the held-out ones.
Each onset frame within one frame (23 ms) of a beat is a positive example, every other frame a
negative one, the two classes weighted equally (scikit-learn's logistic regression).

``--cross-validate`` measures the analyser (F at its metrical level, +-70 ms) with each
``--weights`` share of the activation, leaving one artist of the tuning songs out of the fit at
a time and scoring that artist's songs: how ``AnalysisConfig.activation_weight`` was first
chosen (it is now tuned with BeatNet's share, ``python -m benchmarks.analyser_mix``).

    python -m benchmarks.train_beat_activation [--out FILE] [--cross-validate]
"""

from __future__ import annotations

import argparse
import json
import tempfile
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from benchmarks.beats import beat_f_measure, metrical_level_f_measure
from benchmarks.real_music import (
    REAL_SET_ROOTS,
    RealSong,
    load_audio_at,
    load_songs,
    run_as_script,
)
from quaddance.fileio import write_json
from quaddance.music import analysis
from quaddance.music.beat_activation import (
    CONTEXT,
    BeatActivationModel,
    design_matrix,
    shipped_path,
)

MODULE = "benchmarks.train_beat_activation"
CV_RESULTS = "benchmarks/results/beat_activation_cv.json"
SR_HZ = 22050
FPS = SR_HZ / analysis.AnalysisConfig().hop_length
"""Onset frames per second of the analyser at ``SR_HZ``."""
REGULARISATION_C = 1.0
"""scikit-learn's default; the fit has 112 weights and about 200 000 frames."""


def frame_labels(beats_s: np.ndarray, fps: float, n_frames: int) -> np.ndarray:
    """(n_frames,) True at the frame nearest each beat and at its two neighbours."""
    labels = np.zeros(n_frames, dtype=bool)
    nearest = np.round(np.asarray(beats_s) * fps).astype(int)
    for d in (-1, 0, 1):
        at = nearest + d
        labels[at[(at >= 0) & (at < n_frames)]] = True
    return labels


def fit(
    rows: Sequence[np.ndarray], labels: Sequence[np.ndarray], names: Sequence[str]
) -> BeatActivationModel:
    """Fit the activation on songs' band rows (`analysis.activation_rows`) and frame labels."""
    from sklearn.linear_model import LogisticRegression  # librosa's dependency

    x = np.concatenate([design_matrix(r, CONTEXT) for r in rows])
    y = np.concatenate(labels)
    model = LogisticRegression(C=REGULARISATION_C, class_weight="balanced", max_iter=1000)
    model.fit(x, y)
    return BeatActivationModel(
        weights=model.coef_[0].astype(float),
        bias=float(model.intercept_[0]),
        context=CONTEXT,
        trained_on=tuple(names),
        regularisation_c=REGULARISATION_C,
    )


def tuning_songs() -> list[RealSong]:
    """The tuning songs of every real-music set."""
    return [s for root in REAL_SET_ROOTS.values() for s in load_songs(root, ("tuning",))]


def _artist(song: RealSong) -> str:
    return song.artist.split("(")[0].strip()


def _score(song: RealSong, y: np.ndarray, cfg: analysis.AnalysisConfig) -> tuple[float, float]:
    beats_s = analysis.analyze(y, SR_HZ, cfg).beats_s
    return (
        metrical_level_f_measure(song.beats_s, beats_s),
        beat_f_measure(song.beats_s, beats_s),
    )


def _inputs(
    songs: list[RealSong], audio: dict[str, np.ndarray]
) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Each song's band rows (`analysis.activation_rows`) and frame labels, by name."""
    rows = {s.name: analysis.activation_rows(audio[s.name], SR_HZ) for s in songs}
    labels = {s.name: frame_labels(s.beats_s, FPS, rows[s.name].shape[1]) for s in songs}
    return rows, labels


def cross_validate(
    songs: list[RealSong], audio: dict[str, np.ndarray], weights: Sequence[float]
) -> dict[str, dict[str, float]]:
    """Mean F (metrical level and strict) of the analyser over ``songs`` for each activation
    weight, each artist's songs scored with a model fitted without that artist."""
    rows, labels = _inputs(songs, audio)
    scores: dict[float, list[tuple[float, float]]] = {w: [] for w in weights}
    with tempfile.TemporaryDirectory() as tmp:
        for k, artist in enumerate(sorted({_artist(s) for s in songs})):
            train = [s.name for s in songs if _artist(s) != artist]
            path = Path(tmp) / f"fold{k}.json"  # its own file: `load_model` caches by path
            fit([rows[n] for n in train], [labels[n] for n in train], train).save(path)
            for song in (s for s in songs if _artist(s) == artist):
                for w in weights:
                    cfg = analysis.AnalysisConfig(activation_weight=w, activation_model=path)
                    scores[w].append(_score(song, audio[song.name], cfg))
                print(f"{artist}: {song.name} done", flush=True)
    return {
        f"{w:g}": {
            "f_metrical": round(float(np.mean([s[0] for s in v])), 4),
            "f": round(float(np.mean([s[1] for s in v])), 4),
        }
        for w, v in scores.items()
    }


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog=f"python -m {MODULE}", description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, default=shipped_path(), help="model file to write")
    parser.add_argument("--cross-validate", action="store_true", help="score weights, fit nothing")
    parser.add_argument("--weights", type=float, nargs="+", default=[0.0, 0.3, 0.5, 0.7, 1.0])
    parser.add_argument("--cv-out", type=Path, default=Path(CV_RESULTS), help="its results")
    args = parser.parse_args(argv)
    songs = tuning_songs()
    audio = {s.name: load_audio_at(s, SR_HZ) for s in songs}
    if args.cross_validate:
        scores = cross_validate(songs, audio, args.weights)
        write_json(
            args.cv_out,
            {
                "benchmark": "beat_activation_cv",
                "command": f"python -m {MODULE} --cross-validate",
                "metric": "mean beat F of the analyser, +-70 ms, metrical level and strict; "
                "each artist scored with a model fitted without that artist",
                "songs": [s.name for s in songs],
                "by_activation_weight": scores,
            },
        )
        print(json.dumps(scores, indent=1))
        print(f"wrote {args.cv_out}")
        return
    rows, labels = _inputs(songs, audio)
    names = [s.name for s in songs]
    fit([rows[n] for n in names], [labels[n] for n in names], names).save(args.out)
    print(f"wrote {args.out} (fitted on {len(songs)} tuning songs)")


if __name__ == "__main__":
    run_as_script(main)
