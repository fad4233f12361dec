"""Held-out evaluation sets, written as files that `quaddance eval` dances.

Two sets, reported separately:

- ``generator``: songs made by code at other tempi and seeds than the training bank, danced by
  the built-in choreographer, plus two SMPL stepping motions (EDGE- and AIST++-style pickles).
  The same generator and lift shaping as training: in distribution.
- ``other``: human motions made another way than the choreographer and than the stepping
  motions: foot-height patterns it never makes (holds of 3 beats, alternation at 200 BPM,
  knee lifts near the top of the range, same-foot double steps, square off-beat stomps, a
  60 -> 180 BPM accelerando, two-foot jumps, long stillness with irregular lifts), at 60-200
  BPM, carried by other file layouts: BVH files of five skeletons (Mixamo, CMU, 3ds Max
  Biped, SMPL-style, Blender; metres, centimetres, millimetres and inches; y-up and z-up;
  five rotation orders; position channels on every joint in one), EDGE ``full_pose`` with
  hand-set ankle paths, EDGE SMPL parameters with jumps, and AIST++ poses with knee curls
  and a bounce.

Every file is made from a seed, so a set is the same on every machine.
"""

from __future__ import annotations

import pickle
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from quaddance.errors import QuaddanceError
from quaddance.fileio import atomic_path, ensure_dir

HELD_OUT_SETS: tuple[str, ...] = ("generator", "other")

# --- the generator set --------------------------------------------------------------------

# Held-out songs: (tempo_bpm, seed, swing, syncopation); seeds far from the bank's.
HELD_OUT_SONGS: tuple[tuple[float, int, float, bool], ...] = (
    (84.0, 9001, 0.0, False),
    (96.0, 9002, 0.3, False),
    (104.0, 9003, 0.0, True),
    (112.0, 9004, 0.0, False),
    (124.0, 9005, 0.5, False),
    (132.0, 9006, 0.0, True),
    (142.0, 9007, 0.0, False),
    (156.0, 9008, 0.2, True),
)


def _stepping_poses(n: int, fps: float, tempo_bpm: float, seed: int) -> np.ndarray:
    """(n, 72) SMPL axis-angle poses of a dancer stepping left/right on the beat."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / fps
    beat = 60.0 / tempo_bpm
    poses = np.zeros((n, 72))
    for side, (hip, knee) in enumerate(((1, 4), (2, 5))):  # SMPL joints: hips 1/2, knees 4/5
        phase = (t / beat - side) % 2.0  # each leg lifts every other beat
        lift = np.where(phase < 1.0, np.sin(np.pi * phase) ** 2, 0.0)
        amp = rng.uniform(0.5, 0.9)
        poses[:, 3 * hip] = -amp * lift  # hip flexion (about x)
        poses[:, 3 * knee] = 2.0 * amp * lift  # knee flexion
    return poses


def _write_pickle(path: Path, obj: dict) -> Path:
    with atomic_path(path) as tmp, tmp.open("wb") as f:
        pickle.dump(obj, f, protocol=4)  # writing our own data; loading is the safe side
    return path


def write_generator_set(folder: Path, duration_s: float = 20.0) -> list[Path]:
    """8 code-made songs (84-156 BPM) + EDGE- and AIST++-style stepping motions."""
    import soundfile as sf

    from quaddance.choreo.smpl import smpl_joints
    from quaddance.music.synth import render_song

    files = []
    for tempo, seed, swing, sync in HELD_OUT_SONGS:
        path = folder / f"song_{int(tempo)}bpm_seed{seed}.wav"
        if not path.exists():
            y, _ = render_song(tempo, duration_s, seed, swing=swing, syncopation=sync)
            with atomic_path(path) as tmp:
                sf.write(tmp, y, 22050)
        files.append(path)
    # EDGE style: full_pose (T, 24, 3) z-up metres at 30 fps.
    edge_poses = _stepping_poses(int(duration_s * 30), 30.0, 110.0, seed=9101)
    joints = smpl_joints(edge_poses, np.tile([0.0, 0.95, 0.0], (len(edge_poses), 1)))
    edge = {
        "smpl_poses": edge_poses,
        "smpl_trans": np.zeros((len(edge_poses), 3)),
        "full_pose": _y_up_to_z_up(joints),
    }
    # AIST++ style: poses + translation in centimetre-like units with a scaling, y-up, 60 fps.
    aist_poses = _stepping_poses(int(duration_s * 60), 60.0, 126.0, seed=9102)
    aist = {
        "smpl_poses": aist_poses,
        "smpl_trans": np.tile([0.0, 0.95 * 93.0, 0.0], (len(aist_poses), 1)),
        "smpl_scaling": np.array([93.0]),
    }
    files.append(_write_pickle(folder / "edge_style.pkl", edge))
    files.append(_write_pickle(folder / "aistpp_style.pkl", aist))
    return files


def _y_up_to_z_up(points: np.ndarray) -> np.ndarray:
    """(..., 3) y-up -> z-up: a proper rotation of +90 degrees about x."""
    return np.stack([points[..., 0], -points[..., 2], points[..., 1]], axis=-1)


# --- foot-height patterns of the other set ------------------------------------------------


@dataclass(frozen=True)
class FootLift:
    """One lift of one foot: rises, holds, falls; heights in metres, times in seconds."""

    foot: int  # 0 left, 1 right
    start_s: float
    rise_s: float
    hold_s: float
    fall_s: float
    height_m: float
    shape: str = "cos"  # "cos" (raised cosine), "linear" (trapezoid), "square"


def render_feet(lifts: list[FootLift], duration_s: float, fps: float) -> np.ndarray:
    """(T, 2) left/right foot heights, m, at ``fps``; overlapping lifts of a foot take the max."""
    t = np.arange(round(duration_s * fps)) / fps
    feet = np.zeros((t.size, 2))
    for lift in lifts:
        u = t - lift.start_s
        up = np.clip(u / max(lift.rise_s, 1e-9), 0.0, 1.0)
        down = np.clip((u - lift.rise_s - lift.hold_s) / max(lift.fall_s, 1e-9), 0.0, 1.0)
        ramp = up - down  # 0 -> 1 -> 0 over the lift
        if lift.shape == "cos":
            ramp = 0.5 - 0.5 * np.cos(np.pi * ramp)
        elif lift.shape == "square":
            ramp = (ramp > 0.5).astype(float)
        active = (u >= 0) & (u <= lift.rise_s + lift.hold_s + lift.fall_s)
        feet[:, lift.foot] = np.maximum(
            feet[:, lift.foot], np.where(active, ramp, 0.0) * lift.height_m
        )
    return feet


def _holds(rng: np.random.Generator, duration_s: float) -> list[FootLift]:
    """60 BPM: lift over half a beat, hold 3 beats, lower over half a beat, rest a beat."""
    beat = 1.0
    return [
        FootLift(k % 2, 1.0 + 5 * beat * k, 0.5, 3.0, 0.5, rng.uniform(0.28, 0.32))
        for k in range(int((duration_s - 1.0) // (5 * beat)))
    ]


def _alternation(rng: np.random.Generator, duration_s: float) -> list[FootLift]:
    """200 BPM: the feet alternate on every beat with quick small lifts."""
    beat = 60.0 / 200.0
    n = int((duration_s - 1.0) / beat)
    return [
        FootLift(k % 2, 0.5 + k * beat, 0.3 * beat, 0.0, 0.3 * beat, rng.uniform(0.06, 0.14))
        for k in range(n)
    ]


def _high_knees(rng: np.random.Generator, duration_s: float) -> list[FootLift]:
    """100 BPM: a knee lift to 0.5-0.6 m every other beat, alternating feet."""
    beat = 0.6
    n = int((duration_s - 1.5) / (2 * beat))
    return [
        FootLift(k % 2, 0.6 + 2 * beat * k, 0.5 * beat, 0.1, 0.6 * beat, rng.uniform(0.5, 0.6))
        for k in range(n)
    ]


def _double_steps(rng: np.random.Generator, duration_s: float) -> list[FootLift]:
    """150 BPM: the same foot twice (L L R R ...), triangular lifts, a rest beat per bar."""
    beat = 0.4
    lifts = []
    for bar in range(int((duration_s - 1.0) / (5 * beat))):
        for k, foot in enumerate((0, 0, 1, 1)):
            start = 0.5 + bar * 5 * beat + k * beat
            lifts.append(
                FootLift(foot, start, 0.3 * beat, 0.0, 0.3 * beat, rng.uniform(0.1, 0.2), "linear")
            )
    return lifts


def _offbeat_stomps(rng: np.random.Generator, duration_s: float) -> list[FootLift]:
    """80 BPM: square lifts (up and down within a frame) on the off-beats, some skipped."""
    beat = 0.75
    lifts = []
    for k in range(int((duration_s - 1.5) / beat)):
        if rng.random() < 0.25:
            continue
        lifts.append(FootLift(k % 2, 1.0 + (k + 0.5) * beat, 0.0, 0.4 * beat, 0.0, 0.2, "square"))
    return lifts


def _accelerando(rng: np.random.Generator, duration_s: float) -> list[FootLift]:
    """Tempo sweeping from 60 to 180 BPM: a step per beat, random heights 0.05-0.35 m."""
    lifts, t, k = [], 0.5, 0
    while True:
        bpm = 60.0 + 120.0 * min(t / (duration_s - 1.0), 1.0)
        beat = 60.0 / bpm
        if t + beat > duration_s - 0.5:
            return lifts
        lifts.append(FootLift(k % 2, t, 0.25 * beat, 0.0, 0.25 * beat, rng.uniform(0.05, 0.35)))
        t, k = t + beat, k + 1


def _jumps(rng: np.random.Generator, duration_s: float) -> list[FootLift]:
    """120 BPM bars: two single-foot lifts, then a two-foot jump of 0.1-0.15 m."""
    beat = 0.5
    lifts = []
    for bar in range(int((duration_s - 1.0) / (4 * beat))):
        t0 = 0.5 + 4 * beat * bar
        lifts.append(FootLift(0, t0, 0.2, 0.0, 0.2, rng.uniform(0.12, 0.2)))
        lifts.append(FootLift(1, t0 + beat, 0.2, 0.0, 0.2, rng.uniform(0.12, 0.2)))
        h = rng.uniform(0.1, 0.15)
        for foot in (0, 1):
            lifts.append(FootLift(foot, t0 + 2 * beat, 0.15, 0.1, 0.15, h))
    return lifts


def _stillness(rng: np.random.Generator, duration_s: float) -> list[FootLift]:
    """4 s standing still, then lifts at random times (off any grid), then 3 s still."""
    lifts, t = [], 4.0
    while True:
        t += rng.exponential(0.8) + 0.3
        rise = rng.uniform(0.15, 0.5)
        if t + 2 * rise > duration_s - 3.0:
            return lifts
        lifts.append(
            FootLift(
                int(rng.integers(2)), t, rise, rng.uniform(0, 0.3), rise, rng.uniform(0.05, 0.4)
            )
        )
        t += 2 * rise


# --- leg geometry: a foot height -> joint angles --------------------------------------------


def _leg_angles(lift_m: np.ndarray, thigh_m: float, shin_m: float, method: str) -> tuple:
    """Hip and knee flexion (rad, >= 0) that raise the ankle by ``lift_m`` above standing.

    ``curl``: knee only (the shin swings back); ``knee_lift``: the thigh swings forward and
    the shin hangs vertical; ``kick``: the straight leg swings forward.
    """
    angle = np.linspace(0.0, np.deg2rad(170.0), 2000)
    if method == "curl":
        rise = shin_m * (1 - np.cos(angle))
    elif method == "knee_lift":
        angle = np.linspace(0.0, np.deg2rad(125.0), 2000)
        rise = thigh_m * (1 - np.cos(angle))
    elif method == "kick":
        angle = np.linspace(0.0, np.deg2rad(100.0), 2000)
        rise = (thigh_m + shin_m) * (1 - np.cos(angle))
    else:
        raise QuaddanceError(f"unknown leg method {method!r}")
    a = np.interp(lift_m, rise, angle)  # rise is increasing on these ranges
    if method == "curl":
        return np.zeros_like(a), a
    if method == "knee_lift":
        return a, a
    return a, np.zeros_like(a)


# --- BVH writing ----------------------------------------------------------------------------


@dataclass(frozen=True)
class BvhSkeleton:
    """How a BVH file of the other set is laid out. Lengths in metres before ``unit_m``."""

    root: str
    spine: str
    leg: tuple[str, ...]  # left leg chain, hip to toe; "{s}" is replaced by the side's spelling
    sides: tuple[str, str]  # spelling of left and right inside the names
    unit_m: float  # metres per file unit
    up: str  # "y" or "z"
    order: str  # rotation channel order, e.g. "ZXY"
    fps: float
    thigh_m: float
    shin_m: float
    hip_joint: bool = False  # CMU's extra LHipJoint between the pelvis and the thigh
    positions_everywhere: bool = False  # 6 channels on every joint, as some exporters write


SKELETONS: dict[str, BvhSkeleton] = {
    "mixamo": BvhSkeleton(
        "mixamorig:Hips",
        "mixamorig:Spine",
        ("mixamorig:{s}UpLeg", "mixamorig:{s}Leg", "mixamorig:{s}Foot", "mixamorig:{s}ToeBase"),
        ("Left", "Right"),
        0.01,
        "y",
        "ZXY",
        30.0,
        0.42,
        0.41,
    ),
    "cmu": BvhSkeleton(
        "Hips",
        "LowerBack",
        ("{s}UpLeg", "{s}Leg", "{s}Foot", "{s}ToeBase"),
        ("Left", "Right"),
        0.0254,
        "y",
        "ZYX",
        120.0,
        0.45,
        0.44,
        hip_joint=True,
    ),
    "biped": BvhSkeleton(
        "Bip01 Pelvis",
        "Bip01 Spine",
        ("Bip01 {s} Thigh", "Bip01 {s} Calf", "Bip01 {s} Foot", "Bip01 {s} Toe0"),
        ("L", "R"),
        0.001,
        "z",
        "YXZ",
        60.0,
        0.44,
        0.43,
        positions_everywhere=True,
    ),
    "smpl_names": BvhSkeleton(
        "Pelvis",
        "Spine1",
        ("{s}_Hip", "{s}_Knee", "{s}_Ankle", "{s}_Foot"),
        ("L", "R"),
        1.0,
        "y",
        "XYZ",
        25.0,
        0.39,
        0.43,
    ),
    "blender": BvhSkeleton(
        "hips",
        "spine",
        ("thigh.{s}", "shin.{s}", "foot.{s}", "toe.{s}"),
        ("L", "R"),
        1.0,
        "z",
        "XZY",
        24.0,
        0.36,
        0.37,
    ),
}


def write_bvh(path: Path, skel: BvhSkeleton, feet_m: np.ndarray, method: str, seed: int) -> Path:
    """A BVH file of ``skel`` whose ankles rise by ``feet_m`` (T, 2) above standing.

    The pelvis sways in yaw and each hip has a little abduction, so the rotation order of the
    channels matters; lengths are written in the skeleton's unit and axes.
    """
    rng = np.random.default_rng(seed)
    n = feet_m.shape[0]
    t = np.arange(n) / skel.fps
    u = 1.0 / skel.unit_m  # file units per metre
    up = 1 if skel.up == "y" else 2
    # Offsets are written y-up (x left, z forward) then turned to z-up if needed.
    place = (lambda v: np.asarray(v)) if up == 1 else _y_up_to_z_up
    flex_sign = -1.0 if up == 1 else 1.0  # hip flexion about x brings the thigh forward
    yaw_axis, abd_axis = (1, 2) if up == 1 else (2, 1)

    joints: list[tuple[str, int, np.ndarray]] = []  # name, parent, offset (file units)
    angles: list[np.ndarray] = []  # (T, 3) degrees about file x, y, z per joint

    def add(name: str, parent: int, offset_m) -> int:
        joints.append((name, parent, place(np.asarray(offset_m, float)) * u))
        angles.append(np.zeros((n, 3)))
        return len(joints) - 1

    root_height_m = skel.thigh_m + skel.shin_m + 0.1
    root = add(skel.root, -1, [0.0, 0.0, 0.0])
    angles[root][:, yaw_axis] = 10.0 * np.sin(2 * np.pi * 0.25 * t)  # slow turning sway
    add(skel.spine, root, [0.0, 0.12, -0.01])
    ends = {len(joints) - 1: [0.0, 0.45, 0.0]}
    for side, sign in ((0, 1.0), (1, -1.0)):
        leg = [part.replace("{s}", skel.sides[side]) for part in skel.leg]
        parent = root
        hip_off = [sign * 0.09, -0.07, 0.0]
        if skel.hip_joint:
            parent = add(leg[0].replace("UpLeg", "HipJoint"), root, [sign * 0.02, -0.02, 0.0])
            hip_off = [sign * 0.07, -0.05, 0.0]
        hip = add(leg[0], parent, hip_off)
        knee = add(leg[1], hip, [0.0, -skel.thigh_m, 0.0])
        add(leg[2], knee, [0.0, -skel.shin_m, 0.0])
        toe = add(leg[3], len(joints) - 1, [0.0, -0.05, 0.12])
        ends[toe] = [0.0, 0.0, 0.05]
        hip_rad, knee_rad = _leg_angles(feet_m[:, side], skel.thigh_m, skel.shin_m, method)
        angles[hip][:, 0] = flex_sign * np.rad2deg(hip_rad)
        angles[knee][:, 0] = -flex_sign * np.rad2deg(knee_rad)
        angles[hip][:, abd_axis] = sign * rng.uniform(2.0, 5.0)

    root_pos = np.zeros((n, 3))
    root_pos[:, 1] = root_height_m
    root_pos = place(root_pos) * u

    axis_index = {"X": 0, "Y": 1, "Z": 2}
    rot_channels = [f"{a}rotation" for a in skel.order]
    lines = ["HIERARCHY"]
    columns: list[np.ndarray] = []
    depth_of: dict[int, int] = {}

    def open_block(j: int) -> None:
        name, parent, offset = joints[j]
        depth = 0 if parent < 0 else depth_of[parent] + 1
        depth_of[j] = depth
        pad = "  " * depth
        lines.append(f"{pad}{'ROOT' if parent < 0 else 'JOINT'} {name}")
        lines.append(f"{pad}{{")
        lines.append(f"{pad}  OFFSET {offset[0]:.6f} {offset[1]:.6f} {offset[2]:.6f}")
        with_pos = parent < 0 or skel.positions_everywhere
        chans = (["Xposition", "Yposition", "Zposition"] if with_pos else []) + rot_channels
        lines.append(f"{pad}  CHANNELS {len(chans)} {' '.join(chans)}")
        if with_pos:
            pos = root_pos if parent < 0 else np.broadcast_to(offset, (n, 3))
            columns.extend(pos[:, k] for k in range(3))
        columns.extend(angles[j][:, axis_index[a]] for a in skel.order)
        for child in (k for k, (_, p, _) in enumerate(joints) if p == j):
            open_block(child)
        if j in ends:
            end = place(np.asarray(ends[j], float)) * u
            lines.extend(
                [
                    f"{pad}  End Site",
                    f"{pad}  {{",
                    f"{pad}    OFFSET {end[0]:.6f} {end[1]:.6f} {end[2]:.6f}",
                    f"{pad}  }}",
                ]
            )
        lines.append(f"{pad}}}")

    open_block(root)
    values = np.stack(columns, axis=1)
    lines += ["MOTION", f"Frames: {n}", f"Frame Time: {1.0 / skel.fps:.7f}"]
    lines += [" ".join(f"{v:.5f}" for v in row) for row in values]
    with atomic_path(path) as tmp:
        tmp.write_text("\n".join(lines) + "\n")
    return path


# --- SMPL-based files of the other set -------------------------------------------------------


def _smpl_leg_poses(feet_m: np.ndarray, method: str) -> np.ndarray:
    """(T, 72) SMPL axis-angle poses whose ankles rise by ``feet_m`` (T, 2) (y-up body)."""
    from quaddance.choreo import smpl

    rest = smpl.smpl_joints(np.zeros((1, 72)), np.zeros((1, 3)))[0]
    poses = np.zeros((feet_m.shape[0], 72))
    for side, (hip, knee, ankle) in enumerate(((1, 4, 7), (2, 5, 8))):
        thigh = float(np.linalg.norm(rest[knee] - rest[hip]))
        shin = float(np.linalg.norm(rest[ankle] - rest[knee]))
        hip_rad, knee_rad = _leg_angles(feet_m[:, side], thigh, shin, method)
        poses[:, 3 * hip] = -hip_rad  # SMPL: negative x rotation brings the thigh forward
        poses[:, 3 * knee] = knee_rad
    return poses


def _edge_full_pose_direct(feet_m: np.ndarray) -> dict:
    """EDGE ``full_pose`` (T, 24, 3), z-up, with ankle and toe paths set by hand (no FK)."""
    from quaddance.choreo import smpl

    rest = smpl.smpl_joints(np.zeros((1, 72)), np.array([[0.0, 0.95, 0.0]]))[0]
    joints = np.repeat(_y_up_to_z_up(rest)[None], feet_m.shape[0], axis=0)
    for side, (knee, ankle, toe) in enumerate(((4, 7, 10), (5, 8, 11))):
        joints[:, ankle, 2] += feet_m[:, side]
        joints[:, toe, 2] += feet_m[:, side]
        joints[:, knee, 2] += 0.5 * feet_m[:, side]
    return {"full_pose": joints, "fps": np.array(30.0)}


def _edge_params_with_jumps(feet_m: np.ndarray) -> dict:
    """EDGE SMPL parameters (no full_pose): a jump lifts the pelvis, a single lift curls."""
    both = np.minimum(feet_m[:, 0], feet_m[:, 1])  # the part both feet share is a jump
    single = feet_m - both[:, None]
    trans = np.zeros((feet_m.shape[0], 3))
    trans[:, 1] = 0.95 + both
    return {"smpl_poses": _smpl_leg_poses(single, "curl"), "smpl_trans": trans}


def _aist_curls_with_bounce(feet_m: np.ndarray, fps: float, scaling: float) -> dict:
    """AIST++ pickle: knee curls, a 1 cm bounce of the pelvis at 2 Hz, units of ``scaling``."""
    t = np.arange(feet_m.shape[0]) / fps
    trans = np.zeros((feet_m.shape[0], 3))
    trans[:, 1] = 0.95 - 0.01 * (0.5 - 0.5 * np.cos(2 * np.pi * 2.0 * t))
    return {
        "smpl_poses": _smpl_leg_poses(feet_m, "curl"),
        "smpl_trans": trans * scaling,
        "smpl_scaling": np.array([scaling]),
    }


@dataclass(frozen=True)
class OtherItem:
    """One file of the other set: a foot pattern written in one format."""

    name: str
    pattern: Callable[[np.random.Generator, float], list[FootLift]]
    fmt: str  # a key of SKELETONS, or "edge_full_pose", "edge_params", "aist"
    method: str = "curl"  # leg geometry for BVH / SMPL formats
    seed: int = 0


OTHER_ITEMS: tuple[OtherItem, ...] = (
    OtherItem("holds_60bpm_mixamo_cm.bvh", _holds, "mixamo", "knee_lift", 9201),
    OtherItem("alternation_200bpm_cmu_inch.bvh", _alternation, "cmu", "curl", 9202),
    OtherItem("high_knees_100bpm_biped_mm_zup.bvh", _high_knees, "biped", "knee_lift", 9203),
    OtherItem("double_steps_150bpm_smplnames_m.bvh", _double_steps, "smpl_names", "curl", 9204),
    OtherItem("stillness_irregular_blender_zup.bvh", _stillness, "blender", "kick", 9205),
    OtherItem(
        "offbeat_square_80bpm_edge_fullpose.pkl", _offbeat_stomps, "edge_full_pose", seed=9206
    ),
    OtherItem("jumps_120bpm_edge_params.pkl", _jumps, "edge_params", seed=9207),
    OtherItem("accelerando_60_180bpm_aistpp.pkl", _accelerando, "aist", seed=9208),
)


def write_other_set(folder: Path, duration_s: float = 20.0) -> list[Path]:
    """The motions of the ``other`` set (see the module doc); returns their paths."""
    files = []
    for item in OTHER_ITEMS:
        path = folder / item.name
        rng = np.random.default_rng(item.seed)
        lifts = item.pattern(rng, duration_s)
        if item.fmt in SKELETONS:
            skel = SKELETONS[item.fmt]
            feet = render_feet(lifts, duration_s, skel.fps)
            write_bvh(path, skel, feet, item.method, item.seed)
        elif item.fmt == "edge_full_pose":
            _write_pickle(path, _edge_full_pose_direct(render_feet(lifts, duration_s, 30.0)))
        elif item.fmt == "edge_params":
            _write_pickle(path, _edge_params_with_jumps(render_feet(lifts, duration_s, 30.0)))
        elif item.fmt == "aist":
            _write_pickle(
                path, _aist_curls_with_bounce(render_feet(lifts, duration_s, 60.0), 60.0, 93.0)
            )
        else:
            raise QuaddanceError(f"unknown held-out format {item.fmt!r}")
        files.append(path)
    return files


def write_held_out_set(
    folder: Path, which: str = "generator", duration_s: float = 20.0
) -> list[Path]:
    """Write held-out set ``which`` (`HELD_OUT_SETS`) into ``folder``; returns its files."""
    if which not in HELD_OUT_SETS:
        raise QuaddanceError(
            f"unknown held-out set {which!r}: use one of {', '.join(HELD_OUT_SETS)}"
        )
    ensure_dir(folder)  # a file in its place is one line, not a FileExistsError
    if which == "generator":
        return write_generator_set(folder, duration_s)
    return write_other_set(folder, duration_s)
