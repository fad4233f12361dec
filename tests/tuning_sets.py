"""Two sets of code-made songs that stand in for the real-music sets in the tests of the tuning
grids (``benchmarks.analyser_mix``, ``benchmarks.online_mix``): each set has one tuning song and
one held-out song, which a grid must never read."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from benchmarks.real_music import RealSong
from quaddance.music.synth import render_song


@dataclass
class CodeMadeSets:
    sets: dict[Path, list[RealSong]]
    audio: dict[str, np.ndarray]  # by song name

    @property
    def roots(self) -> dict[str, Path]:
        """In place of `real_music.REAL_SET_ROOTS`."""
        a, b = self.sets
        return {"real": a, "real-lmms": b}

    def load_songs(self, root: Path, splits: tuple[str, ...]) -> list[RealSong]:
        """In place of `real_music.load_songs`."""
        return [s for s in self.sets[root] if s.split in splits]


def code_made_sets(tmp_path: Path, duration_s: float, write_wav: bool = False) -> CodeMadeSets:
    """Sets ``a`` (100 BPM) and ``b`` (128 BPM) under ``tmp_path``, songs named
    ``<set>_tuning`` and ``<set>_heldout``; their audio written as wav where ``write_wav``."""
    import soundfile as sf

    audio: dict[str, np.ndarray] = {}
    sets: dict[Path, list[RealSong]] = {}
    for k, (root, tempo) in enumerate(((tmp_path / "a", 100.0), (tmp_path / "b", 128.0))):
        sets[root] = []
        for split in ("tuning", "heldout"):
            y, truth = render_song(tempo, duration_s, seed=k)
            name = f"{root.name}_{split}"
            audio[name] = y
            path = root / f"{name}.wav"
            if write_wav:
                root.mkdir(exist_ok=True)
                sf.write(path, y, 22050)
            sets[root].append(
                RealSong(name, name, "A", split, "recording", path, truth.beats_s,
                         truth.downbeats_s, (tempo, tempo), "4/4", "MIT", duration_s)
            )  # fmt: skip
    return CodeMadeSets(sets, audio)
