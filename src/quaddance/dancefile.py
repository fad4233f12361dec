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
body_targets   (T, 4)       trunk height offset m, roll, pitch, yaw rad (format 2;
                            missing in format 1 files: read as zeros)
robot          () unicode   the robot the dance was made for, a key of
                            `quaddance.robots.ROBOTS` (format 3; missing in older
                            files: read as the Go1)
format         () int       dance format: 3 (missing in format 1 files)
=============  ===========  =====================================================

A dance is for one robot: its targets keep to that robot's limits. `load_dance` with a
``robot`` refuses a dance made for another.

`Dance.clamp_report` (what feasible mode clamped, from `quaddance.pipeline.compose`) is
not stored.
"""

from __future__ import annotations

import struct
import tokenize
import zipfile
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from quaddance.errors import InputFileError, not_a_file
from quaddance.fileio import atomic_path
from quaddance.layout import MODES, N_BODY, N_PAWS
from quaddance.robots import GO1, ROBOTS, RobotCfg, get_robot

# What a damaged archive raises: zipfile and zlib errors, NotImplementedError (unknown
# compression method), RuntimeError (encrypted member), struct.error (cut headers), and from
# numpy's parsing of a damaged array header SyntaxError and tokenize.TokenError (found by the
# fuzz campaign: an unbalanced bracket in the header).
_ARCHIVE_ERRORS = (
    OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error, NotImplementedError,
    RuntimeError, struct.error, SyntaxError, tokenize.TokenError,
)  # fmt: skip

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
#: Keys a file may lack: format 1 files (before whole-body dances) have none, format 2
#: files (before the Go2) no ``robot``.
OPTIONAL_KEYS: tuple[str, ...] = ("body_targets", "format", "robot")
#: Dance format written: 1 = feet only, 2 = adds ``body_targets`` (T, 4), 3 = adds ``robot``.
FORMAT_VERSION = 3
#: Largest |trunk height offset|, m, and |trunk angle|, rad, read from ``body_targets``.
MAX_BODY_HEIGHT_M = 0.2
MAX_BODY_ANGLE_RAD = 1.0

MAX_DANCE_S = 30 * 60.0
"""Longest dance read, s (the longest song, 20 min, plus room for a long motion file)."""
MAX_FPS = 1000.0
"""Highest curve rate read, Hz (the policy runs at 50)."""
MAX_FRAMES = int(MAX_DANCE_S * MAX_FPS)
"""Most samples in a curve; checked in the archive's headers before any array is read."""
MAX_BEATS = 100_000
"""Most beats or downbeats (a 30-minute dance at 300 BPM has 9000)."""
MAX_HEIGHT_M = 20.0
"""Largest foot height or target read, m (paper mode asks up to h0 = 10 m at most)."""
MAX_TEXT_CHARS = {"mode": 16, "source": 1000, "version": 64, "robot": 64}
"""Longest text of each string field, characters."""
MAX_FILE_BYTES = 256 << 20
"""Largest dance file read, bytes (a 20-minute dance is about 3 MB)."""


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
        body_targets: (T, 4) trunk targets relative to standing: height offset (m), roll,
            pitch, yaw (rad); `quaddance.layout.BODY_COLUMNS`. None -> zeros.
        robot: the robot it was made for (`quaddance.robots.RobotCfg.name`).
        clamp_report: what feasible mode clamped (`compose`), or None; not saved.
        notes: what the user should hear about how the dance was made (a beat file that
            leaves much of the song without beats, say); not saved.
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
    body_targets: np.ndarray | None = None
    robot: str = GO1.name
    clamp_report: dict | None = None
    notes: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if self.body_targets is None:
            self.body_targets = np.zeros((np.asarray(self.time_s).size, N_BODY))

    @property
    def duration_s(self) -> float:
        """Length of the dance, s."""
        return self.time_s.size / self.fps

    def require_robot(self, robot: RobotCfg, what: str) -> None:
        """Refuse, in one line naming ``what`` (the dance file) and both robots, to dance
        this dance on ``robot`` when it was made for another."""
        if self.robot != robot.name:
            mine, theirs = get_robot(self.robot).short_name, robot.short_name
            raise InputFileError(
                what,
                f"a dance for {mine}, not {theirs} (choreograph it again with --robot {theirs})",
            )


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
        "body_targets": np.asarray(dance.body_targets, dtype=np.float64),
        "format": np.int64(FORMAT_VERSION),
    }
    for key in (*_STRING_KEYS, "robot"):
        arrays[key] = np.array(str(getattr(dance, key)), dtype=np.str_)
    with atomic_path(path) as tmp, tmp.open("wb") as fh:
        # Writing through a handle stops numpy from appending ".npz" to the temp name.
        np.savez_compressed(fh, **arrays)


def load_dance(path: str | Path, robot: RobotCfg | None = None) -> Dance:
    """Read and check a ``dance.npz``; raise `InputFileError` naming what is wrong, or, with
    ``robot``, that the dance was made for another robot (`Dance.require_robot`)."""
    path = Path(path)
    if not path.is_file():
        raise not_a_file(path)
    if path.stat().st_size > MAX_FILE_BYTES:
        raise InputFileError(path, f"is {path.stat().st_size} bytes, too large for a dance file")
    try:
        _check_headers(path)
        loaded = np.load(path, allow_pickle=False)
        if not isinstance(loaded, np.lib.npyio.NpzFile):
            raise InputFileError(path, "not a dance file (a single .npy array, not an .npz)")
        with loaded as npz:
            missing = [key for key in KEYS if key not in npz.files]
            if missing:
                raise InputFileError(path, f"not a dance file: missing {', '.join(missing)}")
            raw = {key: npz[key] for key in KEYS + OPTIONAL_KEYS if key in npz.files}
    except InputFileError:
        raise
    except _ARCHIVE_ERRORS as err:
        problem = " ".join(str(err).split())[:200]
        raise InputFileError(path, f"cannot read as a dance .npz ({problem})") from None
    dance = _check(path, raw)
    if robot is not None:
        dance.require_robot(robot, path)
    return dance


def _check_headers(path: Path) -> None:
    """Refuse an archive whose arrays are too large or of the wrong kind, from their headers,
    before numpy allocates them (a few compressed bytes can inflate to gigabytes)."""
    if not zipfile.is_zipfile(path):
        return  # np.load says what it is (a single .npy, text, ...)
    with zipfile.ZipFile(path) as zf:
        members = zf.infolist()
        if len(members) > 4 * len(KEYS):
            raise InputFileError(path, f"not a dance file: {len(members)} arrays in the archive")
        for info in members:
            key = info.filename.removesuffix(".npy")
            if key not in KEYS + OPTIONAL_KEYS:
                continue  # extra members are never read
            with zf.open(info) as fh:
                version = np.lib.format.read_magic(fh)
                if version == (1, 0):
                    shape, _, dtype = np.lib.format.read_array_header_1_0(fh)
                else:
                    shape, _, dtype = np.lib.format.read_array_header_2_0(fh)
            limit = MAX_BEATS if key in ("beats_s", "downbeats_s") else 4 * MAX_FRAMES
            count = float(np.prod(shape, dtype=np.float64))
            if count > limit or count * dtype.itemsize > 8 * limit:
                raise InputFileError(
                    path, f"{key}: {count:.4g} values of {dtype.itemsize} bytes, too large"
                )
            if dtype.kind in "OV":  # objects (pickles) and records: never in a dance file
                raise InputFileError(path, f"{key}: unsupported array type {dtype}")
            if dtype.kind == "U" and dtype.itemsize > 4 * MAX_TEXT_CHARS.get(key, 64):
                raise InputFileError(
                    path,
                    f"{key}: text of {dtype.itemsize // 4} characters, at most "
                    f"{MAX_TEXT_CHARS.get(key, 64)}",
                )


def _check(path: Path, raw: dict[str, np.ndarray]) -> Dance:
    """Validate the arrays of a dance file and build the `Dance`; every error names the key."""

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
        value = str(arr)
        if len(value) > MAX_TEXT_CHARS[key] or not value.isprintable():
            raise InputFileError(
                path, f"{key} must be printable text of at most {MAX_TEXT_CHARS[key]} characters"
            )
        return value

    def curve(key: str, ndim: int, lo: float, hi: float) -> np.ndarray:
        arr = raw[key]
        # bool is refused: a curve of true/false is not heights or times.
        if arr.ndim != ndim or arr.dtype.kind not in "fiu":
            raise InputFileError(
                path, f"{key} must be a {ndim}-D array of real numbers, got {arr.dtype} {arr.shape}"
            )
        out = arr.astype(np.float64)
        if not np.all(np.isfinite(out)):
            raise InputFileError(path, f"{key} contains NaN or infinite values")
        if out.size and not (lo <= out.min() and out.max() <= hi):
            raise InputFileError(
                path,
                f"{key} has values in [{out.min():.4g}, {out.max():.4g}], outside [{lo:g}, {hi:g}]",
            )
        return out

    fps = float(number("fps", "fiu"))
    if not 0 < fps <= MAX_FPS:
        raise InputFileError(path, f"fps must be > 0 and at most {MAX_FPS:g} Hz, got {fps}")
    time_s = curve("time_s", 1, 0.0, MAX_DANCE_S)
    n = time_s.size
    if n == 0:
        raise InputFileError(path, "time_s is empty")
    if n > 1 and not np.all(np.diff(time_s) > 0):
        raise InputFileError(path, "time_s is not increasing")
    if n > 1 and not np.allclose(np.diff(time_s), 1.0 / fps, rtol=1e-6, atol=1e-9):
        raise InputFileError(path, f"time_s is not sampled at fps = {fps:g} Hz")
    human = curve("human_feet_m", 2, -MAX_HEIGHT_M, MAX_HEIGHT_M)
    if human.shape != (n, 2):
        raise InputFileError(path, f"human_feet_m must have shape ({n}, 2), got {human.shape}")
    targets = curve("targets_m", 2, -MAX_HEIGHT_M, MAX_HEIGHT_M)
    if targets.shape != (n, N_PAWS):
        raise InputFileError(
            path, f"targets_m must have shape ({n}, {N_PAWS}), got {targets.shape}"
        )
    beats = {}
    for key in ("beats_s", "downbeats_s"):
        beats[key] = curve(key, 1, -MAX_DANCE_S, 2 * MAX_DANCE_S)
        if beats[key].size > 1 and np.any(np.diff(beats[key]) < 0):
            raise InputFileError(path, f"{key} is not in time order")
    mode = text("mode")
    if mode not in MODES:
        raise InputFileError(path, f"mode must be one of {', '.join(MODES)}, got {mode!r}")
    seed = int(number("seed", "iu"))
    if not 0 <= seed < 2**63:
        raise InputFileError(path, f"seed must be in [0, 2**63), got {seed}")
    if "format" in raw:
        fmt = int(number("format", "iu"))
        if not 1 <= fmt <= FORMAT_VERSION:
            raise InputFileError(
                path, f"format {fmt} is not one this quaddance reads (1 to {FORMAT_VERSION})"
            )
    robot = GO1.name
    if "robot" in raw:
        robot = text("robot")
        if robot not in ROBOTS:
            raise InputFileError(path, f"robot must be one of {', '.join(ROBOTS)}, got {robot!r}")
    body = np.zeros((n, N_BODY))
    if "body_targets" in raw:
        body = curve("body_targets", 2, -MAX_BODY_ANGLE_RAD, MAX_BODY_ANGLE_RAD)
        if body.shape != (n, N_BODY):
            raise InputFileError(
                path, f"body_targets must have shape ({n}, {N_BODY}), got {body.shape}"
            )
        height = np.abs(body[:, 0]).max(initial=0.0)
        if height > MAX_BODY_HEIGHT_M:
            raise InputFileError(
                path,
                f"body_targets height offset reaches {height:.4g} m, beyond "
                f"+-{MAX_BODY_HEIGHT_M:g} m",
            )
    return Dance(
        fps=fps,
        time_s=time_s,
        human_feet_m=human,
        targets_m=targets,
        beats_s=beats["beats_s"],
        downbeats_s=beats["downbeats_s"],
        mode=mode,
        source=text("source"),
        seed=seed,
        version=text("version"),
        body_targets=body,
        robot=robot,
    )
