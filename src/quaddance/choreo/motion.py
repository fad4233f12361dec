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

The trunk becomes ``HumanMotion.body`` (T, 4) = `quaddance.layout.BODY_COLUMNS` in human
units (`body_from_joints`): the pelvis height and the trunk's roll, pitch and yaw, from the
hips (left-right axis) and the spine (up axis), each minus its moving average over
`DRIFT_WINDOW_S` (so walking off, turning round and a crouched stance are not danced).
Without two distinct hips the angles are zeros and only the height is kept.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from quaddance.choreo import bvh, smpl
from quaddance.choreo.grid import _moving_average
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

#: Window of the moving average removed from the trunk curves (drift), s: a few bars, so
#: the moves of a beat or two stay and slow wandering goes.
DRIFT_WINDOW_S = 4.0

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
    body : np.ndarray, shape (T, 4)
        Trunk height offset (m) and roll, pitch, yaw (rad), drift removed, human units
        (`body_from_joints`); zeros where the file gives no trunk.
    """

    fps: float
    feet_m: np.ndarray = field(repr=False)
    source: str
    body: np.ndarray | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        if self.body is None:
            self.body = np.zeros((self.feet_m.shape[0], 4))

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


def _z_up(positions: np.ndarray, axis: int, sign: float) -> np.ndarray:
    """Positions (..., 3) re-expressed in a right-handed frame whose z is ``sign * axis``."""
    z = np.zeros(3)
    z[axis] = sign
    x = np.zeros(3)
    x[(axis + 1) % 3] = 1.0
    y = np.cross(z, x)
    return positions @ np.stack([x, y, z], axis=1)


def body_from_joints(
    positions: np.ndarray,
    up: tuple[int, float],
    pelvis: int,
    hips: tuple[int, int] | None,
    spine: int | None,
    fps: float,
    metres_per_unit: float = 1.0,
) -> np.ndarray:
    """Trunk curves of a human, (T, 4) = height offset m, roll, pitch, yaw rad, drift removed.

    Parameters
    ----------
    positions : (T, J, 3) world joint positions, file units.
    up : (axis, sign) of the world's up direction.
    pelvis : index of the pelvis / root joint (its height is the trunk height).
    hips : (left, right) hip joints, or None: then the angles are 0.
    spine : a joint up the spine (the trunk's up axis), or None: world up (pitch 0).
    fps : frame rate, Hz (for the drift window).

    Angles are ZYX (yaw, pitch, roll) of the frame (forward, left, up) built from the hips
    and spine: roll > 0 tilts the trunk to the right, pitch > 0 bends it forward, yaw > 0
    turns it left. Each column is minus its moving average over `DRIFT_WINDOW_S`.
    """
    p = _z_up(np.asarray(positions, dtype=np.float64), *up) * metres_per_unit
    n = p.shape[0]
    body = np.zeros((n, 4))
    body[:, 0] = p[:, pelvis, 2]
    if hips is not None:
        left = p[:, hips[0]] - p[:, hips[1]]
        width = np.linalg.norm(left, axis=1)
        if np.median(width) > 1e-3:  # two distinct hips, at least a millimetre apart
            trunk_up = p[:, spine] - p[:, pelvis] if spine is not None else np.array([0, 0, 1.0])
            trunk_up = np.broadcast_to(trunk_up, left.shape)
            fwd = np.cross(left, trunk_up)
            fwd /= np.maximum(np.linalg.norm(fwd, axis=1, keepdims=True), 1e-12)
            up_v = np.cross(fwd, left)
            up_v /= np.maximum(np.linalg.norm(up_v, axis=1, keepdims=True), 1e-12)
            left_v = np.cross(up_v, fwd)
            body[:, 1] = np.arctan2(left_v[:, 2], up_v[:, 2])
            body[:, 2] = np.arcsin(np.clip(-fwd[:, 2], -1.0, 1.0))
            body[:, 3] = np.unwrap(np.arctan2(fwd[:, 1], fwd[:, 0]))
    window = max(1, round(DRIFT_WINDOW_S * fps))
    for c in range(4):
        body[:, c] -= _moving_average(body[:, c], window)
    return body


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


_SMPL_HIPS = (1, 2)  # left, right hip joints of SMPL
_SMPL_SPINE = 9  # spine3, the top of the lower back


def _motion_from_pickle(
    path: Path, cfg: MotionImportConfig
) -> tuple[float, np.ndarray, str, np.ndarray]:
    """(fps, ankle heights (T, 2) in metres with any origin, description, body (T, 4))
    from a pickle."""
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
        body = _smpl_body(joints, (cfg.edge_up_axis, 1.0), fps)
        return fps, heights, f"EDGE full_pose, {_AXIS_NAMES[cfg.edge_up_axis]}-up", body
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
        body = _smpl_body(joints, (cfg.aist_up_axis, 1.0), fps)
        return fps, heights, f"AIST++ SMPL, {_AXIS_NAMES[cfg.aist_up_axis]}-up", body
    # EDGE parameters without full_pose: the global orientation decides the up axis.
    axis, sign = up_axis_of(joints, smpl.PELVIS, ankles)
    heights = sign * joints[:, list(ankles), axis]
    body = _smpl_body(joints, (axis, sign), fps)
    return fps, heights, f"EDGE SMPL parameters, {_AXIS_NAMES[axis]}-up (detected)", body


def _smpl_body(joints: np.ndarray, up: tuple[int, float], fps: float) -> np.ndarray:
    return body_from_joints(joints, up, smpl.PELVIS, _SMPL_HIPS, _SMPL_SPINE, fps)


def _motion_from_bvh(
    path: Path, cfg: MotionImportConfig
) -> tuple[float, np.ndarray, str, np.ndarray]:
    """(fps, ankle heights (T, 2) in metres with any origin, description, body (T, 4)) from
    a BVH file."""
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
    body = body_from_joints(
        motion.positions,
        (axis, sign),
        0,
        bvh.find_hips(motion.parents, ankles),
        bvh.find_spine(motion.joint_names, motion.parents, ankles),
        motion.fps,
        metres_per_unit,
    )
    description = f"BVH, {unit}, {sign_text}{_AXIS_NAMES[axis]}-up, ankles {names}"
    return motion.fps, heights, description, body


def _sniff(path: Path) -> str | None:
    """'pickle', 'bvh' or None from the first bytes, for files with an unknown suffix."""
    try:
        with path.open("rb") as f:
            head = f.read(16)
    except OSError as err:
        raise InputFileError(path, f"cannot be read ({err.strerror or err})") from None
    if head.removeprefix(b"\xef\xbb\xbf").lstrip().upper().startswith(b"HIERARCHY"):
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
        the file's frame rate; ``body`` (T, 4): the trunk (`body_from_joints`).

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
        fps, heights, description, body = _motion_from_pickle(path, cfg)
    elif kind == "bvh":
        fps, heights, description, body = _motion_from_bvh(path, cfg)
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
    # Angles are bounded by construction; a height drift-removed from bounded positions too.
    body = np.where(np.isfinite(body), body, 0.0)
    return HumanMotion(
        fps=fps, feet_m=feet_m, source=f"{path.name} ({description}, {fps:g} fps)", body=body
    )
