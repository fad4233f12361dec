"""Leg kinematics from what the robot itself measures: joint encoders and the IMU.

A real Go1 has no sensor for "foot height above the floor". It can compute the feet's
positions in the trunk frame from its joint encoders (forward kinematics), turn them
upright with the IMU's gravity direction, and take the floor to pass through the lowest
foot (a dancing Go1 always has at least three feet down). The same function runs in
training (batched over envs) and on the robot (one row), so the actor's foot heights are
the robot's own estimate, never the simulator's truth.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import torch

from quaddance.robots import RobotCfg
from quaddance.sim.scene import SceneCfg, build_model


@dataclass(frozen=True)
class LegGeometry:
    """Fixed offsets along each leg's chain, trunk frame, m; rows in task foot order
    (`RobotCfg.feet`). Joints: hip about x, thigh and calf about y (as in go1.xml)."""

    hip_pos_b: np.ndarray  # (4, 3) hip joint in the trunk frame
    thigh_offset: np.ndarray  # (4, 3) thigh joint relative to the hip body
    calf_offset: np.ndarray  # (4, 3) calf joint relative to the thigh body
    foot_offset: np.ndarray  # (4, 3) foot sphere centre relative to the calf body
    joint_cols: np.ndarray  # (4, 3) hip, thigh, calf columns in model joint order

    @functools.cached_property
    def _tensors(self) -> dict:
        return {}

    def tensor(self, name: str, like: torch.Tensor) -> torch.Tensor:
        """Field ``name`` as a tensor of ``like``'s dtype and device, made once per dtype and
        device instead of at every call (the kinematics run every policy step)."""
        key = (name, like.dtype, like.device)
        out = self._tensors.get(key)
        if out is None:
            dtype = torch.long if name == "joint_cols" else like.dtype
            with torch.inference_mode(False):  # usable in and out of inference mode
                out = torch.as_tensor(getattr(self, name), dtype=dtype, device=like.device)
            self._tensors[key] = out
        return out


@functools.lru_cache(maxsize=4)
def leg_geometry(robot: RobotCfg) -> LegGeometry:
    """Read the leg offsets from the robot's MJCF, so there is one source."""
    model = build_model(SceneCfg(robot=robot))
    rows: dict[str, list[np.ndarray]] = {k: [] for k in ("hip", "thigh", "calf", "foot")}
    cols = []
    for foot, site in zip(robot.feet, robot.foot_sites, strict=True):
        joint_cols = robot.leg_joint_cols(foot)
        for part, col in zip(("hip", "thigh", "calf"), joint_cols, strict=True):
            # The body each joint moves: the leg's hip, thigh and calf links.
            body = model.body(model.jnt_bodyid[model.joint(robot.joint_names[col]).id])
            # The chain is plain translations + single-axis joints; a rotated body frame
            # would need its quaternion in the chain, which this model does not use.
            if not np.allclose(body.quat, [1.0, 0.0, 0.0, 0.0]):
                raise ValueError(f"{body.name}: rotated body frames are not supported")
            rows[part].append(np.array(body.pos, dtype=np.float64))
        rows["foot"].append(np.array(model.site(site).pos, dtype=np.float64))
        cols.append(list(joint_cols))
    return LegGeometry(
        hip_pos_b=np.stack(rows["hip"]),
        thigh_offset=np.stack(rows["thigh"]),
        calf_offset=np.stack(rows["calf"]),
        foot_offset=np.stack(rows["foot"]),
        joint_cols=np.asarray(cols),
    )


def _rot_x(angle: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    c, s = torch.cos(angle), torch.sin(angle)
    return torch.stack(
        [v[..., 0], c * v[..., 1] - s * v[..., 2], s * v[..., 1] + c * v[..., 2]], -1
    )


def _rot_y(angle: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    c, s = torch.cos(angle), torch.sin(angle)
    return torch.stack(
        [c * v[..., 0] + s * v[..., 2], v[..., 1], -s * v[..., 0] + c * v[..., 2]], -1
    )


def foot_pos_b(joint_pos: torch.Tensor, geom: LegGeometry) -> torch.Tensor:
    """(N, 12) joint angles, model order, rad -> (N, 4, 3) foot sphere centres in the trunk
    frame, m, task foot order."""
    t = lambda name: geom.tensor(name, joint_pos)  # noqa: E731
    q = joint_pos[:, t("joint_cols").reshape(-1)].reshape(-1, 4, 3)
    p = t("calf_offset") + _rot_y(q[..., 2], t("foot_offset").expand(q.shape[0], 4, 3))
    p = t("thigh_offset") + _rot_y(q[..., 1], p)
    return t("hip_pos_b") + _rot_x(q[..., 0], p)


def estimate_foot_height_m(
    joint_pos: torch.Tensor, projected_gravity_b: torch.Tensor, geom: LegGeometry
) -> torch.Tensor:
    """(N, 4) foot-bottom heights above a floor through the lowest foot, m.

    ``joint_pos`` (N, 12) as the encoders read them (model order, rad);
    ``projected_gravity_b`` (N, 3) the IMU's unit gravity direction in the trunk frame. The
    lowest foot reads 0; on flat ground with three feet down this equals the true height of
    each foot's bottom above the floor up to contact penetration (a few mm).
    """
    up_b = -projected_gravity_b / projected_gravity_b.norm(dim=1, keepdim=True).clamp(min=1e-6)
    z = (foot_pos_b(joint_pos, geom) * up_b[:, None, :]).sum(dim=2)  # height along world up
    return z - z.min(dim=1, keepdim=True).values
