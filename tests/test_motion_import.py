"""Motion import: safe pickles, SMPL forward kinematics, BVH, and EDGE / AIST++ / BVH feet."""

from __future__ import annotations

import builtins
import os
import pickle
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from quaddance.choreo.bvh import find_ankles, guess_unit, load_bvh
from quaddance.choreo.motion import load_motion
from quaddance.choreo.safe_pickle import safe_load_pickle
from quaddance.choreo.smpl import LEFT_ANKLE, RIGHT_ANKLE, smpl_joints
from quaddance.errors import InputFileError
from quaddance.play.heldout import SKELETONS, write_bvh

# SMPL joint indices used to pose the legs (SMPL order: 1/2 hips, 4/5 knees).
L_HIP, R_HIP, L_KNEE, R_KNEE = 1, 2, 4, 5
# Rest legs point down (-y) with +z forward: a negative x rotation swings the thigh forward.
HIP_FLEX_SIGN = -1.0

# ---------------------------------------------------------------------------------------------
# safe pickles


class _RunsShell:
    def __init__(self, command: str) -> None:
        self.command = command

    def __reduce__(self) -> tuple[object, tuple[str]]:
        return (os.system, (self.command,))


class _RunsEval:
    def __init__(self, source: str) -> None:
        self.source = source

    def __reduce__(self) -> tuple[object, tuple[str]]:
        return (builtins.eval, (self.source,))


def _write_pickle(path: Path, obj: object, protocol: int = 4) -> Path:
    path.write_bytes(pickle.dumps(obj, protocol=protocol))
    return path


@pytest.mark.parametrize(
    ("make", "refused_name"),
    [
        (lambda s: _RunsShell(f"touch {s}"), "system"),
        (lambda s: _RunsEval(f"open({str(s)!r}, 'w').close()"), "builtins.eval"),
        # Inside a dict of arrays, and as an element of an object array.
        (lambda s: {"full_pose": np.zeros(3), "x": _RunsShell(f"touch {s}")}, "system"),
        (lambda s: np.array([1.0, _RunsShell(f"touch {s}")], dtype=object), "system"),
    ],
)
def test_malicious_pickle_is_refused_and_runs_nothing(tmp_path, make, refused_name):
    sentinel = tmp_path / "SENTINEL"
    for protocol in (0, 2, 5):
        path = _write_pickle(tmp_path / f"evil{protocol}.pkl", make(sentinel), protocol)
        with pytest.raises(InputFileError, match="refused: pickle references") as err:
            safe_load_pickle(path)
        assert refused_name in str(err.value)
        assert path.name in str(err.value)
        assert not sentinel.exists()


@pytest.mark.parametrize(
    "name",
    [
        "builtins.getattr",
        "builtins.exec",
        "builtins.__import__",
        "subprocess.Popen",
        "torch._utils._rebuild_tensor_v2",
        "numpy.load",
        "numpy.frombuffer",
        "collections.OrderedDict",
        "numpy.core.multiarray.fromstring",
    ],
)
def test_any_other_global_is_refused(tmp_path, name):
    # Hand-written protocol-0 pickle: GLOBAL <module> <name>, call it with ("x",).
    module, attr = name.rsplit(".", 1)
    path = tmp_path / "global.pkl"
    path.write_bytes(f"c{module}\n{attr}\n(Vx\ntR.".encode())
    with pytest.raises(InputFileError, match="which could run code") as err:
        safe_load_pickle(path)
    assert attr in str(err.value)


def test_persistent_ids_are_refused(tmp_path):
    # torch.save's pickles fetch tensor storages through persistent ids.
    class StoragePickler(pickle.Pickler):
        def persistent_id(self, obj: object) -> str | None:
            return "storage0" if obj == "tensor" else None

    path = tmp_path / "torch_like.pkl"
    with path.open("wb") as f:
        StoragePickler(f, protocol=2).dump({"w": "tensor"})
    with pytest.raises(InputFileError, match="persistent ids"):
        safe_load_pickle(path)


@pytest.mark.parametrize("protocol", [0, 1, 2, 3, 4, 5])
def test_benign_numpy_pickles_load_at_every_protocol(tmp_path, protocol):
    data = {
        "smpl_poses": np.random.default_rng(0).normal(size=(5, 72)).astype(np.float32),
        "big_endian": np.arange(4, dtype=">f8"),
        "fortran": np.asfortranarray(np.arange(6.0).reshape(2, 3)),
        "scaling": np.float64(93.5),
        "frames": np.int64(120),
        "mask": np.array([[True, False]]),
        "counts": np.arange(3, dtype=np.uint16),
        "containers": [(1, 2), {3}, frozenset({4}), b"raw", bytearray(b"ab"), 2.5, None, True],
    }
    path = _write_pickle(tmp_path / "ok.pkl", data, protocol)
    loaded = safe_load_pickle(path)
    trusted = pickle.loads(path.read_bytes())  # our own file: plain pickle is the reference
    assert loaded.keys() == data.keys()
    for key in ("smpl_poses", "big_endian", "fortran", "mask", "counts"):
        np.testing.assert_array_equal(loaded[key], data[key])
        np.testing.assert_array_equal(loaded[key], trusted[key])
        # Rebuilt from the type string, in native byte order (numpy's own loader is not
        # consistent about byte order across protocols).
        assert loaded[key].dtype == data[key].dtype.newbyteorder("=")
        assert loaded[key].flags.writeable
    assert loaded["fortran"].flags.f_contiguous
    assert loaded["scaling"] == np.float64(93.5)
    assert loaded["frames"] == 120 and loaded["frames"].dtype == np.int64
    assert loaded["containers"] == data["containers"]


@pytest.mark.parametrize(
    ("value", "problem"),
    [
        (np.array([1, "x", (2, 3)], dtype=object), "not a real number"),
        (np.array(["ab", "c"]), "not a real number"),
        (np.arange(3) + 1j, "not a real number"),
        (np.complex128(1 + 2j), "not a real number"),
        (1 + 2j, "complex"),
        (np.zeros(2, dtype=[("a", "f8")]), "not a real number"),
        (np.array(["2020-01-01"], dtype="datetime64[D]"), "not a real number"),
    ],
    ids=["object", "text", "complex", "complex_scalar", "complex_number", "struct", "date"],
)
def test_non_real_arrays_are_refused(tmp_path, value, problem):
    # Issue 12: complex, object and other non-real dtypes are refused, at every protocol.
    for protocol in (0, 2, 5):
        path = _write_pickle(tmp_path / f"v{protocol}.pkl", {"full_pose": value}, protocol)
        with pytest.raises(InputFileError, match=problem) as err:
            safe_load_pickle(path)
        assert path.name in str(err.value)


def test_numpy1_spelling_of_array_pickles_loads(tmp_path):
    # Pickles written by numpy 1.x (e.g. AIST++) name numpy.core.multiarray, not numpy._core.
    raw = pickle.dumps({"a": np.arange(3.0)}, protocol=2)
    assert b"numpy._core.multiarray" in raw
    path = tmp_path / "np1.pkl"
    path.write_bytes(raw.replace(b"numpy._core.multiarray", b"numpy.core.multiarray"))
    np.testing.assert_array_equal(safe_load_pickle(path)["a"], np.arange(3.0))


@pytest.mark.parametrize(
    "content",
    [b"\x00\x01garbage bytes", b"", b"PK\x03\x04zipzip"],
    ids=["garbage", "empty", "zip"],
)
def test_non_pickles_are_clear_errors(tmp_path, content):
    path = tmp_path / "bad.pkl"
    path.write_bytes(content)
    with pytest.raises(InputFileError, match=r"bad\.pkl"):
        safe_load_pickle(path)


def test_truncated_pickle_is_an_error(tmp_path):
    raw = pickle.dumps({"a": np.arange(100.0)}, protocol=4)
    path = tmp_path / "cut.pkl"
    path.write_bytes(raw[: len(raw) // 2])
    with pytest.raises(InputFileError, match="truncated"):
        safe_load_pickle(path)


# ---------------------------------------------------------------------------------------------
# SMPL forward kinematics


def test_zero_pose_is_the_rest_skeleton():
    joints = smpl_joints(np.zeros((1, 72)), np.array([[0.3, 1.0, -0.2]]))[0]
    np.testing.assert_allclose(joints[0], [0.3, 1.0, -0.2])
    for hip, ankle in ((L_HIP, LEFT_ANKLE), (R_HIP, RIGHT_ANKLE)):
        drop_m = joints[hip, 1] - joints[ankle, 1]
        assert 0.75 < drop_m < 0.9  # an adult's thigh + shank
    assert joints[LEFT_ANKLE, 0] > 0.3 > joints[RIGHT_ANKLE, 0]  # SMPL's left is +x
    assert joints[15, 1] - joints[LEFT_ANKLE, 1] > 1.3  # head well above the ankles


def test_knee_bend_raises_the_ankle_by_the_shank_geometry():
    poses = np.zeros((2, 72))
    poses[1, 3 * L_KNEE] = np.pi / 2  # knee flexion: +x rotation swings the shank backwards
    joints = smpl_joints(poses, np.zeros((2, 3)))
    rise_m = joints[1, LEFT_ANKLE, 1] - joints[0, LEFT_ANKLE, 1]
    # A 90-degree bend brings the 0.43 m shank level with the knee.
    assert 0.38 < rise_m < 0.47
    assert joints[1, LEFT_ANKLE, 2] < joints[0, LEFT_ANKLE, 2] - 0.35  # foot went backwards
    np.testing.assert_allclose(joints[1, RIGHT_ANKLE], joints[0, RIGHT_ANKLE])


def test_global_orientation_rotates_the_whole_body():
    poses = np.zeros((1, 72))
    poses[0, 0] = np.pi / 2  # +90 degrees about x maps y-up to z-up
    upright = smpl_joints(np.zeros((1, 72)), np.zeros((1, 3)))[0]
    turned = smpl_joints(poses, np.zeros((1, 3)))[0]
    np.testing.assert_allclose(turned[:, 2], upright[:, 1], atol=1e-12)
    np.testing.assert_allclose(turned[:, 1], -upright[:, 2], atol=1e-12)


def test_rotations_compose_down_the_chain():
    # Random turns of pelvis, left hip and knee; the left ankle, chained by hand with scipy.
    rng = np.random.default_rng(3)
    poses = np.zeros((4, 72))
    for joint in (0, L_HIP, L_KNEE):
        poses[:, 3 * joint : 3 * joint + 3] = rng.normal(scale=0.8, size=(4, 3))
    trans = rng.normal(size=(4, 3))
    ankle = smpl_joints(poses, trans)[:, LEFT_ANKLE]
    offsets = {  # FACTS.md section 3
        L_HIP: [0.05858135, -0.08228004, -0.01766408],
        L_KNEE: [0.04345142, -0.38646945, 0.008037],
        LEFT_ANKLE: [-0.01479032, -0.42687458, -0.037428],
    }
    expected = trans.copy()
    rotation = Rotation.identity(4)
    for parent, joint in ((0, L_HIP), (L_HIP, L_KNEE), (L_KNEE, LEFT_ANKLE)):
        rotation = rotation * Rotation.from_rotvec(poses[:, 3 * parent : 3 * parent + 3])
        expected += rotation.apply(offsets[joint])
    np.testing.assert_allclose(ankle, expected, atol=1e-12)


# ---------------------------------------------------------------------------------------------
# synthetic EDGE and AIST++ files


def _stepping(n_frames: int, fps: float, step_hz: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """SMPL poses of alternate knee-up steps: left on the first half of each cycle, right on
    the second. Returns (poses (T, 72), hip flexion angle (T, 2) of (left, right), rad)."""
    phase = 2 * np.pi * step_hz * np.arange(n_frames) / fps
    flex = 0.8 * np.stack([np.maximum(np.sin(phase), 0), np.maximum(-np.sin(phase), 0)], axis=1)
    poses = np.zeros((n_frames, 72))
    for side, (hip, knee) in enumerate(((L_HIP, L_KNEE), (R_HIP, R_KNEE))):
        poses[:, 3 * hip] = HIP_FLEX_SIGN * flex[:, side]  # thigh forward
        poses[:, 3 * knee] = 2 * flex[:, side]  # shank back: shank angle = -thigh angle
    return poses, flex


def _expected_lift_m(flex: np.ndarray) -> np.ndarray:
    """Ankle rise (T, 2) of the `_stepping` legs, from the rest offsets in the sagittal plane.

    A bone (y, z) turned by b about x gets height y cos b - z sin b; the thigh turns by -a and
    the shank by +a, so the rise is -(y_thigh + y_shank)(1 - cos a) + (z_thigh - z_shank) sin a.
    """
    thigh_yz = np.array([[-0.38646945, 0.008037], [-0.38368791, -0.00484304]])  # joints 4, 5
    shank_yz = np.array([[-0.42687458, -0.037428], [-0.4200455, -0.03456167]])  # joints 7, 8
    length = -(thigh_yz[:, 0] + shank_yz[:, 0])
    lean = thigh_yz[:, 1] - shank_yz[:, 1]
    return length * (1 - np.cos(flex)) + lean * np.sin(flex)


def test_edge_pickle_recovers_the_stepping_pattern(tmp_path):
    fps, n_frames = 30, 120
    poses, flex = _stepping(n_frames, fps)
    trans = np.zeros((n_frames, 3))
    trans[:, 2] = np.linspace(0, 1, n_frames)  # walks forward while stepping
    joints_y_up = smpl_joints(poses, trans)
    # EDGE's full_pose is z-up: new z = old y; the floor at z = 0.5 m.
    full_pose = np.stack(
        [joints_y_up[..., 0], -joints_y_up[..., 2], joints_y_up[..., 1] + 0.5], axis=-1
    )
    path = _write_pickle(
        tmp_path / "edge.pkl",
        {"smpl_poses": poses, "smpl_trans": trans, "full_pose": full_pose.astype(np.float32)},
    )
    motion = load_motion(path)
    assert motion.fps == 30
    assert motion.feet_m.shape == (n_frames, 2)
    np.testing.assert_allclose(motion.feet_m, _expected_lift_m(flex), atol=0.003)
    assert motion.feet_m[:, 0].max() > 0.2  # lifts happen (0.8 rad: about 0.25 m)
    assert "edge.pkl" in motion.source

    # Only the SMPL parameters, rotated to z-up: the up axis is found from the body.
    poses_z_up = poses.copy()
    poses_z_up[:, 0] = np.pi / 2  # global orientation +90 degrees about x: y-up -> z-up
    trans_z_up = np.stack([trans[:, 0], -trans[:, 2], trans[:, 1] + 0.5], axis=-1)
    path = _write_pickle(
        tmp_path / "edge_params.pkl",
        {"smpl_poses": poses_z_up, "smpl_trans": trans_z_up, "fps": 25},
    )
    motion = load_motion(path)
    assert motion.fps == 25
    np.testing.assert_allclose(motion.feet_m, _expected_lift_m(flex), atol=0.003)


def test_aist_pickle_uses_scaling_and_estimates_the_floor(tmp_path):
    fps, n_frames, scaling = 60, 150, 93.7
    poses, flex = _stepping(n_frames, fps, step_hz=2.0)
    trans_m = np.zeros((n_frames, 3))
    trans_m[:, 1] = 1.7  # the floor is not at 0
    trans_m[:, 0] = np.linspace(-0.5, 0.5, n_frames)
    # Four 0.1 m hops of the whole body: both feet leave the floor, by a scaled translation.
    hop_m = 0.1 * np.maximum(np.sin(2 * np.pi * 1.6 * np.arange(n_frames) / fps), 0) ** 8
    trans_m[:, 1] += hop_m
    path = _write_pickle(
        tmp_path / "aist.pkl",
        {
            "smpl_poses": poses.astype(np.float32),
            "smpl_trans": trans_m * scaling,
            "smpl_scaling": np.array([scaling]),
            "smpl_loss": np.float64(0.1),
        },
        protocol=2,
    )
    motion = load_motion(path)
    assert motion.fps == 60
    expected = _expected_lift_m(flex) + hop_m[:, None]
    np.testing.assert_allclose(motion.feet_m, expected, atol=0.003)
    assert motion.duration_s == pytest.approx(2.5)


# ---------------------------------------------------------------------------------------------
# BVH

_BVH_HIERARCHY = """HIERARCHY
ROOT Hips
{
\tOFFSET 0.00 0.00 0.00
\tCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
\tJOINT LeftUpLeg
\t{
\t\tOFFSET 10.0 -5.0 0.0
\t\tCHANNELS 3 Zrotation Xrotation Yrotation
\t\tJOINT LeftLeg
\t\t{
\t\t\tOFFSET 0.0 -45.0 0.0
\t\t\tCHANNELS 3 Zrotation Xrotation Yrotation
\t\t\tJOINT LeftFoot
\t\t\t{
\t\t\t\tOFFSET 0.0 -45.0 0.0
\t\t\t\tCHANNELS 3 Zrotation Xrotation Yrotation
\t\t\t\tEnd Site
\t\t\t\t{
\t\t\t\t\tOFFSET 0.0 -5.0 12.0
\t\t\t\t}
\t\t\t}
\t\t}
\t}
\tJOINT RightUpLeg
\t{
\t\tOFFSET -10.0 -5.0 0.0
\t\tCHANNELS 3 Zrotation Xrotation Yrotation
\t\tJOINT RightLeg
\t\t{
\t\t\tOFFSET 0.0 -45.0 0.0
\t\t\tCHANNELS 3 Zrotation Xrotation Yrotation
\t\t\tJOINT RightFoot
\t\t\t{
\t\t\t\tOFFSET 0.0 -45.0 0.0
\t\t\t\tCHANNELS 3 Zrotation Xrotation Yrotation
\t\t\t\tEnd Site
\t\t\t\t{
\t\t\t\t\tOFFSET 0.0 -5.0 12.0
\t\t\t\t}
\t\t\t}
\t\t}
\t}
\tJOINT Spine
\t{
\t\tOFFSET 0.0 10.0 0.0
\t\tCHANNELS 3 Zrotation Xrotation Yrotation
\t\tEnd Site
\t\t{
\t\t\tOFFSET 0.0 60.0 0.0
\t\t}
\t}
}
"""


def _leg_lift_bvh(path: Path, n_frames: int, frame_time_s: float, hip_deg: np.ndarray) -> None:
    """The skeleton above (Y-up, cm) standing at hip height 100 cm, the left thigh raised
    forward by ``hip_deg`` (T,) degrees (negative x rotation swings +y-down legs to +z)."""
    lines = [_BVH_HIERARCHY + "MOTION", f"Frames: {n_frames}", f"Frame Time: {frame_time_s}"]
    for t in range(n_frames):
        root = [3.0 * t, 100.0, 0.0, 0.0, 0.0, 0.0]
        left_hip = [0.0, -hip_deg[t], 0.0]
        lines.append(" ".join(f"{v:.4f}" for v in root + left_hip + [0.0] * 18))
    path.write_text("\n".join(lines) + "\n")


def test_bvh_left_foot_lifts_by_the_right_amount(tmp_path):
    n_frames, frame_time_s = 48, 0.041667  # written rounded, as exporters do for 24 fps
    hip_deg = np.where(np.arange(n_frames) % 24 < 12, 0.0, 60.0)
    path = tmp_path / "leg.bvh"
    _leg_lift_bvh(path, n_frames, frame_time_s, hip_deg)

    parsed = load_bvh(path)
    legs = [f"{side}{part}" for side in ("Left", "Right") for part in ("UpLeg", "Leg", "Foot")]
    assert parsed.joint_names == ("Hips", *legs, "Spine")
    assert parsed.positions.shape == (n_frames, 8, 3)
    left_foot = parsed.positions[:, 3]
    # Standing: ankle 95 cm below the hips; thigh up 60 degrees: forward by 90 sin 60 cm.
    np.testing.assert_allclose(left_foot[0], [10.0, 5.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(left_foot[12], [10.0 + 36.0, 100 - 5 - 90 * 0.5, 90 * 0.866], 0.01)

    motion = load_motion(path)
    assert motion.fps == 24.0
    bom = tmp_path / "bom"  # a byte-order mark, and no suffix: found by its first bytes
    bom.write_bytes(b"\xef\xbb\xbf" + path.read_bytes())
    np.testing.assert_array_equal(load_motion(bom).feet_m, motion.feet_m)
    lifted = hip_deg > 0
    # 90 cm leg raised 60 degrees: the ankle rises 45 cm = 0.45 m; the right foot stays down.
    np.testing.assert_allclose(motion.feet_m[lifted, 0], 0.45, atol=1e-6)
    np.testing.assert_allclose(motion.feet_m[~lifted, 0], 0.0, atol=1e-6)
    np.testing.assert_allclose(motion.feet_m[:, 1], 0.0, atol=1e-6)
    assert "cm" in motion.source and "y-up" in motion.source


def test_bvh_z_up_in_metres_is_detected(tmp_path):
    # The same skeleton in metres with z up: swap y and z in offsets and root positions.
    n_frames, fps = 40, 40
    hierarchy = _BVH_HIERARCHY
    for cm, m in (("-10.0 -5.0 0.0", "-0.10 0.0 -0.05"), ("10.0 -5.0 0.0", "0.10 0.0 -0.05")):
        hierarchy = hierarchy.replace(cm, m)
    hierarchy = hierarchy.replace("0.0 -45.0 0.0", "0.0 0.0 -0.45")
    hierarchy = hierarchy.replace("0.0 10.0 0.0", "0.0 0.0 0.10")
    lines = [hierarchy + "MOTION", f"Frames: {n_frames}", f"Frame Time: {1 / fps}"]
    for t in range(n_frames):
        lift_deg = 60.0 if t >= n_frames // 2 else 0.0
        # Right thigh this time: 60 degrees about x lifts a -z leg by half its length.
        row = [0.0, 0.0, 1.0, 0.0, 0.0, 0.0] + [0.0] * 9 + [0.0, lift_deg, 0.0] + [0.0] * 9
        lines.append(" ".join(f"{v:.4f}" for v in row))
    path = tmp_path / "zup.bvh"
    path.write_text("\n".join(lines) + "\n")
    motion = load_motion(path)
    assert "m, z-up" in motion.source
    np.testing.assert_allclose(motion.feet_m[n_frames // 2 :, 1], 0.45, atol=1e-6)
    np.testing.assert_allclose(motion.feet_m[:, 0], 0.0, atol=1e-6)


def test_cmu_skeleton_units_are_told_from_inches():
    # The CMU database's BVH conversions keep its ASF unit (1/0.45 inch): the root-to-ankle
    # chain of an adult subject is about 0 + 2.7 + 6.9 + 7.4 = 17 units (LHipJoint, LeftUpLeg,
    # LeftLeg, LeftFoot offsets), which in inches would be a 0.43 m leg.
    assert guess_unit(17.0)[0] == "cmu"
    assert guess_unit(35.0)[0] == "inch"  # the same leg exported in inches
    assert guess_unit(90.0)[0] == "cm"


@pytest.mark.parametrize(("unit", "unit_m"), [("cmu", 0.0254 / 0.45), ("inch", 0.0254)])
def test_bvh_lifts_come_out_in_metres_whatever_the_unit(tmp_path, unit, unit_m):
    # A CMU-layout skeleton (its LHipJoint included) written in CMU units and in inches: the
    # same lifts in metres either way.
    feet_m = np.zeros((240, 2))
    feet_m[40:80, 0] = 0.2
    feet_m[140:180, 1] = 0.3
    skel = replace(SKELETONS["cmu"], unit_m=unit_m)
    path = write_bvh(tmp_path / f"{unit}.bvh", skel, feet_m, "curl", seed=3)
    motion = load_motion(path)
    assert f"BVH, {unit}," in motion.source
    lift = motion.feet_m - motion.feet_m[:20].mean(axis=0)
    np.testing.assert_allclose(lift[50:70, 0], 0.2, atol=0.01)
    np.testing.assert_allclose(lift[150:170, 1], 0.3, atol=0.01)


@pytest.mark.parametrize("order", ["ZXY", "XYZ", "YZX"])
def test_bvh_euler_order_follows_the_channels(tmp_path, order):
    # One bone turned by three angles at once; scipy's intrinsic Euler rotation is the reference.
    angles_deg = np.array([[25.0, -40.0, 70.0], [-10.0, 80.0, 5.0]])
    channels = " ".join(f"{axis}rotation" for axis in order)
    text = (
        "HIERARCHY\nROOT Hips\n{\n OFFSET 0 0 0\n CHANNELS 3 " + channels + "\n"
        " JOINT LeftFoot\n {\n  OFFSET 3 -40 7\n  CHANNELS 0\n"
        "  End Site\n  {\n   OFFSET 0 -1 0\n  }\n }\n}\n"
        "MOTION\nFrames: 2\nFrame Time: 0.5\n"
        + "\n".join(" ".join(map(str, row)) for row in angles_deg)
    )
    path = tmp_path / f"{order}.bvh"
    path.write_text(text)
    foot = load_bvh(path).positions[:, 1]
    expected = Rotation.from_euler(order, angles_deg, degrees=True).apply([3.0, -40.0, 7.0])
    np.testing.assert_allclose(foot, expected, atol=1e-9)


def test_ankle_names_are_found_across_conventions():
    cases = {
        ("Hips", "LeftFoot", "LeftToeBase", "RightFoot", "RightToeBase"): (1, 3),
        ("Pelvis", "L_Foot", "L_Ankle", "R_Foot", "R_Ankle"): (2, 4),  # SMPL: Foot = toe
        ("mixamorig:Hips", "mixamorig:RightFoot", "mixamorig:LeftFoot"): (2, 1),
        ("Bip01", "Bip01 L Foot", "Bip01 R Foot"): (1, 2),
        ("root", "foot_l", "foot_r"): (1, 2),
        ("hip", "lAnkle", "rAnkle"): (1, 2),
    }
    for names, expected in cases.items():
        assert find_ankles(names) == expected, names
    assert find_ankles(("Hips", "LeftToe", "RightToe")) is None


# ---------------------------------------------------------------------------------------------
# malformed input


def _edge_dict(n_frames: int = 60) -> dict[str, np.ndarray]:
    return {"full_pose": np.zeros((n_frames, 24, 3))}


@pytest.mark.parametrize(
    ("name", "content", "problem"),
    [
        ("keys.pkl", {"poses": np.zeros((60, 72))}, "keys found: poses"),
        ("shape.pkl", {"full_pose": np.zeros((60, 23, 3))}, r"shape \(60, 23, 3\)"),
        (
            "aistshape.pkl",
            {
                "smpl_poses": np.zeros((60, 72)),
                "smpl_trans": np.zeros((59, 3)),
                "smpl_scaling": np.ones(1),
            },
            "smpl_trans",
        ),
        ("nan.pkl", {**_edge_dict(), "full_pose": np.full((60, 24, 3), np.nan)}, "NaN"),
        ("short.pkl", _edge_dict(20), "too short"),
        (
            "scale.pkl",
            {
                "smpl_poses": np.zeros((60, 72)),
                "smpl_trans": np.zeros((60, 3)),
                "smpl_scaling": np.zeros(1),
            },
            "'smpl_scaling' is 0, expected",
        ),
        ("list.pkl", [1, 2, 3], "expected a dict"),
    ],
)
def test_malformed_pickles_name_the_file_and_problem(tmp_path, name, content, problem):
    path = _write_pickle(tmp_path / name, content)
    with pytest.raises(InputFileError, match=problem) as err:
        load_motion(path)
    assert name in str(err.value)


def test_unknown_format_garbage_and_truncated_bvh_are_errors(tmp_path):
    cases = {"dance.txt": b"just some text\n", "noise.pkl": os.urandom(64) + b"\x00garbage"}
    full = tmp_path / "full.bvh"
    _leg_lift_bvh(full, 48, 1 / 24, np.zeros(48))
    text = full.read_bytes()
    cases["cut_motion.bvh"] = text[: len(text) - 200]
    cases["cut_hierarchy.bvh"] = text[: len(_BVH_HIERARCHY) // 2]
    for name, content in cases.items():
        path = tmp_path / name
        path.write_bytes(content)
        with pytest.raises(InputFileError) as err:
            load_motion(path)
        assert name in str(err.value)
    with pytest.raises(InputFileError, match="does not exist"):
        load_motion(tmp_path / "missing.bvh")
    # A BVH with an unknown suffix is still recognised from its content.
    renamed = tmp_path / "full.mocap"
    renamed.write_bytes(text)
    assert load_motion(renamed).feet_m.shape == (48, 2)


# ---------------------------------------------------------------------------------------------
# trunk (body) curves


def test_bvh_moving_root_becomes_body_curves_without_drift(tmp_path):
    """The root bobs, rolls, pitches and turns (yaw about up, then pitch, then roll: the
    channel order Y X Z) while walking off and turning round slowly: the body curves are
    the bob and the angles, the slow walk and turn removed."""
    fps, n_frames = 30, 360
    t = np.arange(n_frames) / fps
    bob_cm = 4.0 * np.sin(2 * np.pi * 1.0 * t)
    roll_deg = 10.0 * np.sin(2 * np.pi * 0.5 * t)
    pitch_deg = 6.0 * np.sin(2 * np.pi * 1.0 * t + 1.0)
    yaw_deg = 8.0 * np.sin(2 * np.pi * 0.5 * t) + 30.0 * t / t[-1]  # plus a slow turn
    hierarchy = _BVH_HIERARCHY.replace(
        "CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation",
        "CHANNELS 6 Xposition Yposition Zposition Yrotation Xrotation Zrotation",
    )
    lines = [hierarchy + "MOTION", f"Frames: {n_frames}", f"Frame Time: {1 / fps:.6f}"]
    for k in range(n_frames):
        # Y-up, cm, facing +z (the toes), left hip at +x.
        root = [2.0 * k, 100.0 + bob_cm[k], 1.0 * k, yaw_deg[k], pitch_deg[k], roll_deg[k]]
        lines.append(" ".join(f"{v:.5f}" for v in root + [0.0] * 21))
    path = tmp_path / "dance.bvh"
    path.write_text("\n".join(lines) + "\n")

    motion = load_motion(path)
    assert motion.body.shape == (n_frames, 4)
    inner = slice(2 * fps, n_frames - 2 * fps)  # the drift window's edges aside
    np.testing.assert_allclose(motion.body[inner, 0], bob_cm[inner] / 100, atol=2e-3)
    # roll > 0: left side up; pitch > 0: nose down (a positive x rotation tips +z down);
    # yaw > 0: turned left (a positive y rotation turns +z towards +x, the left).
    np.testing.assert_allclose(np.rad2deg(motion.body[inner, 1]), roll_deg[inner], atol=0.5)
    np.testing.assert_allclose(np.rad2deg(motion.body[inner, 2]), pitch_deg[inner], atol=0.5)
    wiggle = yaw_deg - 30.0 * t / t[-1]
    np.testing.assert_allclose(np.rad2deg(motion.body[inner, 3]), wiggle[inner], atol=0.5)

    # make_dance scales them into the robot's range and keeps its limits.
    from quaddance.pipeline import make_dance
    from quaddance.robots import GO1

    dance, _ = make_dance(None, path)
    body = dance.body_targets
    assert np.all(body >= GO1.body_four_feet.low - 1e-9)
    assert np.all(body <= GO1.body_four_feet.high + 1e-9)
    roll_50 = np.interp(dance.time_s, t, roll_deg)
    assert np.corrcoef(body[100:-100, 1], roll_50[100:-100])[0, 1] > 0.95
    assert np.ptp(body[:, 0]) > 0.04  # an 8 cm bob, scaled into the (paw-up) range


def test_bvh_without_hips_keeps_only_the_height(tmp_path):
    # Ankles hung straight off the root: no knee-hip chain, so no trunk orientation.
    text = (
        "HIERARCHY\nROOT Hips\n{\n OFFSET 0 0 0\n CHANNELS 6 Xposition Yposition Zposition "
        "Zrotation Xrotation Yrotation\n JOINT LeftFoot\n {\n  OFFSET 10 -90 0\n  CHANNELS 0\n"
        "  End Site\n  {\n   OFFSET 0 -5 10\n  }\n }\n JOINT RightFoot\n {\n  OFFSET -10 -90 0\n"
        "  CHANNELS 0\n  End Site\n  {\n   OFFSET 0 -5 10\n  }\n }\n}\nMOTION\n"
    )
    n_frames, fps = 200, 50
    t = np.arange(n_frames) / fps
    rows = [
        f"0 {100 + 3 * np.sin(2 * np.pi * t[k]):.4f} 0 {20 * np.sin(t[k]):.4f} 0 0"
        for k in range(n_frames)
    ]
    path = tmp_path / "nohips.bvh"
    path.write_text(text + f"Frames: {n_frames}\nFrame Time: 0.02\n" + "\n".join(rows) + "\n")
    motion = load_motion(path)
    assert not motion.body[:, 1:].any()
    assert np.ptp(motion.body[:, 0]) > 0.04


def test_aist_global_orientation_becomes_roll(tmp_path):
    fps, n_frames = 60, 480
    t = np.arange(n_frames) / fps
    roll = 0.2 * np.sin(2 * np.pi * t)
    poses = np.zeros((n_frames, 72))
    poses[:, 2] = roll  # about +z, the way the rest body faces: the left side (+x) goes up
    path = _write_pickle(
        tmp_path / "aist.pkl",
        {
            "smpl_poses": poses,
            "smpl_trans": np.tile([0.0, 1.0, 0.0], (n_frames, 1)),
            "smpl_scaling": np.array([1.0]),
        },
    )
    motion = load_motion(path)
    inner = slice(2 * fps, n_frames - 2 * fps)
    np.testing.assert_allclose(motion.body[inner, 1], roll[inner], atol=0.02)
    assert np.abs(motion.body[inner, 3]).max() < 0.02
