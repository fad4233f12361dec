"""Human motion files -> left/right foot heights above the floor, in metres.

Supported formats:

- EDGE output pickle (``.pkl``): ``full_pose`` (T, 24, 3) SMPL joint positions, z-up, metres,
  30 fps unless the file holds ``fps``; or only ``smpl_poses`` / ``smpl_trans``, whose up axis is
  then found from the body.
- AIST++ motion pickle (``.pkl``): ``smpl_poses`` (T, 72), ``smpl_trans`` (T, 3) and
  ``smpl_scaling`` (1,); y-up, 60 fps; ``smpl_trans / smpl_scaling`` is in metres.
- BVH (``.bvh``): any skeleton whose ankles can be found by name; unit and up axis detected.

Every number read is checked before it is used (type, finite, range) and every motion is at
most `MAX_MOTION_S` (20 minutes) and `MAX_MOTION_FRAMES` long, at 1-1000 frames per second;
anything else is an `InputFileError` naming the file and the field, in one short line.

Pickles are read with `safe_load_pickle`, never plain pickle. The floor is estimated per
sequence as a low percentile of both ankles' heights, so a foot's height is its ankle's
height above its standing height (the foot's bottom, up to the sole thickness).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from quaddance.choreo import bvh, smpl
from quaddance.choreo.safe_pickle import safe_load_pickle
from quaddance.errors import InputFileError

#: Longest motion accepted, seconds (20 minutes: longer than any song a robot dances to).
#: Longer files are refused from their header or array shapes, before the work they drive.
MAX_MOTION_S = 20 * 60.0
#: Most frames accepted (20 minutes at 166 fps); bounds the memory of forward kinematics.
MAX_MOTION_FRAMES = 200_000
#: Frame rates accepted, frames per second (motion capture runs at 24-480).
MIN_FPS_HZ, MAX_FPS_HZ = 1.0, 1000.0
#: AIST++ ``smpl_scaling`` accepted (the released files hold about 90-100).
MIN_SCALING, MAX_SCALING = 1e-3, 1e5
#: Largest joint position or translation, metres: nothing human is 10 km from the origin,
#: and the bound keeps every product downstream finite.
MAX_POSITION_M = 1e4
#: Largest axis-angle component, radians (real poses stay within a few turns).
MAX_ANGLE_RAD = 1e3
_MAX_MESSAGE_LIST = 120  # characters of a key or joint list quoted in an error

_PICKLE_SUFFIXES = (".pkl", ".pickle")
_BVH_SUFFIXES = (".bvh",)
_AXIS_NAMES = "xyz"


@dataclass(frozen=True)
class MotionImportConfig:
    """How motion files are read."""

    edge_fps: float = 30.0  # EDGE output frame rate (FACTS.md section 3)
    aist_fps: float = 60.0  # AIST++ motion frame rate (FACTS.md section 3)
    edge_up_axis: int = 2  # EDGE full_pose is z-up (FACTS.md section 3)
    aist_up_axis: int = 1  # AIST++ is y-up (FACTS.md section 3)
    # Floor = this percentile of both ankles' heights (FACTS.md section 3: "a low percentile");
    # low enough to sit on standing frames, high enough to ignore a few glitched frames.
    floor_percentile: float = 2.0
    min_duration_s: float = 1.0  # shorter clips cannot carry a dance (brief of the importer)
    max_duration_s: float = MAX_MOTION_S  # longer ones are refused before they are computed


@dataclass
class HumanMotion:
    """Left/right foot heights of a human dance.

    Attributes
    ----------
    fps : float
        Frame rate of ``feet_m``, frames per second.
    feet_m : np.ndarray, shape (T, 2)
        Height of the (left, right) foot above the floor, metres, >= 0.
    source : str
        Where the curves came from, for logs and plots (file name and format).
    """

    fps: float
    feet_m: np.ndarray = field(repr=False)
    source: str

    @property
    def duration_s(self) -> float:
        """Length of the motion, seconds."""
        return self.feet_m.shape[0] / self.fps


def feet_above_floor(ankle_heights: np.ndarray, floor_percentile: float) -> np.ndarray:
    """Ankle heights relative to a floor estimated from the sequence itself.

    Parameters
    ----------
    ankle_heights : np.ndarray, shape (T, 2)
        Height of the (left, right) ankle along the up axis, metres, any origin.
    floor_percentile : float
        Percentile (0-100) of all ankle heights of both feet taken as the floor.

    Returns
    -------
    np.ndarray, shape (T, 2)
        ``ankle_heights - floor`` clipped at 0, metres.
    """
    floor = np.percentile(ankle_heights, floor_percentile)
    return np.clip(ankle_heights - floor, 0.0, None)


def up_axis_of(positions: np.ndarray, root: int, ankles: tuple[int, int]) -> tuple[int, float]:
    """The world axis (and its sign) pointing from the feet to the pelvis on average.

    Parameters
    ----------
    positions : np.ndarray, shape (T, J, 3)
        World joint positions, any unit.
    root : int
        Index of the pelvis / root joint.
    ankles : (int, int)
        Indices of the left and right ankles.

    Returns
    -------
    (axis, sign)
        ``axis`` in 0, 1, 2 and ``sign`` +1.0 or -1.0, so that height = sign * position[axis].
    """
    feet_to_root = positions[:, root] - positions[:, list(ankles)].mean(axis=1)
    mean = feet_to_root.mean(axis=0)
    axis = int(np.argmax(np.abs(mean)))
    return axis, float(np.sign(mean[axis]) or 1.0)


def _listing(names: list[str]) -> str:
    """Names joined for an error message, cut to `_MAX_MESSAGE_LIST` characters."""
    # Non-printable characters (newlines in a pickle's keys) would break the one-line error.
    shown = ["".join(c if c.isprintable() else "?" for c in name[:30]) for name in names[:20]]
    text = ", ".join(shown) or "none"
    cut = len(names) > 20 or len(text) > _MAX_MESSAGE_LIST
    return text[:_MAX_MESSAGE_LIST] + (" ..." if cut else "")


_NUMBER_TYPES = frozenset(
    [int, float]
    + [np.dtype(c).type for c in ("i1", "i2", "i4", "i8", "u1", "u2", "u4", "u8")]
    + [np.float16, np.float32, np.float64]
)


def _count_numbers(value: object, limit: int) -> int | None:
    """Numbers in nested lists/tuples as `np.asarray` would expand them (a list shared many
    times counts each time), or None if a leaf is not an int or float (bools and text are
    not) or the count passes ``limit``. Each distinct list is visited once, without
    recursion, so a small file of shared lists cannot make this slow."""
    if type(value) in _NUMBER_TYPES:
        return 1
    if not isinstance(value, list | tuple):
        return None
    counts: dict[int, int] = {}
    expanding: set[int] = set()  # met again before it is counted: a cycle
    stack: list[tuple[list[Any] | tuple[Any, ...], bool]] = [(value, False)]
    while stack:
        item, expanded = stack.pop()
        if id(item) in counts:
            continue
        if not expanded:
            if id(item) in expanding:
                return None
            expanding.add(id(item))
            stack.append((item, True))
            stack += [(c, False) for c in item if isinstance(c, list | tuple)]
            continue
        total = 0
        for child in item:
            if type(child) in _NUMBER_TYPES:
                total += 1
            elif isinstance(child, list | tuple) and id(child) in counts:
                total += counts[id(child)]
            else:
                return None
        if total > limit:
            return None
        counts[id(item)] = total
    return counts[id(value)]


def _array(
    path: Path, data: dict[str, Any], key: str, shape: tuple[int | None, ...], max_abs: float
) -> np.ndarray:
    """``data[key]`` as a float array of ``shape`` (None: any length, at most
    `MAX_MOTION_FRAMES`) with |values| <= max_abs; shape and length are checked before the
    float copy is made."""
    value = data[key]
    limit = MAX_MOTION_FRAMES * 3 * smpl.N_JOINTS
    if isinstance(value, np.ndarray):
        if value.dtype.kind not in "iuf":
            raise InputFileError(path, f"'{key}' is a {value.dtype} array, not real numbers")
        _check_shape(path, key, value.shape, shape)
    elif _count_numbers(value, limit) is None:
        raise InputFileError(
            path, f"'{key}' is not a numeric array (or has more than {limit} numbers)"
        )
    try:
        # Quietly: a warning would be a second line on the terminal; the checks below speak.
        with np.errstate(all="ignore"):
            value = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise InputFileError(path, f"'{key}' is not a numeric array") from None
    _check_shape(path, key, value.shape, shape)
    if not np.all(np.isfinite(value)):
        raise InputFileError(path, f"'{key}' contains NaN or infinite values")
    if value.size and np.max(np.abs(value)) > max_abs:
        raise InputFileError(
            path, f"'{key}' has values up to {np.max(np.abs(value)):.3g}, beyond +-{max_abs:g}"
        )
    return value


def _check_shape(path: Path, key: str, got: tuple[int, ...], want: tuple[int | None, ...]) -> None:
    """Refuse ``got`` unless it matches ``want`` (None: any length up to the frame limit)."""
    if len(got) != len(want) or any(
        w is not None and g != w for g, w in zip(got, want, strict=True)
    ):
        want_text = "(" + ", ".join("T" if s is None else str(s) for s in want) + ")"
        raise InputFileError(path, f"'{key}' has shape {got}, expected {want_text} for this format")
    if got and got[0] > MAX_MOTION_FRAMES:
        raise InputFileError(
            path, f"motion is too long: '{key}' has {got[0]} frames, at most {MAX_MOTION_FRAMES}"
        )


def _number(path: Path, data: dict[str, Any], key: str, low: float, high: float) -> float:
    """``data[key]`` as one real number in ``[low, high]`` (a scalar or a one-element array)."""
    value = data[key]
    if isinstance(value, np.ndarray) and value.size == 1 and value.dtype.kind in "iuf":
        value = value.reshape(-1)[0]
    if isinstance(value, bool | np.bool_) or not isinstance(
        value, int | float | np.integer | np.floating
    ):
        raise InputFileError(path, f"'{key}' must be one number, got a {type(value).__name__}")
    number = float(value)  # ints are at most 64 bits (safe_pickle), so this is finite
    if not low <= number <= high:
        raise InputFileError(path, f"'{key}' is {number:.6g}, expected {low:g} to {high:g}")
    return number


def _check_length(path: Path, n_frames: int, fps: float, cfg: MotionImportConfig) -> None:
    """Refuse a motion shorter or longer than the config allows, before it is computed."""
    if n_frames > MAX_MOTION_FRAMES or n_frames > cfg.max_duration_s * fps:
        raise InputFileError(
            path,
            f"motion is too long: {n_frames} frames at {fps:g} fps = {n_frames / fps:.0f} s; "
            f"at most {cfg.max_duration_s:g} s and {MAX_MOTION_FRAMES} frames",
        )
    if n_frames < cfg.min_duration_s * fps:
        raise InputFileError(
            path,
            f"motion is too short: {n_frames} frames at {fps:g} fps = {n_frames / fps:.2f} s, "
            f"need at least {cfg.min_duration_s:g} s",
        )


def _motion_from_pickle(path: Path, cfg: MotionImportConfig) -> tuple[float, np.ndarray, str]:
    """(fps, ankle heights (T, 2) in metres with any origin, description) from a pickle."""
    data = safe_load_pickle(path)
    if not isinstance(data, dict):
        raise InputFileError(
            path, f"pickle holds a {type(data).__name__}, expected a dict of motion arrays"
        )

    def fps_or(default: float) -> float:
        return _number(path, data, "fps", MIN_FPS_HZ, MAX_FPS_HZ) if "fps" in data else default

    if "full_pose" in data:
        fps = fps_or(cfg.edge_fps)
        joints = _array(path, data, "full_pose", (None, smpl.N_JOINTS, 3), MAX_POSITION_M)
        _check_length(path, joints.shape[0], fps, cfg)
        heights = joints[:, [smpl.LEFT_ANKLE, smpl.RIGHT_ANKLE], cfg.edge_up_axis]
        return fps, heights, f"EDGE full_pose, {_AXIS_NAMES[cfg.edge_up_axis]}-up"
    if "smpl_poses" not in data or "smpl_trans" not in data:
        keys = _listing(sorted(map(str, data)))
        raise InputFileError(
            path,
            "is not an EDGE or AIST++ motion: expected 'full_pose' (EDGE) or 'smpl_poses' and "
            f"'smpl_trans' (AIST++, EDGE); keys found: {keys}",
        )
    aist = "smpl_scaling" in data
    fps = fps_or(cfg.aist_fps if aist else cfg.edge_fps)
    poses = _array(path, data, "smpl_poses", (None, 3 * smpl.N_JOINTS), MAX_ANGLE_RAD)
    _check_length(path, poses.shape[0], fps, cfg)
    scaling = _number(path, data, "smpl_scaling", MIN_SCALING, MAX_SCALING) if aist else 1.0
    trans = _array(path, data, "smpl_trans", (poses.shape[0], 3), MAX_POSITION_M * scaling)
    joints = smpl.smpl_joints(poses, trans / scaling)
    ankles = (smpl.LEFT_ANKLE, smpl.RIGHT_ANKLE)
    if aist:
        heights = joints[:, list(ankles), cfg.aist_up_axis]
        return fps, heights, f"AIST++ SMPL, {_AXIS_NAMES[cfg.aist_up_axis]}-up"
    # EDGE parameters without full_pose: the global orientation decides the up axis.
    axis, sign = up_axis_of(joints, smpl.PELVIS, ankles)
    heights = sign * joints[:, list(ankles), axis]
    return fps, heights, f"EDGE SMPL parameters, {_AXIS_NAMES[axis]}-up (detected)"


def _motion_from_bvh(path: Path, cfg: MotionImportConfig) -> tuple[float, np.ndarray, str]:
    """(fps, ankle heights (T, 2) in metres with any origin, description) from a BVH file."""
    motion = bvh.load_bvh(path, cfg.max_duration_s, MAX_MOTION_FRAMES)
    _check_length(path, motion.positions.shape[0], motion.fps, cfg)
    ankles = bvh.find_ankles(motion.joint_names)
    if ankles is None:
        raise InputFileError(
            path,
            "BVH has no joints recognisable as left and right ankles (e.g. LeftFoot/RightFoot, "
            f"L_Ankle/R_Ankle); joints: {_listing(list(motion.joint_names))}",
        )
    leg_chain = np.mean([bvh.chain_length(motion.offsets, motion.parents, a) for a in ankles])
    if leg_chain <= 0:
        raise InputFileError(path, "BVH skeleton has zero-length legs")
    unit, metres_per_unit = bvh.guess_unit(float(leg_chain))
    axis, sign = up_axis_of(motion.positions, 0, ankles)
    heights = sign * metres_per_unit * motion.positions[:, list(ankles), axis]
    names = "/".join(motion.joint_names[a] for a in ankles)
    sign_text = "" if sign > 0 else "-"
    return motion.fps, heights, f"BVH, {unit}, {sign_text}{_AXIS_NAMES[axis]}-up, ankles {names}"


def _sniff(path: Path) -> str | None:
    """'pickle', 'bvh' or None from the first bytes, for files with an unknown suffix."""
    try:
        with path.open("rb") as f:
            head = f.read(16)
    except OSError as err:
        raise InputFileError(path, f"cannot be read ({err.strerror or err})") from None
    if head.lstrip().upper().startswith(b"HIERARCHY"):
        return "bvh"
    if head[:1] == b"\x80":  # PROTO opcode: every pickle of protocol 2 or later starts so
        return "pickle"
    return None


def load_motion(path: str | Path, cfg: MotionImportConfig | None = None) -> HumanMotion:
    """Read a human motion file and return its left/right foot heights above the floor.

    Parameters
    ----------
    path : str or Path
        EDGE or AIST++ pickle (``.pkl``, ``.pickle``) or BVH (``.bvh``); a file with another
        suffix is recognised by its first bytes.
    cfg : MotionImportConfig, optional
        Frame rates, axes and floor estimate; defaults to `MotionImportConfig()`.

    Returns
    -------
    HumanMotion
        ``feet_m`` (T, 2): (left, right) ankle height above the estimated floor, metres, at
        the file's frame rate.

    Raises
    ------
    InputFileError
        If the file is missing, of unknown format, unsafe, malformed (missing keys, wrong
        shapes, NaN / inf), or shorter than ``cfg.min_duration_s``.
    """
    cfg = cfg or MotionImportConfig()
    path = Path(path)
    if not path.is_file():
        raise InputFileError(path, "does not exist or is not a file")
    suffix = path.suffix.lower()
    if suffix in _PICKLE_SUFFIXES:
        kind = "pickle"
    elif suffix in _BVH_SUFFIXES:
        kind = "bvh"
    else:
        kind = _sniff(path)
    if kind == "pickle":
        fps, heights, description = _motion_from_pickle(path, cfg)
    elif kind == "bvh":
        fps, heights, description = _motion_from_bvh(path, cfg)
    else:
        raise InputFileError(
            path,
            f"unknown motion format '{suffix or '(no suffix)'}': expected an EDGE or AIST++ "
            "pickle (.pkl, .pickle) or a BVH file (.bvh)",
        )
    # Bounded inputs give finite heights; this holds the promise for every format at once.
    if not np.all(np.isfinite(heights)) or np.max(np.abs(heights)) > MAX_POSITION_M:
        raise InputFileError(path, f"foot heights are not finite or beyond {MAX_POSITION_M:g} m")
    feet_m = feet_above_floor(heights, cfg.floor_percentile)
    return HumanMotion(fps=fps, feet_m=feet_m, source=f"{path.name} ({description}, {fps:g} fps)")
