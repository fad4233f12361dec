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

from quaddance.sim import go1
from quaddance.sim.scene import SceneCfg, build_model

LUT_HEIGHTS_M = np.round(np.linspace(0.0, 0.45, 46), 4)
FORWARD_PER_UP = 0.25  # the foot moves forward 2.5 cm per 10 cm up: clears the elbow


@functools.lru_cache(maxsize=2)
def lift_table(scene: SceneCfg = SceneCfg()) -> np.ndarray:
    """(H, 2) thigh and calf offsets (rad) from the nominal pose that raise a front foot by
    `LUT_HEIGHTS_M` relative to the trunk (FL; FR is its mirror image in the sagittal
    plane, so the same offsets apply)."""
    model = build_model(scene)
    data = mujoco.MjData(model)
    data.qpos[:] = model.key("home").qpos
    site = model.site("FL").id
    ti = model.joint("FL_thigh_joint").qposadr[0]
    ci = model.joint("FL_calf_joint").qposadr[0]
    mujoco.mj_kinematics(model, data)
    x0, z0 = data.site_xpos[site][0], data.site_xpos[site][2]
    thigh0, calf0 = data.qpos[ti], data.qpos[ci]
    lo_t, hi_t = model.jnt_range[model.joint("FL_thigh_joint").id]
    lo_c, hi_c = model.jnt_range[model.joint("FL_calf_joint").id]
    # Forward kinematics over a grid of the two joints (about 1 s, once per process).
    thighs = np.linspace(max(lo_t, thigh0 - 1.4), min(hi_t, thigh0 + 0.6), 101)
    calves = np.linspace(max(lo_c, calf0 - 1.2), min(hi_c, calf0 + 0.6), 91)
    pos = np.zeros((thighs.size, calves.size, 2))
    for i, a in enumerate(thighs):
        for j, b in enumerate(calves):
            data.qpos[ti], data.qpos[ci] = a, b
            mujoco.mj_kinematics(model, data)
            pos[i, j] = data.site_xpos[site][[0, 2]]
    out = np.zeros((LUT_HEIGHTS_M.size, 2))
    prev = np.array([thigh0, calf0])
    for k, h in enumerate(LUT_HEIGHTS_M):
        want = np.array([x0 + FORWARD_PER_UP * h, z0 + h])
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
        self, scene: SceneCfg, device: torch.device, table: np.ndarray | None = None
    ) -> None:
        table = lift_table(scene) if table is None else np.asarray(table, dtype=np.float64)
        if table.shape != (LUT_HEIGHTS_M.size, 2):
            raise ValueError(
                f"feed-forward table must be {(LUT_HEIGHTS_M.size, 2)}, got {table.shape}"
            )
        self.table = torch.as_tensor(table, dtype=torch.float32, device=device)
        self.h_max = float(LUT_HEIGHTS_M[-1])
        self.dh = float(LUT_HEIGHTS_M[1] - LUT_HEIGHTS_M[0])
        legs = {leg: i for i, leg in enumerate(go1.MODEL_LEGS)}
        # (thigh, calf) joint indices of FL and FR in model order.
        self.cols = [(3 * legs[f] + 1, 3 * legs[f] + 2) for f in ("FL", "FR")]

    def __call__(self, front_targets_m: torch.Tensor) -> torch.Tensor:
        u = front_targets_m.clamp(0.0, self.h_max) / self.dh
        k = u.floor().long().clamp(max=self.table.shape[0] - 2)
        w = (u - k).unsqueeze(-1)
        offs = self.table[k] * (1 - w) + self.table[k + 1] * w  # (N, 2 feet, 2 joints)
        out = torch.zeros(front_targets_m.shape[0], go1.NUM_JOINTS, device=u.device)
        for f, (ti, ci) in enumerate(self.cols):
            out[:, ti] = offs[:, f, 0]
            out[:, ci] = offs[:, f, 1]
        return out
