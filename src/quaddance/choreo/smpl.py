"""SMPL joint positions from pose parameters, without the SMPL body model.

Only the 24 joints are needed (for the ankles), and those follow from the kinematic tree and
the rest offsets of the standard neutral body (FACTS.md section 3): the world rotation of a
joint is its parent's world rotation times its own axis-angle rotation, and its position is
the parent's position plus the parent's world rotation applied to the rest offset. The rest
skeleton is y-up, in metres, facing +z.
"""

from __future__ import annotations

import numpy as np

N_JOINTS = 24
LEFT_ANKLE, RIGHT_ANKLE = 7, 8
LEFT_TOE, RIGHT_TOE = 10, 11
PELVIS = 0
_CHUNK_FRAMES = 4096  # frames per forward-kinematics step, bounds its temporary memory

# Parent of each joint (-1 for the pelvis); every parent comes before its children.
PARENTS = (-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 20, 21)

# Offset of each joint from its parent in the rest pose, metres, y-up (FACTS.md section 3).
REST_OFFSETS_M = np.array(
    [
        [0.0, 0.0, 0.0],
        [0.05858135, -0.08228004, -0.01766408],
        [-0.06030973, -0.09051332, -0.01354254],
        [0.00443945, 0.12440352, -0.03838522],
        [0.04345142, -0.38646945, 0.008037],
        [-0.04325663, -0.38368791, -0.00484304],
        [0.00448844, 0.1379564, 0.02682033],
        [-0.01479032, -0.42687458, -0.037428],
        [0.01905555, -0.4200455, -0.03456167],
        [-0.00226458, 0.05603239, 0.00285505],
        [0.04105436, -0.06028581, 0.12204243],
        [-0.03483987, -0.06210566, 0.13032329],
        [-0.0133902, 0.21163553, -0.03346758],
        [0.07170245, 0.11399969, -0.01889817],
        [-0.08295366, 0.11247234, -0.02370739],
        [0.01011321, 0.08893734, 0.05040987],
        [0.12292141, 0.04520509, -0.019046],
        [-0.11322832, 0.04685326, -0.00847207],
        [0.2553319, -0.01564902, -0.02294649],
        [-0.26012748, -0.01436928, -0.03126873],
        [0.26570925, 0.01269811, -0.00737473],
        [-0.26910836, 0.00679372, -0.00602676],
        [0.08669055, -0.01063603, -0.01559429],
        [-0.0887537, -0.00865157, -0.01010708],
    ]
)


def axis_angle_to_matrix(axis_angle: np.ndarray) -> np.ndarray:
    """Rotation matrices from axis-angle vectors (Rodrigues' formula), vectorised.

    Parameters
    ----------
    axis_angle : np.ndarray, shape (..., 3)
        Rotation axis times angle, radians.

    Returns
    -------
    np.ndarray, shape (..., 3, 3)
        ``R`` with ``R @ v`` rotating column vector ``v``.
    """
    v = np.asarray(axis_angle, dtype=np.float64)
    angle = np.linalg.norm(v, axis=-1)[..., None, None]
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    zero = np.zeros_like(x)
    # Cross-product matrix of the unnormalised vector, so the small-angle limit needs no axis.
    skew = np.stack([zero, -z, y, z, zero, -x, -y, x, zero], axis=-1).reshape(*v.shape[:-1], 3, 3)
    small = angle < 1e-6
    safe = np.where(small, 1.0, angle)
    # sin(a)/a and (1 - cos(a))/a^2, with their Taylor limits 1 and 1/2 near a = 0.
    a = np.where(small, 1.0 - angle**2 / 6.0, np.sin(safe) / safe)
    b = np.where(small, 0.5 - angle**2 / 24.0, (1.0 - np.cos(safe)) / safe**2)
    return np.eye(3) + a * skew + b * (skew @ skew)


def smpl_joints(poses_aa: np.ndarray, trans: np.ndarray) -> np.ndarray:
    """World positions of the 24 SMPL joints by forward kinematics.

    Parameters
    ----------
    poses_aa : np.ndarray, shape (T, 72)
        Axis-angle rotation of each joint relative to its parent (joint 0: the global
        orientation), radians, joints in SMPL order.
    trans : np.ndarray, shape (T, 3)
        Pelvis position, metres, in the frame the global orientation maps into.

    Returns
    -------
    np.ndarray, shape (T, 24, 3)
        Joint positions, metres. Joints 7/8 are the left/right ankles, 10/11 the toes. With
        a zero global orientation the result is y-up like the rest skeleton.
    """
    poses_aa = np.asarray(poses_aa, dtype=np.float64)
    trans = np.asarray(trans, dtype=np.float64)
    if poses_aa.ndim != 2 or poses_aa.shape[1] != 3 * N_JOINTS:
        raise ValueError(f"poses_aa must have shape (T, 72), got {poses_aa.shape}")
    if trans.shape != (poses_aa.shape[0], 3):
        raise ValueError(f"trans must have shape ({poses_aa.shape[0]}, 3), got {trans.shape}")
    joints = np.empty((poses_aa.shape[0], N_JOINTS, 3))
    # In chunks of frames: the rotations take 1.7 kB per frame, several copies of them at once.
    for start in range(0, poses_aa.shape[0], _CHUNK_FRAMES):
        chunk = slice(start, start + _CHUNK_FRAMES)
        joints[chunk] = _joints_chunk(poses_aa[chunk], trans[chunk])
    return joints


def _joints_chunk(poses_aa: np.ndarray, trans: np.ndarray) -> np.ndarray:
    """`smpl_joints` for frames that fit in memory at once."""
    local = axis_angle_to_matrix(poses_aa.reshape(-1, N_JOINTS, 3))  # (T, 24, 3, 3)
    world_rot = np.empty_like(local)
    joints = np.empty((poses_aa.shape[0], N_JOINTS, 3))
    world_rot[:, PELVIS] = local[:, PELVIS]
    joints[:, PELVIS] = trans + REST_OFFSETS_M[PELVIS]
    for j in range(1, N_JOINTS):
        parent = PARENTS[j]
        world_rot[:, j] = world_rot[:, parent] @ local[:, j]
        joints[:, j] = joints[:, parent] + world_rot[:, parent] @ REST_OFFSETS_M[j]
    return joints
