"""Trunk poses for whole-body dance: leg inverse kinematics and the body feed-forward.

A body target is (height offset m, roll, pitch, yaw rad) of the trunk relative to the
standing pose, feet staying where they stand (`quaddance.layout.BODY_COLUMNS`). The
feed-forward moves every leg so that its foot stays put in the world while the trunk takes
the pose: the same idea as the front-lift feed-forward (`sim/feedforward.py`), so PPO learns
corrections and balance instead of the whole motion. Batched torch, used by training, playback
and the robot runner alike (through `sim.task.joint_targets`).
"""

from __future__ import annotations

import functools

import torch

from quaddance.robots import RobotCfg
from quaddance.sim.kinematics import LegGeometry, foot_pos_b, leg_geometry

#: `rpy_matrix`'s nine entries, each ``a * b * c + sign * (d * e)`` over the table
#: [cos r, cos p, cos y, 1, sin r, sin p, sin y, 0] (indices below): R = R_z R_y R_x.
_CR, _CP, _CY, _ONE, _SR, _SP, _SY, _ZERO = range(8)
_RPY_FACTORS = (
    # r00 = cy cp, r01 = cy sp sr - sy cr, r02 = cy sp cr + sy sr
    (_CY, _CP, _ONE, _ZERO, _ZERO, 0.0),
    (_CY, _SP, _SR, _SY, _CR, -1.0),
    (_CY, _SP, _CR, _SY, _SR, 1.0),
    # r10 = sy cp, r11 = sy sp sr + cy cr, r12 = sy sp cr - cy sr
    (_SY, _CP, _ONE, _ZERO, _ZERO, 0.0),
    (_SY, _SP, _SR, _CY, _CR, 1.0),
    (_SY, _SP, _CR, _CY, _SR, -1.0),
    # r20 = -sp, r21 = cp sr, r22 = cp cr
    (_ZERO, _ONE, _ONE, _SP, _ONE, -1.0),
    (_CP, _SR, _ONE, _ZERO, _ZERO, 0.0),
    (_CP, _CR, _ONE, _ZERO, _ZERO, 0.0),
)


@functools.lru_cache(maxsize=8)
def _rpy_factors(device: torch.device, dtype: torch.dtype) -> tuple[torch.Tensor, ...]:
    """(45,) `_RPY_FACTORS`' table indices, factor by factor, (9,) their signs, and the
    index and mask that make (r, p, y, 0) of (r, p, y)."""
    with torch.inference_mode(False):  # usable in and out of inference mode
        index = torch.tensor([row[:5] for row in _RPY_FACTORS], device=device).T.reshape(-1)
        sign = torch.tensor([row[5] for row in _RPY_FACTORS], device=device, dtype=dtype)
        angle_index = torch.tensor([0, 1, 2, 0], device=device)
        angle_mask = torch.tensor([1.0, 1.0, 1.0, 0.0], device=device, dtype=dtype)
        return index, sign, angle_index, angle_mask


def rpy_matrix(rpy: torch.Tensor) -> torch.Tensor:
    """(N, 3) roll, pitch, yaw (rad, extrinsic x-y-z = R_z R_y R_x) -> (N, 3, 3) rotations."""
    index, sign, angle_index, angle_mask = _rpy_factors(rpy.device, rpy.dtype)
    angles = rpy.index_select(1, angle_index) * angle_mask  # r, p, y, 0: the 1 and the 0
    table = torch.cat([angles.cos(), angles.sin()], dim=1)
    a, b, c, d, e = table.index_select(1, index).view(-1, 5, 9).unbind(1)
    return (a * b * c + sign * (d * e)).view(-1, 3, 3)


def leg_ik(foot_b: torch.Tensor, geom: LegGeometry) -> torch.Tensor:
    """(N, 4, 3) foot sphere centres in the trunk frame (task foot order FL, FR, RL, RR) ->
    (N, 12) joint angles in model order, the inverse of `kinematics.foot_pos_b`.

    Closed form for a Go1-like chain (hip about x; thigh and calf about y; the thigh offset
    is lateral and both links point straight down at zero angle, as `leg_geometry` checks).
    Out-of-reach points are pulled onto the workspace boundary instead of giving NaN.
    """
    t = geom.tensors(foot_b)
    d = foot_b - t.hip_pos_b
    vx, dy, dz = d.unbind(-1)
    # Hip: the leg plane sits ty to the side; the foot is at depth vz below the hip in it.
    vz = -(dy * dy + dz * dz - t.thigh_y_sq).clamp(min=1e-6).sqrt()
    hip = torch.atan2(dz, dy) - torch.atan2(vz, t.thigh_y)
    r2 = (vx * vx + vz * vz).clamp(max=t.max_reach_sq)
    cos_knee = ((r2 - t.thigh_len_sq - t.calf_len_sq) / t.two_thigh_calf).clamp(-1.0, 1.0)
    calf = -torch.acos(cos_knee)  # knees bend backwards (as the Go1's): calf angles < 0
    phi = torch.atan2(-vx, -vz)  # direction of the foot from straight down
    thigh = phi - torch.atan2(t.calf_len * calf.sin(), t.thigh_len + t.calf_len * calf.cos())
    q_task = torch.stack([hip, thigh, calf], -1)  # (N, 4 feet, 3)
    return q_task.view(q_task.shape[0], -1).index_select(1, t.to_model)


class BodyFeedforward:
    """Batched map (N, 4) body targets -> (N, 12) joint offsets from the nominal pose (rad,
    model order) that hold all four feet where they stand while the trunk takes the pose."""

    def __init__(self, robot: RobotCfg, device: torch.device | str = "cpu") -> None:
        self.geom = leg_geometry(robot)
        nominal = torch.tensor(robot.nominal_joint_pos_rad, dtype=torch.float32)[None]
        self.nominal = nominal.to(device)
        self.feet0_b = foot_pos_b(nominal, self.geom).to(device)  # (1, 4, 3)
        self.q0 = leg_ik(self.feet0_b, self.geom)  # the nominal pose through the same IK
        self.up = torch.tensor([0.0, 0.0, 1.0], device=device)

    def feet_b(self, body: torch.Tensor) -> torch.Tensor:
        """(N, 4, 3) where the standing feet are in the trunk frame for trunk pose ``body``."""
        rot = rpy_matrix(body[:, 1:4])  # trunk orientation relative to the standing pose
        rel = self.feet0_b - body[:, :1, None] * self.up  # feet relative to the moved trunk
        return torch.bmm(rel, rot)  # R^T (p - dz e_z), row by row

    def __call__(self, body: torch.Tensor) -> torch.Tensor:
        # Offsets from the IK's own nominal solution, so zero targets give exactly zero.
        return leg_ik(self.feet_b(body), self.geom) - self.q0
