"""BVH motion capture files: parse the skeleton and motion, and compute world joint positions.

A BVH file has a HIERARCHY (ROOT / JOINT blocks with an OFFSET from the parent, CHANNELS naming
the per-frame values, End Site leaves) and a MOTION block (``Frames:``, ``Frame Time:``, then one
line of channel values per frame). Rotations are Euler angles in degrees applied in the order
the channels are listed (intrinsic): ``Zrotation Xrotation Yrotation`` means
``R = Rz @ Rx @ Ry``. Position channels give the joint's position in its parent's frame and
replace the matching OFFSET components. Positions come out in the file's units; the helpers
below find the ankles by name and the unit from the skeleton's leg length.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from quaddance.errors import InputFileError

_AXES = {"x": 0, "y": 1, "z": 2}

# Candidate units, metres per file unit. BVH has no unit field; exporters use one of these.
UNITS_M: dict[str, float] = {"m": 1.0, "cm": 0.01, "mm": 0.001, "inch": 0.0254}

# Pelvis-to-ankle bone-chain length of an adult, metres (SMPL neutral body: 0.09 + 0.39 + 0.43,
# FACTS.md section 3); the unit that brings the file's chain closest to this is chosen.
TYPICAL_LEG_CHAIN_M = 0.9

# Joint names of the ankles after lower-casing and dropping "_", "-", " ", "." and any
# "namespace:" prefix. Ankle names win over foot names: in SMPL-style files "L_Foot" is the toe
# while "L_Ankle" is the ankle; elsewhere (CMU, Mixamo) "LeftFoot" is the ankle joint.
_ANKLE_PATTERNS = (r"(left|l)ankle|ankle(left|l)", r"(left|l)foot|foot(left|l)")


@dataclass(frozen=True)
class BvhMotion:
    """A parsed BVH file.

    Attributes
    ----------
    fps : float
        Frames per second, ``1 / Frame Time``.
    joint_names : tuple of str
        ROOT and JOINT names in file order (End Sites are not joints).
    parents : tuple of int
        Index of each joint's parent, -1 for the root.
    offsets : np.ndarray, shape (J, 3)
        Rest offset of each joint from its parent, file units.
    positions : np.ndarray, shape (T, J, 3)
        World joint positions per frame, file units, in the file's axes.
    """

    fps: float
    joint_names: tuple[str, ...]
    parents: tuple[int, ...]
    offsets: np.ndarray
    positions: np.ndarray


@dataclass
class _Joint:
    name: str
    parent: int
    offset: np.ndarray
    channels: list[tuple[str, int]]  # (kind "position"/"rotation", axis 0/1/2)


def _parse_hierarchy(tokens: list[str], path: Path) -> list[_Joint]:
    """Joints in file order from the HIERARCHY tokens (after the word HIERARCHY)."""
    joints: list[_Joint] = []
    stack: list[int] = []  # open blocks: joint index, or -2 for an End Site
    i = 0

    def need(count: int, what: str) -> list[str]:
        nonlocal i
        if i + count > len(tokens):
            raise InputFileError(path, f"BVH hierarchy ends inside {what}")
        got = tokens[i : i + count]
        i += count
        return got

    def numbers(count: int, what: str) -> np.ndarray:
        try:
            return np.array([float(t) for t in need(count, what)])
        except ValueError:
            raise InputFileError(path, f"BVH {what} has a value that is not a number") from None

    while i < len(tokens):
        word = tokens[i]
        i += 1
        key = word.upper()
        if key in ("ROOT", "JOINT"):
            if (key == "ROOT") != (not stack):
                raise InputFileError(path, f"BVH {word} in the wrong place (block nesting)")
            name_parts = []
            while i < len(tokens) and tokens[i] != "{":
                name_parts.append(tokens[i])
                i += 1
            need(1, f"{word} block")  # the "{"
            parent = stack[-1] if stack else -1
            if parent == -2:
                raise InputFileError(path, "BVH End Site has a child joint")
            name = " ".join(name_parts) or f"joint{len(joints)}"
            joints.append(_Joint(name, parent, np.zeros(3), []))
            stack.append(len(joints) - 1)
        elif key == "END":
            need(2, "End Site")  # "Site" "{"
            stack.append(-2)
        elif key == "OFFSET":
            offset = numbers(3, "OFFSET")
            if not stack:
                raise InputFileError(path, "BVH OFFSET outside a joint block")
            if stack[-1] >= 0:
                joints[stack[-1]].offset = offset
        elif key == "CHANNELS":
            if not stack or stack[-1] < 0:
                raise InputFileError(path, "BVH CHANNELS outside a joint block")
            (count_text,) = need(1, "CHANNELS")
            if not count_text.isdigit():
                raise InputFileError(path, f"BVH CHANNELS count {count_text!r} is not a number")
            for channel in need(int(count_text), "CHANNELS"):
                match = re.fullmatch(r"([xyz])(position|rotation)", channel.lower())
                if match is None:
                    raise InputFileError(path, f"BVH channel {channel!r} is not understood")
                joints[stack[-1]].channels.append((match[2], _AXES[match[1]]))
        elif word == "}":
            if not stack:
                raise InputFileError(path, "BVH hierarchy has an unmatched '}'")
            stack.pop()
        else:
            raise InputFileError(path, f"BVH hierarchy has an unexpected word {word!r}")
    if stack:
        raise InputFileError(path, "BVH hierarchy is truncated (a block is never closed)")
    if not joints:
        raise InputFileError(path, "BVH hierarchy has no ROOT joint")
    return joints


def _elementary_rotations(axis: int, angle_rad: np.ndarray) -> np.ndarray:
    """Rotation matrices about one coordinate axis, shape (T, 3, 3)."""
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    out = np.zeros((angle_rad.shape[0], 3, 3))
    a, b = [k for k in range(3) if k != axis]
    # About x: (y, z) plane; about y: (z, x); about z: (x, y) - keep the right-handed sign.
    if axis == 1:
        a, b = b, a
    out[:, axis, axis] = 1.0
    out[:, a, a] = c
    out[:, a, b] = -s
    out[:, b, a] = s
    out[:, b, b] = c
    return out


def _forward_kinematics(joints: list[_Joint], values: np.ndarray) -> np.ndarray:
    """World positions (T, J, 3) from per-frame channel values (T, C)."""
    n_frames = values.shape[0]
    positions = np.empty((n_frames, len(joints), 3))
    world_rot = np.empty((n_frames, len(joints), 3, 3))
    column = 0
    for j, joint in enumerate(joints):
        local_pos = np.broadcast_to(joint.offset, (n_frames, 3)).copy()
        local_rot = np.broadcast_to(np.eye(3), (n_frames, 3, 3)).copy()
        for kind, axis in joint.channels:
            value = values[:, column]
            column += 1
            if kind == "position":
                local_pos[:, axis] = value
            else:
                local_rot = local_rot @ _elementary_rotations(axis, np.deg2rad(value))
        if joint.parent < 0:
            positions[:, j] = local_pos
            world_rot[:, j] = local_rot
        else:
            parent_rot = world_rot[:, joint.parent]
            positions[:, j] = positions[:, joint.parent] + np.einsum(
                "tik,tk->ti", parent_rot, local_pos
            )
            world_rot[:, j] = parent_rot @ local_rot
    return positions


def load_bvh(path: str | Path) -> BvhMotion:
    """Read a BVH file and compute world joint positions for every frame.

    Parameters
    ----------
    path : str or Path
        The ``.bvh`` file.

    Returns
    -------
    BvhMotion
        Frame rate, joint names and parents, rest offsets and world positions ``(T, J, 3)``
        in the file's units and axes.

    Raises
    ------
    InputFileError
        If the file cannot be read, is not BVH, or its hierarchy or motion block is
        malformed or truncated.
    """
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as err:
        raise InputFileError(path, f"cannot be read ({err.strerror or err})") from None
    text = raw.decode("utf-8", errors="replace")
    parts = re.split(r"^\s*MOTION\s*$", text, maxsplit=1, flags=re.MULTILINE)
    head_tokens = parts[0].split()
    if not head_tokens or head_tokens[0].upper() != "HIERARCHY":
        raise InputFileError(path, "is not a BVH file (it does not start with HIERARCHY)")
    if len(parts) < 2:
        raise InputFileError(path, "BVH file has no MOTION block (truncated?)")
    joints = _parse_hierarchy(head_tokens[1:], path)

    motion = parts[1]
    frames_match = re.search(r"Frames:\s*(\d+)", motion)
    time_match = re.search(r"Frame\s+Time:\s*(\S+)", motion)
    if frames_match is None or time_match is None:
        raise InputFileError(path, "BVH MOTION block lacks 'Frames:' or 'Frame Time:'")
    n_frames = int(frames_match[1])
    try:
        frame_time_s = float(time_match[1])
    except ValueError:
        raise InputFileError(path, f"BVH Frame Time {time_match[1]!r} is not a number") from None
    if not np.isfinite(frame_time_s) or frame_time_s <= 0:
        raise InputFileError(path, f"BVH Frame Time must be positive, got {frame_time_s}")
    if n_frames < 1:
        raise InputFileError(path, "BVH file has no frames")
    try:
        flat = np.array(motion[time_match.end() :].split(), dtype=np.float64)
    except ValueError:
        raise InputFileError(path, "BVH motion data has a value that is not a number") from None
    n_channels = sum(len(j.channels) for j in joints)
    expected = n_frames * n_channels
    if flat.size != expected:
        raise InputFileError(
            path,
            f"BVH motion data has {flat.size} values but {n_frames} frames x {n_channels} "
            f"channels need {expected} (truncated or inconsistent file)",
        )
    if not np.all(np.isfinite(flat)):
        raise InputFileError(path, "BVH motion data contains NaN or infinite values")
    positions = _forward_kinematics(joints, flat.reshape(n_frames, n_channels))
    fps = 1.0 / frame_time_s
    # Exporters round the frame time (0.0333333 for 30 fps): snap to a whole rate when close.
    if abs(fps - round(fps)) < 1e-3 * fps:
        fps = float(round(fps))
    return BvhMotion(
        fps=fps,
        joint_names=tuple(j.name for j in joints),
        parents=tuple(j.parent for j in joints),
        offsets=np.stack([j.offset for j in joints]),
        positions=positions,
    )


def _normalised_name(name: str) -> str:
    return re.sub(r"[\s_.\-]", "", name.rsplit(":", 1)[-1].lower())


def find_ankles(joint_names: tuple[str, ...] | list[str]) -> tuple[int, int] | None:
    """Indices of the (left, right) ankle joints found by name, or None if either is missing.

    Names such as LeftFoot, LeftAnkle, l_ankle, LFoot, lAnkle, L_Ankle, foot_l,
    mixamorig:LeftFoot and "Bip01 L Foot" are recognised, case-insensitively; a name with
    "ankle" wins over one with "foot".
    """
    names = [_normalised_name(n) for n in joint_names]
    found: list[int] = []
    for side_pattern in (r"(left|l)", r"(right|r)"):
        index = None
        for pattern in _ANKLE_PATTERNS:
            sided = pattern.replace(r"(left|l)", side_pattern)
            hits = [k for k, n in enumerate(names) if re.search(f"(?:{sided})$", n)]
            if hits:
                index = hits[0]
                break
        if index is None:
            return None
        found.append(index)
    return found[0], found[1]


def chain_length(offsets: np.ndarray, parents: tuple[int, ...], joint: int) -> float:
    """Sum of bone lengths from the root to ``joint``, file units (independent of pose).

    The root's own OFFSET is left out: some exporters put the standing pelvis height there.
    """
    length = 0.0
    while parents[joint] >= 0:
        length += float(np.linalg.norm(offsets[joint]))
        joint = parents[joint]
    return length


def guess_unit(leg_chain: float) -> tuple[str, float]:
    """The unit in `UNITS_M` that makes a root-to-ankle chain closest to an adult's.

    Parameters
    ----------
    leg_chain : float
        Root-to-ankle bone-chain length, file units.

    Returns
    -------
    (name, metres_per_unit)
    """
    return min(
        UNITS_M.items(),
        key=lambda item: abs(np.log(max(leg_chain, 1e-12) * item[1] / TYPICAL_LEG_CHAIN_M)),
    )
