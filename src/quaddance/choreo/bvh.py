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
# "cmu": the CMU motion capture database's skeletons declare `:units length 0.45` (a file unit
# is 1/0.45 inch, 5.6 cm), and the widely used BVH conversions of it keep that unit; its adult
# leg chains are about 17 units long, which inches would read as a 0.43 m leg.
UNITS_M: dict[str, float] = {
    "m": 1.0,
    "cm": 0.01,
    "mm": 0.001,
    "inch": 0.0254,
    "cmu": 0.0254 / 0.45,
}

# Pelvis-to-ankle bone-chain length of an adult, metres (SMPL neutral body: 0.09 + 0.39 + 0.43,
# FACTS.md section 3); the unit that brings the file's chain closest to this is chosen.
TYPICAL_LEG_CHAIN_M = 0.9

# Limits on what a BVH file may ask for, checked before the memory they drive is allocated.
MAX_BVH_BYTES = 256 << 20  # 20 min at 120 fps of a 96-channel skeleton is about 130 MB
MAX_JOINTS = 512  # mocap skeletons have 20-100 joints; hands and faces a few hundred
MAX_HIERARCHY_CHARS = 1 << 20  # 512 joints take about 150 kB of text
MAX_CHANNELS_PER_JOINT = 6  # three positions and three rotations
MAX_VALUES = 24_000_000  # frames x channels held at once (192 MB of float64)
MAX_JOINT_FRAMES = 12_000_000  # frames x joints of world positions (288 MB)
MAX_ABS_VALUE = 1e7  # any OFFSET or channel value: 10 km in mm, or 27 000 turns in degrees
MIN_FRAME_TIME_S = 1e-3  # 1000 fps: faster than any motion capture system
MAX_FRAME_TIME_S = 1.0  # 1 fps: slower cannot carry a dance
_FK_CHUNK_FRAMES = 4096  # frames per forward-kinematics step, bounds its temporary memory
_ASCII_INT = re.compile(r"[0-9]{1,12}")
_ASCII_FLOAT = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]{1,3})?")


def _short(text: str, limit: int = 40) -> str:
    """``text`` quoted and cut to ``limit`` characters, for error messages."""
    return repr(text if len(text) <= limit else text[:limit] + "...")


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
        texts = need(count, what)
        # ASCII decimal only: float() would also take "1_0", "nan" and Arabic-Indic digits.
        if not all(_ASCII_FLOAT.fullmatch(t) for t in texts):
            bad = next(t for t in texts if not _ASCII_FLOAT.fullmatch(t))
            raise InputFileError(path, f"BVH {what} value {_short(bad)} is not a number")
        values = np.array([float(t) for t in texts])
        if not np.all(np.abs(values) <= MAX_ABS_VALUE):
            raise InputFileError(path, f"BVH {what} value beyond +-{MAX_ABS_VALUE:g}")
        return values

    while i < len(tokens):
        word = tokens[i]
        i += 1
        key = word.upper()
        if key in ("ROOT", "JOINT"):
            if (key == "ROOT") != (not stack):
                raise InputFileError(path, f"BVH {_short(word)} in the wrong place (block nesting)")
            name_parts = []
            while i < len(tokens) and tokens[i] != "{":
                name_parts.append(tokens[i])
                i += 1
            need(1, f"{word} block")  # the "{"
            parent = stack[-1] if stack else -1
            if parent == -2:
                raise InputFileError(path, "BVH End Site has a child joint")
            if len(joints) >= MAX_JOINTS:
                raise InputFileError(path, f"BVH hierarchy has more than {MAX_JOINTS} joints")
            # Printable only: names end up in messages and logs (no terminal escapes).
            name = "".join(c if c.isprintable() else "?" for c in " ".join(name_parts)[:100])
            name = name or f"joint{len(joints)}"
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
            # ASCII digits only: str.isdigit() is also true for "²", which int() refuses.
            if not _ASCII_INT.fullmatch(count_text):
                raise InputFileError(
                    path, f"BVH CHANNELS count {_short(count_text)} is not a number"
                )
            if int(count_text) > MAX_CHANNELS_PER_JOINT:
                raise InputFileError(
                    path,
                    f"BVH CHANNELS count {int(count_text)} is more than "
                    f"{MAX_CHANNELS_PER_JOINT} (3 positions, 3 rotations)",
                )
            for channel in need(int(count_text), "CHANNELS"):
                match = re.fullmatch(r"([xyz])(position|rotation)", channel.lower())
                if match is None:
                    raise InputFileError(path, f"BVH channel {_short(channel)} is not understood")
                joints[stack[-1]].channels.append((match[2], _AXES[match[1]]))
        elif word == "}":
            if not stack:
                raise InputFileError(path, "BVH hierarchy has an unmatched '}'")
            stack.pop()
        else:
            raise InputFileError(path, f"BVH hierarchy has an unexpected word {_short(word)}")
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
    """World positions (T, J, 3) from per-frame channel values (T, C).

    Runs over chunks of frames so the world rotations (J 3x3 matrices per frame) never exist
    for the whole motion at once.
    """
    n_frames = values.shape[0]
    positions = np.empty((n_frames, len(joints), 3))
    for start in range(0, n_frames, _FK_CHUNK_FRAMES):
        chunk = slice(start, min(start + _FK_CHUNK_FRAMES, n_frames))
        positions[chunk] = _forward_kinematics_chunk(joints, values[chunk])
    return positions


def _forward_kinematics_chunk(joints: list[_Joint], values: np.ndarray) -> np.ndarray:
    """`_forward_kinematics` for frames that fit in memory at once."""
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


def _frame_time_s(path: Path, motion: str) -> float:
    """The ``Frame Time:`` of the MOTION block, seconds, checked to be a plausible rate."""
    match = re.search(r"Frame\s+Time:[ \t]*(\S*)", motion)
    if match is None:
        raise InputFileError(path, "BVH MOTION block lacks 'Frame Time:'")
    if not _ASCII_FLOAT.fullmatch(match[1]):
        raise InputFileError(path, f"BVH Frame Time {_short(match[1])} is not a number")
    frame_time_s = float(match[1])
    if not MIN_FRAME_TIME_S <= frame_time_s <= MAX_FRAME_TIME_S:
        raise InputFileError(
            path,
            f"BVH Frame Time {frame_time_s:g} s is out of range: expected "
            f"{MIN_FRAME_TIME_S:g} to {MAX_FRAME_TIME_S:g} s (1000 to 1 frames per second)",
        )
    return frame_time_s


def _motion_values(path: Path, data: str, n_frames: int, n_channels: int) -> np.ndarray:
    """The channel values (T, C) after ``Frame Time:``, parsed line by line into one array."""
    expected = n_frames * n_channels
    if expected > MAX_VALUES:
        raise InputFileError(
            path,
            f"BVH motion is too large: {n_frames} frames x {n_channels} channels is more "
            f"than {MAX_VALUES} values",
        )
    if not data.isascii():
        # float() would read Arabic-Indic and other Unicode digits; BVH numbers are ASCII.
        raise InputFileError(path, "BVH motion data has non-ASCII characters")
    flat = np.empty(expected)
    filled = 0
    # One frame per line: a line longer than its frame can be is refused before it is split
    # (a 200 MB line would become millions of strings at once).
    max_line_chars = 64 * n_channels + 1024
    start = 0
    while start < len(data):
        end = data.find("\n", start)
        end = len(data) if end < 0 else end
        if end - start > max_line_chars:
            raise InputFileError(
                path, f"BVH motion data has a line longer than {max_line_chars} characters"
            )
        tokens = data[start:end].split()
        start = end + 1
        if not tokens:
            continue
        if filled + len(tokens) > expected:
            raise InputFileError(
                path,
                f"BVH motion data has more values than {n_frames} frames x {n_channels} "
                f"channels (inconsistent file)",
            )
        try:
            flat[filled : filled + len(tokens)] = np.array(tokens, dtype=np.float64)
        except ValueError:
            raise InputFileError(path, "BVH motion data has a value that is not a number") from None
        filled += len(tokens)
    if filled != expected:
        raise InputFileError(
            path,
            f"BVH motion data has {filled} values but {n_frames} frames x {n_channels} "
            f"channels need {expected} (truncated or inconsistent file)",
        )
    if not np.all(np.isfinite(flat)):
        raise InputFileError(path, "BVH motion data contains NaN or infinite values")
    if not np.all(np.abs(flat) <= MAX_ABS_VALUE):
        raise InputFileError(path, f"BVH motion data has a value beyond +-{MAX_ABS_VALUE:g}")
    return flat.reshape(n_frames, n_channels)


def load_bvh(
    path: str | Path, max_duration_s: float = float("inf"), max_frames: int | None = None
) -> BvhMotion:
    """Read a BVH file and compute world joint positions for every frame.

    Parameters
    ----------
    path : str or Path
        The ``.bvh`` file.
    max_duration_s : float
        Longest motion accepted, seconds; checked from the header before the frames are read.
    max_frames : int, optional
        Most frames accepted, checked likewise.

    Returns
    -------
    BvhMotion
        Frame rate, joint names and parents, rest offsets and world positions ``(T, J, 3)``
        in the file's units and axes.

    Raises
    ------
    InputFileError
        If the file cannot be read, is not BVH, its hierarchy or motion block is malformed or
        truncated, or it breaks a limit: frame time outside 1 ms - 1 s, longer than
        ``max_duration_s``, more than `MAX_JOINTS` joints or `MAX_VALUES` values, values
        beyond `MAX_ABS_VALUE`, numbers that are not ASCII decimals.
    """
    path = Path(path)
    try:
        with path.open("rb") as f:
            raw = f.read(MAX_BVH_BYTES + 1)
    except OSError as err:
        raise InputFileError(path, f"cannot be read ({err.strerror or err})") from None
    if len(raw) > MAX_BVH_BYTES:
        raise InputFileError(path, f"is larger than {MAX_BVH_BYTES >> 20} MB, too big a motion")
    # utf-8-sig: a byte-order mark, as Windows editors write, is not part of the text.
    text = raw.decode("utf-8-sig", errors="replace")
    del raw
    # [ \t], not \s: "\s*" can run over newlines and made this search quadratic in blank lines
    # (100 000 of them took a minute).
    parts = re.split(r"^[ \t]*MOTION[ \t]*\r?$", text, maxsplit=1, flags=re.MULTILINE)
    del text
    if len(parts[0]) > MAX_HIERARCHY_CHARS:
        raise InputFileError(
            path, f"BVH HIERARCHY is longer than {MAX_HIERARCHY_CHARS >> 20} MB (no MOTION line?)"
        )
    head_tokens = parts[0].split()
    if not head_tokens or head_tokens[0].upper() != "HIERARCHY":
        raise InputFileError(path, "is not a BVH file (it does not start with HIERARCHY)")
    if len(parts) < 2:
        raise InputFileError(path, "BVH file has no MOTION block (truncated?)")
    joints = _parse_hierarchy(head_tokens[1:], path)

    motion = parts[1]
    frames_match = re.search(r"Frames:[ \t]*(\S*)", motion)
    if frames_match is None:
        raise InputFileError(path, "BVH MOTION block lacks 'Frames:'")
    if not _ASCII_INT.fullmatch(frames_match[1]):
        raise InputFileError(path, f"BVH Frames: {_short(frames_match[1])} is not a count")
    n_frames = int(frames_match[1])
    if n_frames < 1:
        raise InputFileError(path, "BVH file has no frames")
    frame_time_s = _frame_time_s(path, motion)
    if n_frames * frame_time_s > max_duration_s:
        raise InputFileError(
            path,
            f"BVH motion is {n_frames} frames x {frame_time_s:g} s = "
            f"{n_frames * frame_time_s:.0f} s, longer than the {max_duration_s:g} s allowed",
        )
    if max_frames is not None and n_frames > max_frames:
        raise InputFileError(
            path, f"BVH Frames: {n_frames} is more than the {max_frames} frames allowed"
        )
    if n_frames * len(joints) > MAX_JOINT_FRAMES:
        raise InputFileError(
            path,
            f"BVH motion is too large: {n_frames} frames x {len(joints)} joints is more than "
            f"{MAX_JOINT_FRAMES}",
        )
    time_line = re.search(r"Frame\s+Time:[^\n]*", motion)
    assert time_line is not None  # found by _frame_time_s
    n_channels = sum(len(j.channels) for j in joints)
    values = _motion_values(path, motion[time_line.end() :], n_frames, n_channels)
    positions = _forward_kinematics(joints, values)
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


_SPINE_PATTERN = re.compile(r"spine|chest|lowerback|back|torso|abdomen")


def find_hips(parents: tuple[int, ...], ankles: tuple[int, int]) -> tuple[int, int] | None:
    """The (left, right) hip joints: each ankle's grandparent (ankle <- knee <- hip), or
    None when a leg is too short a chain or both reach the same joint."""
    hips = []
    for ankle in ankles:
        knee = parents[ankle]
        hip = parents[knee] if knee >= 0 else -1
        if hip < 0:
            return None
        hips.append(hip)
    return (hips[0], hips[1]) if hips[0] != hips[1] else None


def find_spine(
    joint_names: tuple[str, ...] | list[str], parents: tuple[int, ...], ankles: tuple[int, int]
) -> int | None:
    """A joint up the spine, for the trunk's up axis: the last joint named like a spine or
    chest (the highest of them in a chain) that is not in a leg, or None."""
    legs: set[int] = set()
    for joint in ankles:
        while joint > 0:
            legs.add(joint)
            joint = parents[joint]
    found = [
        j
        for j, name in enumerate(joint_names)
        if j > 0 and j not in legs and _SPINE_PATTERN.search(_normalised_name(name))
    ]
    return found[-1] if found else None
