"""Reference feed-forward for the front legs: the joint offsets that lift a foot by h.

Our addition to the paper's method. With kp 20 and an action scale of 0.25, a 15 cm lift
needs actions of 2-4 standard deviations; PPO then settles on standing still (the reward
hacking the paper reports in 4.3.3). Adding, for each front leg, the thigh and calf offsets
that raise its foot by the current target (by kinematics, trunk held level) turns the
policy's job into balancing and correcting: it still outputs all 12 joint offsets.
"""

from __future__ import annotations

import functools

import mujoco
import numpy as np
import torch

from quaddance.robots import RobotCfg
from quaddance.sim.scene import SceneCfg, build_model


@functools.lru_cache(maxsize=2)
def lift_table(robot: RobotCfg) -> np.ndarray:
    """(H, 2) thigh and calf offsets (rad) from the nominal pose that raise a front foot by
    each of `FrontLiftCfg.heights_m` relative to the trunk (the front-left foot, the first of
    `RobotCfg.feet`; the front-right one is its mirror image in the sagittal plane, so the
    same offsets apply)."""
    cfg = robot.front_lift
    model = build_model(SceneCfg(robot=robot))
    data = mujoco.MjData(model)
    data.qpos[:] = model.key("home").qpos
    site = model.site(robot.foot_sites[0]).id
    _, thigh_col, calf_col = robot.leg_joint_cols(robot.feet[0])
    thigh_joint = model.joint(robot.joint_names[thigh_col])
    calf_joint = model.joint(robot.joint_names[calf_col])
    ti, ci = thigh_joint.qposadr[0], calf_joint.qposadr[0]
    mujoco.mj_kinematics(model, data)
    x0, z0 = data.site_xpos[site][0], data.site_xpos[site][2]
    thigh0, calf0 = data.qpos[ti], data.qpos[ci]
    lo_t, hi_t = model.jnt_range[thigh_joint.id]
    lo_c, hi_c = model.jnt_range[calf_joint.id]
    # Forward kinematics over a grid of the two joints (about 1 s, once per process).
    (dt_lo, dt_hi), (dc_lo, dc_hi) = cfg.thigh_window_rad, cfg.calf_window_rad
    thighs = np.linspace(max(lo_t, thigh0 + dt_lo), min(hi_t, thigh0 + dt_hi), cfg.thigh_points)
    calves = np.linspace(max(lo_c, calf0 + dc_lo), min(hi_c, calf0 + dc_hi), cfg.calf_points)
    pos = np.zeros((thighs.size, calves.size, 2))
    for i, a in enumerate(thighs):
        for j, b in enumerate(calves):
            data.qpos[ti], data.qpos[ci] = a, b
            mujoco.mj_kinematics(model, data)
            pos[i, j] = data.site_xpos[site][[0, 2]]
    heights_m = cfg.heights_m
    out = np.zeros((heights_m.size, 2))
    prev = np.array([thigh0, calf0])
    for k, h in enumerate(heights_m):
        want = np.array([x0 + cfg.forward_per_up * h, z0 + h])
        err = ((pos - want) ** 2).sum(-1)
        # Among near-exact solutions, the one closest to the previous height's: continuity.
        tg, cg = np.meshgrid(thighs, calves, indexing="ij")
        cost = err + 1e-4 * ((tg - prev[0]) ** 2 + (cg - prev[1]) ** 2)
        i, j = np.unravel_index(np.argmin(cost), cost.shape)
        prev = np.array([thighs[i], calves[j]])
        out[k] = prev - [thigh0, calf0]
    return out


class FrontLiftFeedforward:
    """Batched map (N, 2) front targets (m) -> (N, 12) joint offsets (rad), model order."""

    def __init__(
        self, robot: RobotCfg, device: torch.device, table: np.ndarray | None = None
    ) -> None:
        heights_m = robot.front_lift.heights_m
        table = lift_table(robot) if table is None else np.asarray(table, dtype=np.float64)
        if table.shape != (heights_m.size, 2):
            raise ValueError(f"feed-forward table must be {(heights_m.size, 2)}, got {table.shape}")
        self.table = torch.as_tensor(table, dtype=torch.float32, device=device)
        # Row k: the offsets at heights k and k + 1 side by side, read with one index.
        self._pairs = torch.cat([self.table[:-1], self.table[1:]], dim=1).view(-1, 2, 2)
        self.h_max = float(heights_m[-1])
        self.dh = torch.tensor(float(heights_m[1] - heights_m[0]), device=device)
        self._one = torch.ones((), device=device)
        self.num_joints = robot.num_joints
        # Each model joint's column in the offsets [FL thigh, FL calf, FR thigh, FR calf]; the
        # other joints read column 0, zeroed by the mask.
        cols = [c for foot in robot.feet[:2] for c in robot.leg_joint_cols(foot)[1:]]
        to_model = [cols.index(j) if j in cols else 0 for j in range(self.num_joints)]
        self._to_model = torch.tensor(to_model, device=device)
        self._mask = torch.tensor([float(j in cols) for j in range(self.num_joints)], device=device)

    def __call__(self, front_targets_m: torch.Tensor) -> torch.Tensor:
        u = front_targets_m.clamp(0.0, self.h_max) / self.dh
        k = u.floor().clamp(max=self.table.shape[0] - 2)
        w = (u - k).unsqueeze(-1)
        pairs = self._pairs.index_select(0, k.view(-1).long()).view(-1, 2, 2, 2)
        low, high = pairs.unbind(-2)  # (N, 2 feet, 2 joints) each
        offs = (low * (self._one - w) + high * w).view(-1, 4)
        return offs.index_select(1, self._to_model) * self._mask
