"""Score the online tracker's use of BeatNet, how far a held grid follows its onsets, how far
the score must jump for the grid to be held, and BeatNet's vote on the phase, on songs outside
the held-out parts.

The online tracker's onset envelopes take in BeatNet's causal activation
(`online_beats.BEATNET_WEIGHT`, the stream heard at each of `online_beats.BEATNET_STRETCHES`
speeds), a held grid moves towards its own onsets (`online_beats.HOLD_FOLLOW`), and BeatNet's
activation summed at the beats and at their midpoints moves the grid half a beat
(`online_beats.OFFBEAT_VOTE_RATIO`); a jump of the score by `online_beats.PHASE_JUMP_BEATS`
of a beat or more is held. This scores a grid of the five by the tracker's beat F
(+-70 ms, at its metrical level and strict) after its first lock, its lock time and its CPU
share, the tracker fed each file at full speed as ``bench live`` feeds it (`live.track_file`),
on the tuning songs of both real-music sets and on those of every set given with ``--also``
(e.g. the ``benchmarks/real_music_fit`` set of commit f53a2e1). Held-out songs are never read.

    python -m benchmarks.online_mix [--also ROOT ...] [--mix NAME ...] [--out FILE]
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
from benchmarks.real_music import REAL_SET_ROOTS, RealSong, load_songs, run_as_script
from quaddance.music import analysis, live, online_beats

MODULE = "benchmarks.online_mix"
RESULTS = "benchmarks/results/online_mix.json"
FIVE = analysis.AnalysisConfig().beatnet_stretches
"""The speeds the offline analyser hears the song at."""
THREE = (0.93, 1.0, 1.07)


CONSTANTS = {
    "beatnet_weight": "BEATNET_WEIGHT",
    "beatnet_stretches": "BEATNET_STRETCHES",
    "hold_follow": "HOLD_FOLLOW",
    "offbeat_vote": "OFFBEAT_VOTE_RATIO",
    "phase_jump": "PHASE_JUMP_BEATS",
}
"""Each field of a `Mix` and the online tracker's module constant it sets."""
LABELS = {"hold_follow": "follow", "offbeat_vote": "vote", "phase_jump": "jump"}
"""How a mix's name says a field that differs from the tracker's default."""


@dataclass(frozen=True)
class Mix:
    beatnet_weight: float
    beatnet_stretches: tuple[float, ...] = (1.0,)
    hold_follow: float = online_beats.HOLD_FOLLOW
    offbeat_vote: float = online_beats.OFFBEAT_VOTE_RATIO
    """Infinite (the default): no vote."""
    phase_jump: float = online_beats.PHASE_JUMP_BEATS

    @property
    def name(self) -> str:
        name = tuning_grid.beatnet_name(self.beatnet_weight, self.beatnet_stretches)
        for field, label in LABELS.items():
            value = getattr(self, field)
            if value != getattr(online_beats, CONSTANTS[field]):
                name += f", {label} {value:g}"
        return name

    @contextlib.contextmanager
    def applied(self) -> Iterator[None]:
        """The tracker reads this mix while the block runs (its module constants)."""
        before = {c: getattr(online_beats, c) for c in CONSTANTS.values()}
        for field, constant in CONSTANTS.items():
            setattr(online_beats, constant, getattr(self, field))
        try:
            yield
        finally:
            for constant, value in before.items():
                setattr(online_beats, constant, value)


MIXES = (
    Mix(0.5),
    Mix(0.75),
    Mix(0.5, THREE),
    Mix(0.6, THREE),
    Mix(0.5, FIVE),
    Mix(0.75, FIVE),
    Mix(0.5, hold_follow=0.5),
    Mix(0.5, hold_follow=0.0),
    Mix(0.5, offbeat_vote=2.0),
    Mix(0.5, offbeat_vote=3.0),
    Mix(0.5, phase_jump=0.25),
    Mix(0.5, phase_jump=0.2),
    Mix(0.5, phase_jump=0.1),
)
"""The grid: the default (BeatNet's share 0.5, heard once), a larger share, the song heard
at three and at five speeds (the offline analyser's), a held grid that moves half of the
way to its onsets, or not at all, BeatNet's vote on the phase at two ratios, and other
jumps of the score that the grid holds against."""


def score(song: RealSong, mix: Mix) -> dict[str, Any]:
    with mix.applied():
        track = live.track_file(song.audio_path)
    lock_s = track.first_lock_s()
    after = song.duration_s if lock_s is None else lock_s
    ref, beats = song.beats_s[song.beats_s >= after], track.beats_s[track.beats_s >= after]
    return {
        "f_metrical": round(metrical_level_f_measure(ref, beats), 4),
        "f": round(beat_f_measure(ref, beats), 4),
        "lock_s": None if lock_s is None else round(lock_s, 3),
        "cpu_per_audio_s": round(track.tracker_s / song.duration_s, 4),
    }


def means(rows: list[dict[str, Any]]) -> dict[str, float]:
    out = {k: round(float(np.mean([r[k] for r in rows])), 4) for k in ("f_metrical", "f")}
    locked = [r["lock_s"] is not None and r["lock_s"] <= 6.0 for r in rows]
    out["lock_within_6_s"] = round(float(np.mean(locked)), 4)
    out["cpu_per_audio_s"] = round(float(np.mean([r["cpu_per_audio_s"] for r in rows])), 4)
    return out


def run(sets: dict[str, Path], mixes: tuple[Mix, ...]) -> dict[str, Any]:
    """Each mix's scores per song and their means per set, tuning songs only."""
    names = [m.name for m in mixes]
    return tuning_grid.run(
        sets, names, lambda song: {m.name: score(song, m) for m in mixes}, means, load_songs
    )


def main(argv: list[str] | None = None) -> None:
    tuning_grid.main(
        argv,
        module=MODULE,
        doc=__doc__,
        results=RESULTS,
        metric="mean over songs of the online tracker's beat F (+-70 ms) at its metrical "
        "level and strict after its first lock, the share of songs locked within 6 s and "
        "its CPU time per second of audio; tuning songs only",
        roots=REAL_SET_ROOTS,
        mix_names=[m.name for m in MIXES],
        grid=lambda sets, names: run(sets, tuple(m for m in MIXES if m.name in names)),
    )


if __name__ == "__main__":
    run_as_script(main)
