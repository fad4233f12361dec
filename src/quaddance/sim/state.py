"""The robot's state as batched torch tensors: the only thing the task code sees.

Both engines produce a `RobotState` from the same three arrays (qpos, qvel, sensordata), by
the same function, so the task cannot tell which engine ran the physics.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import mujoco
import torch

from quaddance.robots import RobotCfg


@dataclass(frozen=True)
class SensorLayout:
    """Where each quantity lies in MuJoCo's sensordata vector (addresses by sensor name)."""

    foot_pos: tuple[int, ...]  # 4 x 3, task foot order
    foot_vel: tuple[int, ...]  # 4 x 3
    joint_torque: tuple[int, ...]  # 12, model joint order
    base_contact: int  # trunk touching the floor (number of contacts)
    leg_contact: tuple[int, ...]  # thighs and calves touching the floor (8)
    foot_radius_m: float  # the foot sensors read the sphere's centre; its bottom is this lower

    @classmethod
    def from_model(cls, model: mujoco.MjModel, robot: RobotCfg) -> SensorLayout:
        """The layout of a scene built for ``robot`` (`quaddance.sim.scene.build_spec`)."""

        def adr(name: str, dim: int) -> list[int]:
            start = int(model.sensor(name).adr[0])
            return list(range(start, start + dim))

        legs = [f"{leg}_{p}" for leg in robot.legs for p in ("thigh", "knee")]
        return cls(
            foot_pos=tuple(i for f in robot.feet for i in adr(f"{f}_pos", 3)),
            foot_vel=tuple(i for f in robot.feet for i in adr(f"{f}_vel", 3)),
            joint_torque=tuple(i for j in robot.joint_names for i in adr(f"{j}_torque", 1)),
            base_contact=adr("trunk_contact", 1)[0],
            leg_contact=tuple(adr(f"{b}_contact", 1)[0] for b in legs),
            foot_radius_m=robot.foot_radius_m,
        )


@dataclass
class RobotState:
    """Batched robot state; N environments, world frame `_w`, body frame `_b`."""

    base_pos_w: torch.Tensor  # (N, 3) m
    base_quat_w: torch.Tensor  # (N, 4) w, x, y, z
    base_lin_vel_w: torch.Tensor  # (N, 3) m/s
    base_ang_vel_b: torch.Tensor  # (N, 3) rad/s
    joint_pos: torch.Tensor  # (N, 12) rad, model joint order
    joint_vel: torch.Tensor  # (N, 12) rad/s
    joint_torque: torch.Tensor  # (N, 12) N m
    foot_pos_w: torch.Tensor  # (N, 4, 3) m, foot sphere centres, FL FR RL RR
    foot_vel_w: torch.Tensor  # (N, 4, 3) m/s
    base_contact: torch.Tensor  # (N,) bool
    leg_contacts: torch.Tensor  # (N,) number of thighs/calves touching the floor
    foot_radius_m: float

    @functools.cached_property
    def foot_height_m(self) -> torch.Tensor:
        """(N, 4) height of each foot's bottom above the floor: THE foot height of quaddance."""
        return self.foot_pos_w[..., 2] - self.foot_radius_m

    @functools.cached_property
    def projected_gravity_b(self) -> torch.Tensor:
        """(N, 3) unit gravity direction in the body frame."""
        gravity_w = torch.zeros_like(self.base_lin_vel_w)
        gravity_w[:, 2] = -1.0
        return quat_rotate_inverse(self.base_quat_w, gravity_w)

    @functools.cached_property
    def base_rpy_rad(self) -> torch.Tensor:
        """(N, 3) roll, pitch, yaw of the trunk (extrinsic x-y-z, as `sim.body.rpy_matrix`)."""
        w, x, y, z = self.base_quat_w.unbind(1)
        roll = torch.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
        pitch = torch.asin((2 * (w * y - z * x)).clamp(-1.0, 1.0))
        return torch.stack([roll, pitch, yaw_from_quat(self.base_quat_w)], dim=1)

    @property
    def base_yaw_rad(self) -> torch.Tensor:
        """(N,) heading of the trunk about the world vertical, rad."""
        return self.base_rpy_rad[:, 2]

    @functools.cached_property
    def base_lin_vel_b(self) -> torch.Tensor:
        return quat_rotate_inverse(self.base_quat_w, self.base_lin_vel_w)


def yaw_from_quat(quat_wxyz: torch.Tensor) -> torch.Tensor:
    """(N,) yaw (heading about the world vertical, rad) of (N, 4) w x y z quaternions."""
    w, x, y, z = quat_wxyz.unbind(-1)
    return torch.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


def wrap_angle_rad(angle: torch.Tensor) -> torch.Tensor:
    """Angles wrapped to [-pi, pi)."""
    return torch.remainder(angle + torch.pi, 2 * torch.pi) - torch.pi


def quat_rotate_inverse(quat_wxyz: torch.Tensor, vec: torch.Tensor) -> torch.Tensor:
    """Rotate world vectors (N, 3) into the frame of unit quaternions (N, 4)."""
    w = quat_wxyz[:, :1]
    xyz = quat_wxyz[:, 1:]
    t = 2.0 * torch.cross(xyz, vec, dim=1)
    return vec - w * t + torch.cross(xyz, t, dim=1)


def state_from_arrays(
    qpos: torch.Tensor, qvel: torch.Tensor, sensordata: torch.Tensor, layout: SensorLayout
) -> RobotState:
    """Build the state from MuJoCo's arrays (N, nq), (N, nv), (N, nsensordata).

    The free joint's qvel holds the linear velocity in the world frame and the angular
    velocity in the body frame (MuJoCo convention).
    """

    def cols(idx: tuple[int, ...]) -> torch.Tensor:
        return sensordata[:, _index(idx, sensordata.device)]

    n = qpos.shape[0]
    return RobotState(
        base_pos_w=qpos[:, 0:3],
        base_quat_w=qpos[:, 3:7],
        base_lin_vel_w=qvel[:, 0:3],
        base_ang_vel_b=qvel[:, 3:6],
        joint_pos=qpos[:, 7:],
        joint_vel=qvel[:, 6:],
        joint_torque=cols(layout.joint_torque),
        foot_pos_w=cols(layout.foot_pos).reshape(n, 4, 3),
        foot_vel_w=cols(layout.foot_vel).reshape(n, 4, 3),
        base_contact=sensordata[:, layout.base_contact] > 0.5,
        leg_contacts=(cols(layout.leg_contact) > 0.5).sum(dim=1),
        foot_radius_m=layout.foot_radius_m,
    )


@functools.lru_cache(maxsize=64)
def _index(idx: tuple[int, ...], device: torch.device) -> torch.Tensor:
    # Index tensors are built once, not on every step.
    return torch.as_tensor(idx, device=device)
