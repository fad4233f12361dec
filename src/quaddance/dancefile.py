"""The ``dance.npz`` hand-off between choreography and the robot (training, playback).

One compressed numpy archive, no pickles: numbers are arrays and strings are 0-d unicode
arrays, so it loads with ``allow_pickle=False``. Keys:

=============  ===========  =====================================================
key            shape        meaning
=============  ===========  =====================================================
fps            ()           sample rate of the three curves below, Hz
time_s         (T,)         sample times, s
human_feet_m   (T, 2)       human left, right foot heights above the floor, m
targets_m      (T, 4)       robot FL, FR, RL, RR foot-height targets, m
beats_s        (B,)         beat times of the music, s (may be empty)
downbeats_s    (D,)         downbeat times, s (may be empty)
mode           () unicode   target mode: feasible, paper or minmax
source         () unicode   where the dance came from (song or motion file)
seed           () int       choreographer seed
version        () unicode   quaddance version that wrote the file
=============  ===========  =====================================================
"""

from __future__ import annotations

import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from quaddance.errors import InputFileError
from quaddance.fileio import atomic_path

KEYS: tuple[str, ...] = (
    "fps",
    "time_s",
    "human_feet_m",
    "targets_m",
    "beats_s",
    "downbeats_s",
    "mode",
    "source",
    "seed",
    "version",
)
_STRING_KEYS = ("mode", "source", "version")


@dataclass
class Dance:
    """A dance ready for the robot; curves share ``time_s`` (T,) at ``fps`` Hz.

    Attributes:
        fps: sample rate, Hz.
        time_s: (T,) sample times, s.
        human_feet_m: (T, 2) human (left, right) foot heights, m.
        targets_m: (T, 4) robot (FL, FR, RL, RR) foot-height targets, m.
        beats_s: (B,) beat times, s.
        downbeats_s: (D,) downbeat times, s.
        mode: target mode used (see `quaddance.targets`).
        source: where the dance came from.
        seed: choreographer seed.
        version: quaddance version that made it.
    """

    fps: float
    time_s: np.ndarray
    human_feet_m: np.ndarray
    targets_m: np.ndarray
    beats_s: np.ndarray
    downbeats_s: np.ndarray
    mode: str
    source: str
    seed: int
    version: str

    @property
    def duration_s(self) -> float:
        """Length of the dance, s."""
        return self.time_s.size / self.fps


def save_dance(path: str | Path, dance: Dance) -> None:
    """Write ``dance`` to ``path`` (a ``.npz``), atomically."""
    arrays: dict[str, np.ndarray] = {
        "fps": np.float64(dance.fps),
        "time_s": np.asarray(dance.time_s, dtype=np.float64),
        "human_feet_m": np.asarray(dance.human_feet_m, dtype=np.float64),
        "targets_m": np.asarray(dance.targets_m, dtype=np.float64),
        "beats_s": np.asarray(dance.beats_s, dtype=np.float64).reshape(-1),
        "downbeats_s": np.asarray(dance.downbeats_s, dtype=np.float64).reshape(-1),
        "seed": np.int64(dance.seed),
    }
    for key in _STRING_KEYS:
        arrays[key] = np.array(str(getattr(dance, key)), dtype=np.str_)
    with atomic_path(path) as tmp, tmp.open("wb") as fh:
        # Writing through a handle stops numpy from appending ".npz" to the temp name.
        np.savez_compressed(fh, **arrays)


def load_dance(path: str | Path) -> Dance:
    """Read and check a ``dance.npz``; raise `InputFileError` naming what is wrong."""
    path = Path(path)
    if not path.is_file():
        raise InputFileError(path, "no such file")
    try:
        loaded = np.load(path, allow_pickle=False)
        if not isinstance(loaded, np.lib.npyio.NpzFile):
            raise InputFileError(path, "not a dance file (a single .npy array, not an .npz)")
        with loaded as npz:
            missing = [key for key in KEYS if key not in npz.files]
            if missing:
                raise InputFileError(path, f"not a dance file: missing {', '.join(missing)}")
            raw = {key: npz[key] for key in KEYS}
    except InputFileError:
        raise
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as err:
        raise InputFileError(path, f"cannot read as a dance .npz ({err})") from None
    return _check(path, raw)


def _check(path: Path, raw: dict[str, np.ndarray]) -> Dance:
    """Validate the arrays of a dance file and build the `Dance`."""

    def number(key: str, kind: str) -> np.ndarray:
        arr = raw[key]
        if arr.shape != () or arr.dtype.kind not in kind:
            raise InputFileError(
                path, f"{key} must be a single number, got {arr.dtype} {arr.shape}"
            )
        if not np.isfinite(arr):
            raise InputFileError(path, f"{key} is not finite")
        return arr

    def text(key: str) -> str:
        arr = raw[key]
        if arr.shape != () or arr.dtype.kind != "U":
            raise InputFileError(path, f"{key} must be a text value, got {arr.dtype} {arr.shape}")
        return str(arr)

    def curve(key: str, ndim: int) -> np.ndarray:
        arr = raw[key]
        if arr.ndim != ndim or arr.dtype.kind not in "fiu":
            raise InputFileError(path, f"{key} must be a {ndim}-D numeric array, got {arr.shape}")
        if not np.all(np.isfinite(arr)):
            raise InputFileError(path, f"{key} contains NaN or infinite values")
        return arr.astype(np.float64)

    fps = float(number("fps", "fiu"))
    if fps <= 0:
        raise InputFileError(path, f"fps must be > 0, got {fps}")
    time_s = curve("time_s", 1)
    n = time_s.size
    if n == 0:
        raise InputFileError(path, "time_s is empty")
    if n > 1 and not np.all(np.diff(time_s) > 0):
        raise InputFileError(path, "time_s is not increasing")
    human = curve("human_feet_m", 2)
    if human.shape != (n, 2):
        raise InputFileError(path, f"human_feet_m must have shape ({n}, 2), got {human.shape}")
    targets = curve("targets_m", 2)
    if targets.shape != (n, 4):
        raise InputFileError(path, f"targets_m must have shape ({n}, 4), got {targets.shape}")
    return Dance(
        fps=fps,
        time_s=time_s,
        human_feet_m=human,
        targets_m=targets,
        beats_s=curve("beats_s", 1),
        downbeats_s=curve("downbeats_s", 1),
        mode=text("mode"),
        source=text("source"),
        seed=int(number("seed", "iu")),
        version=text("version"),
    )
