"""Reward terms: one small function each, returning (N,) before the weight and dt."""

from __future__ import annotations

from typing import TYPE_CHECKING

import torch

from quaddance.sim.state import wrap_angle_rad

if TYPE_CHECKING:
    from quaddance.sim.task import DanceEnv


def front_tracking(env: DanceEnv) -> torch.Tensor:
    """Eq. 2: sum over FL, FR of c_f (exp(-lambda_f |h - h*|) - 1) (0 when tracked), or the
    released code's L2 form -c (h - h*)^2 when `form == "l2"`."""
    cfg = env.cfg.rewards
    err = env.robot.foot_height_m[:, :2] - env.targets_at(0)[:, :2]
    if cfg.form == "l2":
        return -cfg.c_l2 * (err**2).sum(dim=1)
    return (cfg.c_f * (torch.exp(-cfg.lambda_f * err.abs()) - 1.0)).sum(dim=1)


def rear_lift(env: DanceEnv) -> torch.Tensor:
    """Eq. 3: c_r (h_rl^2 + h_rr^2); the weight of this term is 1 (c_r carries the sign)."""
    h = env.robot.foot_height_m[:, 2:].clamp(min=0.0)
    return env.cfg.rewards.c_r * (h**2).sum(dim=1)


def rear_lift_l1(env: DanceEnv) -> torch.Tensor:
    """Sum of rear-foot heights above the floor, m."""
    return env.robot.foot_height_m[:, 2:].clamp(min=0.0).sum(dim=1)


def torques(env: DanceEnv) -> torch.Tensor:
    return (env.robot.joint_torque**2).sum(dim=1)


def joint_vel(env: DanceEnv) -> torch.Tensor:
    return (env.robot.joint_vel**2).sum(dim=1)


def joint_acc(env: DanceEnv) -> torch.Tensor:
    acc = (env.robot.joint_vel - env.prev_joint_vel) / env.cfg.step_dt_s
    return (acc**2).sum(dim=1)


def action_rate(env: DanceEnv) -> torch.Tensor:
    return ((env.last_action - env.prev_action) ** 2).sum(dim=1)


def action_smoothness(env: DanceEnv) -> torch.Tensor:
    """Second difference of actions (WTW's smoothness term)."""
    return ((env.last_action - 2 * env.prev_action + env.prev_prev_action) ** 2).sum(dim=1)


def collision(env: DanceEnv) -> torch.Tensor:
    """Number of thighs and knees touching the floor."""
    return env.robot.leg_contacts.float()


def target_gravity_b(body: torch.Tensor) -> torch.Tensor:
    """(N, 3) gravity direction in the trunk frame when the trunk has the body targets' roll
    and pitch (yaw does not change it)."""
    r, p = body[:, 1], body[:, 2]
    return torch.stack([p.sin(), -p.cos() * r.sin(), -p.cos() * r.cos()], dim=1)


def base_orientation(env: DanceEnv) -> torch.Tensor:
    """Squared tilt away from the body target's roll and pitch (level when there is none)."""
    g_star = target_gravity_b(env.body_targets_at(0))
    return ((env.robot.projected_gravity_b[:, :2] - g_star[:, :2]) ** 2).sum(dim=1)


def _height_target_m(env: DanceEnv) -> torch.Tensor:
    return env.cfg.rewards.base_height_target_m + env.body_targets_at(0)[:, 0]


def base_height(env: DanceEnv) -> torch.Tensor:
    return (env.robot.base_pos_w[:, 2] - _height_target_m(env)) ** 2


def _exp_tracking(err: torch.Tensor, lam: float, c: float) -> torch.Tensor:
    return c * (torch.exp(-lam * err.abs()) - 1.0)


def body_height_tracking(env: DanceEnv) -> torch.Tensor:
    """Trunk height vs standing height + the target's offset, eq. 2's exp form."""
    cfg = env.cfg.rewards
    err = env.robot.base_pos_w[:, 2] - _height_target_m(env)
    return _exp_tracking(err, cfg.lambda_body_height_per_m, cfg.c_body)


def body_tilt_tracking(env: DanceEnv) -> torch.Tensor:
    """Roll and pitch vs the target's: the gravity direction's distance (about the angle)."""
    cfg = env.cfg.rewards
    g_star = target_gravity_b(env.body_targets_at(0))
    err = (env.robot.projected_gravity_b - g_star).norm(dim=1)
    return _exp_tracking(err, cfg.lambda_body_angle_per_rad, cfg.c_body)


def body_yaw_tracking(env: DanceEnv) -> torch.Tensor:
    """Heading vs the target yaw; episodes start facing yaw 0, so heading = twist."""
    cfg = env.cfg.rewards
    err = wrap_angle_rad(env.robot.base_yaw_rad - env.body_targets_at(0)[:, 3])
    return _exp_tracking(err, cfg.lambda_body_angle_per_rad, cfg.c_body)


def joint_limits(env: DanceEnv) -> torch.Tensor:
    """How far joints are past 90 % of their range, rad."""
    q = env.robot.joint_pos
    lo, hi = env.soft_joint_limits
    return ((lo - q).clamp(min=0) + (q - hi).clamp(min=0)).sum(dim=1)


def _on_ground(env: DanceEnv) -> torch.Tensor:
    """(N, 4) feet on the ground: lower than 1 cm."""
    return env.robot.foot_height_m < 0.01


def foot_slip(env: DanceEnv) -> torch.Tensor:
    """Horizontal speed^2 of feet on the ground (height < 1 cm)."""
    v2 = (env.robot.foot_vel_w[..., :2] ** 2).sum(dim=2)
    return (v2 * _on_ground(env)).sum(dim=1)


def foot_slide(env: DanceEnv) -> torch.Tensor:
    """Horizontal speed of the feet on the ground (height < 1 cm), summed, m/s: the distance
    they slide per second. Unlike `foot_slip`'s squares it does not vanish for a slow creep,
    which had the robot wander about 30 cm in a 30 s dance."""
    return (env.robot.foot_vel_w[..., :2].norm(dim=2) * _on_ground(env)).sum(dim=1)


def base_drift(env: DanceEnv) -> torch.Tensor:
    return (env.robot.base_lin_vel_w[:, :2] ** 2).sum(dim=1)


def yaw_rate(env: DanceEnv) -> torch.Tensor:
    """Squared yaw rate beyond the body target's (zero when the trunk does not twist)."""
    want = (env.body_targets_at(1)[:, 3] - env.body_targets_at(0)[:, 3]) / env.cfg.step_dt_s
    return (env.robot.base_ang_vel_b[:, 2] - want) ** 2


# name -> (term, weight attribute of RewardCfg or None for weight 1)
TERMS = {
    "front_tracking": (front_tracking, None),
    "rear_lift": (rear_lift, None),
    "rear_lift_l1": (rear_lift_l1, "rear_lift_l1"),
    "torques": (torques, "torques"),
    "joint_vel": (joint_vel, "joint_vel"),
    "joint_acc": (joint_acc, "joint_acc"),
    "action_rate": (action_rate, "action_rate"),
    "action_smoothness": (action_smoothness, "action_smoothness"),
    "collision": (collision, "collision"),
    "base_orientation": (base_orientation, "base_orientation"),
    "base_height": (base_height, "base_height"),
    "joint_limits": (joint_limits, "joint_limits"),
    "foot_slip": (foot_slip, "foot_slip"),
    "foot_slide": (foot_slide, "foot_slide"),
    "base_drift": (base_drift, "base_drift"),
    "yaw_rate": (yaw_rate, "yaw_rate"),
}
#: Terms of whole-body dance only (DanceTaskCfg.whole_body); weight 1, c_body carries it.
BODY_TERMS = {
    "body_height_tracking": (body_height_tracking, None),
    "body_tilt_tracking": (body_tilt_tracking, None),
    "body_yaw_tracking": (body_yaw_tracking, None),
}
#: Every reward term's name (`RewardCfg.curriculum_terms` must name some of these).
TERM_NAMES: tuple[str, ...] = (*TERMS, *BODY_TERMS)
