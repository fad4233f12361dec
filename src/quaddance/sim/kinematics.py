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
from typing import NamedTuple

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

    def tensors(self, like: torch.Tensor) -> LegTensors:
        """The geometry as tensors of ``like``'s dtype and device, made once per dtype and
        device instead of at every call (the kinematics run every policy step)."""
        key = (like.dtype, like.device)
        out = self._tensors.get(key)
        if out is None:
            with torch.inference_mode(False):  # usable in and out of inference mode
                out = LegTensors.of(self, like.dtype, like.device)
            self._tensors[key] = out
        return out


class _Axis(NamedTuple):
    """A rotation about one axis written as ``R v = v * C + v[swap] * S``: ``C`` holds the
    cosine or 1 and ``S`` the signed sine or 0, per component. The 1s and 0s are the cosine
    and sine of the angle 0, so one cos and one sin give the factors of every rotation."""

    uses_angle: tuple[int, int, int]  # 1: the joint angle, 0: the angle 0
    sin_sign: tuple[float, float, float]
    swap: tuple[int, int, int]


# R_y(a) v = (c v0 + s v2, v1, c v2 - s v0); R_x(a) v = (v0, c v1 - s v2, c v2 + s v1).
_ABOUT_Y = _Axis((1, 0, 1), (1.0, 1.0, -1.0), (2, 1, 0))
_ABOUT_X = _Axis((0, 1, 1), (1.0, -1.0, 1.0), (0, 2, 1))


@dataclass(frozen=True)
class LegTensors:
    """`LegGeometry` as tensors, with the constants the batched kinematics derive from it:
    the factors of the chain's three rotations (calf and thigh about y, hip about x, each an
    `_Axis`) and the leg IK's lengths."""

    hip_pos_b: torch.Tensor  # (4, 3)
    thigh_offset: torch.Tensor  # (4, 3)
    calf_offset: torch.Tensor  # (4, 3)
    foot_offset: torch.Tensor  # (4, 3)
    #: (4 * 3 * 3,) per foot, per rotation (calf, thigh, hip), per component: the column of
    #: the joint angle there, and 1, or 0 where the rotation needs the angle 0.
    angle_index: torch.Tensor
    angle_mask: torch.Tensor
    sin_sign: torch.Tensor  # (3, 3) per rotation, per component
    swap: tuple[torch.Tensor, torch.Tensor, torch.Tensor]  # per rotation: (3,) components
    to_model: torch.Tensor  # (12,) task-order (foot, joint) column of each model joint
    # Leg IK (`quaddance.sim.body.leg_ik`): squared lateral thigh offset, link lengths.
    thigh_y: torch.Tensor  # (4,)
    thigh_y_sq: torch.Tensor  # (4,)
    thigh_len: torch.Tensor  # (4,)
    calf_len: torch.Tensor  # (4,)
    thigh_len_sq: torch.Tensor  # (4,)
    calf_len_sq: torch.Tensor  # (4,)
    two_thigh_calf: torch.Tensor  # (4,) 2 l2 l3
    max_reach_sq: torch.Tensor  # (4,) (l2 + l3)^2, a hair inside

    @classmethod
    def of(cls, geom: LegGeometry, dtype: torch.dtype, device: torch.device) -> LegTensors:
        t = lambda a: torch.as_tensor(np.asarray(a), dtype=dtype, device=device)  # noqa: E731
        long = lambda a: torch.as_tensor(np.asarray(a), dtype=torch.long, device=device)  # noqa: E731
        rotations = (_ABOUT_Y, _ABOUT_Y, _ABOUT_X)  # calf, thigh, hip
        index = [
            [[geom.joint_cols[f, joint]] * 3 for joint in (2, 1, 0)]
            for f in range(geom.joint_cols.shape[0])
        ]
        mask = [[rot.uses_angle for rot in rotations]] * geom.joint_cols.shape[0]
        ty = t(geom.thigh_offset[:, 1])  # lateral thigh offset, m: left legs +
        l2, l3 = -t(geom.calf_offset[:, 2]), -t(geom.foot_offset[:, 2])
        return cls(
            hip_pos_b=t(geom.hip_pos_b),
            thigh_offset=t(geom.thigh_offset),
            calf_offset=t(geom.calf_offset),
            foot_offset=t(geom.foot_offset),
            angle_index=long(index).reshape(-1),
            angle_mask=t(mask).reshape(-1),
            sin_sign=t([rot.sin_sign for rot in rotations]),
            swap=tuple(long(rot.swap) for rot in rotations),
            to_model=long(np.argsort(geom.joint_cols.reshape(-1))),
            thigh_y=ty,
            thigh_y_sq=ty**2,
            thigh_len=l2,
            calf_len=l3,
            thigh_len_sq=l2**2,
            calf_len_sq=l3**2,
            two_thigh_calf=2 * l2 * l3,
            max_reach_sq=(l2 + l3) ** 2 * 0.9999,
        )


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


def _rotate(v: torch.Tensor, cos: torch.Tensor, sin: torch.Tensor, swap: torch.Tensor):
    """``R v`` (..., 3) for rotations about one axis, factors as `_Axis` describes them."""
    return v * cos + v.index_select(-1, swap) * sin


def foot_pos_b(joint_pos: torch.Tensor, geom: LegGeometry) -> torch.Tensor:
    """(N, 12) joint angles, model order, rad -> (N, 4, 3) foot sphere centres in the trunk
    frame, m, task foot order."""
    t = geom.tensors(joint_pos)
    angles = joint_pos.index_select(1, t.angle_index) * t.angle_mask
    angles = angles.view(-1, 4, 3, 3)  # (N, foot, rotation: calf thigh hip, component)
    cos, sin = angles.cos().unbind(2), (angles.sin() * t.sin_sign).unbind(2)
    p = t.calf_offset + _rotate(t.foot_offset, cos[0], sin[0], t.swap[0])
    p = t.thigh_offset + _rotate(p, cos[1], sin[1], t.swap[1])
    return t.hip_pos_b + _rotate(p, cos[2], sin[2], t.swap[2])


def foot_up_m(
    joint_pos: torch.Tensor, projected_gravity_b: torch.Tensor, geom: LegGeometry
) -> torch.Tensor:
    """(N, 4) the foot sphere centres' heights along world up relative to the trunk's origin,
    m, from the encoders (N, 12; model order, rad) and the IMU's unit gravity direction in
    the trunk frame (N, 3). Minus the lowest is the trunk's height above that foot's centre."""
    norm = torch.linalg.vector_norm(projected_gravity_b, dim=1, keepdim=True).clamp(min=1e-6)
    up_b = -projected_gravity_b / norm
    return (foot_pos_b(joint_pos, geom) * up_b[:, None, :]).sum(dim=2)


def foot_height_from_up(up_m: torch.Tensor) -> torch.Tensor:
    """(N, 4) foot-bottom heights above a floor through the lowest foot, m, of `foot_up_m`.

    The lowest foot reads 0; on flat ground with three feet down this equals the true height
    of each foot's bottom above the floor up to contact penetration (a few mm)."""
    return up_m - up_m.amin(dim=1, keepdim=True)


def estimate_foot_height_m(
    joint_pos: torch.Tensor, projected_gravity_b: torch.Tensor, geom: LegGeometry
) -> torch.Tensor:
    """(N, 4) foot-bottom heights above a floor through the lowest foot, m (`foot_up_m`, then
    `foot_height_from_up`)."""
    return foot_height_from_up(foot_up_m(joint_pos, projected_gravity_b, geom))
