"""Trunk poses for whole-body dance: leg inverse kinematics and the body feed-forward.

A body target is (height offset m, roll, pitch, yaw rad) of the trunk relative to the
standing pose, feet staying where they stand (`quaddance.layout.BODY_COLUMNS`). The
feed-forward moves every leg so that its foot stays put in the world while the trunk takes
the pose: the same idea as the front-lift feed-forward (`sim/feedforward.py`), so PPO learns
corrections and balance instead of the whole motion. Batched torch, used by training, playback
and the robot runner alike (through `sim.task.joint_targets`).
"""

from __future__ import annotations

import torch

from quaddance.robots import RobotCfg
from quaddance.sim.kinematics import LegGeometry, foot_pos_b, leg_geometry


def rpy_matrix(rpy: torch.Tensor) -> torch.Tensor:
    """(N, 3) roll, pitch, yaw (rad, extrinsic x-y-z = R_z R_y R_x) -> (N, 3, 3) rotations."""
    r, p, y = rpy.unbind(-1)
    cr, sr, cp, sp, cy, sy = r.cos(), r.sin(), p.cos(), p.sin(), y.cos(), y.sin()
    row0 = torch.stack([cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr], -1)
    row1 = torch.stack([sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr], -1)
    row2 = torch.stack([-sp, cp * sr, cp * cr], -1)
    return torch.stack([row0, row1, row2], -2)


def leg_ik(foot_b: torch.Tensor, geom: LegGeometry) -> torch.Tensor:
    """(N, 4, 3) foot sphere centres in the trunk frame (task foot order FL, FR, RL, RR) ->
    (N, 12) joint angles in model order, the inverse of `kinematics.foot_pos_b`.

    Closed form for a Go1-like chain (hip about x; thigh and calf about y; the thigh offset
    is lateral and both links point straight down at zero angle, as `leg_geometry` checks).
    Out-of-reach points are pulled onto the workspace boundary instead of giving NaN.
    """
    t = lambda name: geom.tensor(name, foot_b)  # noqa: E731
    ty = t("thigh_offset")[:, 1]  # (4,) lateral thigh offset, m: left legs +
    l2 = -t("calf_offset")[:, 2]  # thigh link length
    l3 = -t("foot_offset")[:, 2]  # calf link length
    d = foot_b - t("hip_pos_b")
    dy, dz = d[..., 1], d[..., 2]
    # Hip: the leg plane sits ty to the side; the foot is at depth vz below the hip in it.
    vz = -(dy**2 + dz**2 - ty**2).clamp(min=1e-6).sqrt()
    hip = torch.atan2(dz, dy) - torch.atan2(vz, ty.expand_as(vz))
    vx = d[..., 0]
    r2 = (vx**2 + vz**2).clamp(max=(l2 + l3) ** 2 * 0.9999)
    cos_knee = ((r2 - l2**2 - l3**2) / (2 * l2 * l3)).clamp(-1.0, 1.0)
    calf = -torch.acos(cos_knee)  # knees bend backwards (as the Go1's): calf angles < 0
    phi = torch.atan2(-vx, -vz)  # direction of the foot from straight down
    thigh = phi - torch.atan2(l3 * torch.sin(calf), l2 + l3 * torch.cos(calf))
    q_task = torch.stack([hip, thigh, calf], -1)  # (N, 4 feet, 3)
    n_joints = q_task.shape[1] * q_task.shape[2]
    out = torch.empty(foot_b.shape[0], n_joints, dtype=foot_b.dtype, device=foot_b.device)
    out[:, t("joint_cols").reshape(-1)] = q_task.reshape(-1, n_joints)
    return out


class BodyFeedforward:
    """Batched map (N, 4) body targets -> (N, 12) joint offsets from the nominal pose (rad,
    model order) that hold all four feet where they stand while the trunk takes the pose."""

    def __init__(self, robot: RobotCfg, device: torch.device | str = "cpu") -> None:
        self.geom = leg_geometry(robot)
        nominal = torch.tensor(robot.nominal_joint_pos_rad, dtype=torch.float32)[None]
        self.nominal = nominal.to(device)
        self.feet0_b = foot_pos_b(nominal, self.geom).to(device)  # (1, 4, 3)
        self.q0 = leg_ik(self.feet0_b, self.geom)  # the nominal pose through the same IK

    def feet_b(self, body: torch.Tensor) -> torch.Tensor:
        """(N, 4, 3) where the standing feet are in the trunk frame for trunk pose ``body``."""
        rot = rpy_matrix(body[:, 1:4])  # trunk orientation relative to the standing pose
        lift = torch.zeros_like(body[:, :3])
        lift[:, 2] = body[:, 0]
        rel = self.feet0_b - lift[:, None, :]  # feet relative to the moved trunk, old axes
        return torch.einsum("nji,nkj->nki", rot, rel)  # R^T (p - dz e_z)

    def __call__(self, body: torch.Tensor) -> torch.Tensor:
        # Offsets from the IK's own nominal solution, so zero targets give exactly zero.
        return leg_ik(self.feet_b(body), self.geom) - self.q0
