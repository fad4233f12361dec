"""Score the offline analyser's mix of learned activations (and its beat tracker's stiffness) on
songs outside the held-out parts.

The analyser's onset envelopes take in two learned beat activations: its own
(`AnalysisConfig.activation_weight`) and BeatNet's (`beatnet_weight`, the song heard at each of
`beatnet_stretches`). This scores a grid of the three by the analyser's beat F (+-70 ms, at its
metrical level and strict) and downbeat F, on the tuning songs of both real-music sets (its own
activation is fitted on them: in-sample there) and on the tuning songs of every set given with
``--also`` (one built as the real-music sets are, e.g. the ``benchmarks/real_music_fit`` set of
commit f53a2e1: 60 game-music songs that no model was fitted on). Held-out songs are never
read.

    python -m benchmarks.analyser_mix [--also ROOT ...] [--mix NAME ...] [--out FILE]
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks import tuning_grid
from benchmarks.beats import beat_f_measure, metrical_level_f_measure
from benchmarks.real_music import (
    REAL_SET_ROOTS,
    RealSong,
    downbeat_f,
    load_audio_at,
    load_songs,
    run_as_script,
)
from quaddance.music import analysis, beatnet

MODULE = "benchmarks.analyser_mix"
RESULTS = "benchmarks/results/analyser_mix.json"
SR_HZ = 22050
FIVE = (0.9, 0.93, 1.0, 1.07, 1.1)
SEVEN = (0.85, *FIVE, 1.15)
NINE = (0.85, 0.9, 0.93, 0.96, 1.0, 1.04, 1.07, 1.1, 1.15)


SHIPPED = analysis.AnalysisConfig()
STEP_NAMES = {1: "whole", 2: "half", 4: "quarter"}


@dataclass(frozen=True)
class Mix:
    activation_weight: float
    beatnet_weight: float
    beatnet_stretches: tuple[float, ...] = (1.0,)
    gain_db: float = 0.0  # the song heard this much quieter: the analysis should not care
    tightness: float = SHIPPED.tightness
    beat_steps_per_frame: int = SHIPPED.beat_steps_per_frame

    @property
    def name(self) -> str:
        beatnet = tuning_grid.beatnet_name(self.beatnet_weight, self.beatnet_stretches)
        level = f", at {self.gain_db:g} dB" if self.gain_db else ""
        dp = (self.tightness, self.beat_steps_per_frame)
        beats = "" if dp == (SHIPPED.tightness, SHIPPED.beat_steps_per_frame) else (
            f", tightness {dp[0]:g} on {STEP_NAMES.get(dp[1], f'1/{dp[1]}')} frames"
        )  # fmt: skip
        return f"own {self.activation_weight:g}, {beatnet}{level}{beats}"

    def config(self) -> analysis.AnalysisConfig:
        return analysis.AnalysisConfig(
            activation_weight=self.activation_weight,
            beatnet_weight=self.beatnet_weight,
            beatnet_stretches=self.beatnet_stretches,
            tightness=self.tightness,
            beat_steps_per_frame=self.beat_steps_per_frame,
        )


MIXES = (
    Mix(0.5, 0.5),
    Mix(0.5, 0.5, FIVE),
    Mix(0.5, 1.0),
    Mix(0.5, 1.0, FIVE),
    Mix(0.25, 0.5, FIVE),
    Mix(0.25, 0.75),
    Mix(0.25, 0.75, FIVE),
    Mix(0.1, 0.75, FIVE),
    Mix(0.4, 0.75, FIVE),
    Mix(0.25, 0.65, FIVE),
    Mix(0.25, 0.85, FIVE),
    Mix(0.25, 0.75, SEVEN),
    Mix(0.25, 0.75, NINE),
    Mix(0.25, 0.75, FIVE, gain_db=-6.0),
    Mix(0.25, 0.75, FIVE, tightness=1000.0, beat_steps_per_frame=1),
    Mix(0.25, 0.75, FIVE, tightness=3000.0, beat_steps_per_frame=1),
    Mix(0.25, 0.75, FIVE, tightness=1000.0, beat_steps_per_frame=2),
    Mix(0.25, 0.75, FIVE, tightness=6000.0, beat_steps_per_frame=2),
    Mix(0.25, 0.75, FIVE, tightness=10000.0, beat_steps_per_frame=2),
    Mix(0.25, 0.75, FIVE, tightness=3000.0, beat_steps_per_frame=4),
)
"""The grid: the shares that shipped before, BeatNet alone, and the neighbours of the default
(own 0.25, BeatNet 0.75 heard at five speeds) in each setting, its speeds among them; and the
default with the song 6 dB quieter (what a file's level does to the analysis); and the default
mix with the beat tracker's dynamic program at other tightnesses and steps per frame (the
shipped one is 3000 on half frames; 1000 on whole frames shipped before)."""


def score(song: RealSong, y: np.ndarray, mix: Mix) -> dict[str, float]:
    heard = y if not mix.gain_db else (y * np.float32(10 ** (mix.gain_db / 20))).astype(y.dtype)
    return analysis_scores(song, analysis.analyze(heard, SR_HZ, mix.config()))


def analysis_scores(song: RealSong, a: analysis.Analysis) -> dict[str, float]:
    """The analysis ``a`` of ``song`` scored: beat F (+-70 ms) at its metrical level and
    strict, and downbeat F."""
    return {
        "f_metrical": round(metrical_level_f_measure(song.beats_s, a.beats_s), 4),
        "f": round(beat_f_measure(song.beats_s, a.beats_s), 4),
        "downbeat_f": downbeat_f(song, a.downbeats_s),
    }


@contextlib.contextmanager
def beatnet_once_per_speed(y: np.ndarray) -> Iterator[None]:
    """While the mixes score song ``y``, the network hears it once at each speed: the
    analyser's calls of `beatnet.beat_activation` on it are answered from a cache (the mixes
    share their speeds; this makes the grid about five times quicker)."""
    network, cache = beatnet.beat_activation, {}

    def cached(audio: np.ndarray, sr: int, stretch: float = 1.0) -> np.ndarray:
        if audio is not y:
            return network(audio, sr, stretch)
        if (sr, stretch) not in cache:
            cache[sr, stretch] = network(audio, sr, stretch)
        return cache[sr, stretch]

    beatnet.beat_activation = cached
    try:
        yield
    finally:
        beatnet.beat_activation = network


def score_song(song: RealSong, mixes: tuple[Mix, ...]) -> dict[str, dict[str, float]]:
    """Each mix's scores on ``song``."""
    # float32, as the analyser reads it: the same array reaches the network
    y = np.asarray(load_audio_at(song, SR_HZ), dtype=np.float32)
    with beatnet_once_per_speed(y):
        return {mix.name: score(song, y, mix) for mix in mixes}


def means(rows: list[dict[str, float]]) -> dict[str, float]:
    return {k: round(float(np.mean([r[k] for r in rows])), 4) for k in rows[0]}


def run(sets: dict[str, Path], mixes: tuple[Mix, ...]) -> dict[str, Any]:
    """Each mix's scores per song and their means per set, tuning songs only."""
    names = [m.name for m in mixes]
    return tuning_grid.run(sets, names, lambda s: score_song(s, mixes), means, load_songs)


def main(argv: list[str] | None = None) -> None:
    tuning_grid.main(
        argv,
        module=MODULE,
        doc=__doc__,
        results=RESULTS,
        metric="mean over songs of the analyser's beat F (+-70 ms) at its metrical "
        "level and strict, and its downbeat F; tuning songs only",
        roots=REAL_SET_ROOTS,
        mix_names=[m.name for m in MIXES],
        grid=lambda sets, names: run(sets, tuple(m for m in MIXES if m.name in names)),
    )


if __name__ == "__main__":
    run_as_script(main)
