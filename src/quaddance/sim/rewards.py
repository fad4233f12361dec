"""Reward terms: one small function each, ``fn(env, **params) -> (N,)`` before its weight.

A task's terms are `RewardTerm` entries (function, weight, parameters, curriculum) of
`DanceTaskCfg.rewards`, built by `quaddance.sim.tasks`. The tracking errors that several terms
and the training log read are computed once per step, by `TrackingErrors`.
"""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING

import torch

from quaddance.sim.state import wrap_angle_rad

if TYPE_CHECKING:
    from quaddance.sim.task import DanceEnv


class TrackingErrors:
    """The dance's tracking errors at one step, each computed once when first read (the reward
    terms and the training log share them); `DanceEnv` makes a new one after every step."""

    def __init__(self, env: DanceEnv) -> None:
        self._env = env

    @functools.cached_property
    def front_m(self) -> torch.Tensor:
        """(N, 2) FL, FR foot height minus its target, m."""
        return self._env.robot.foot_height_m[:, :2] - self._env.targets_at(0)[:, :2]

    @functools.cached_property
    def body_height_m(self) -> torch.Tensor:
        """(N,) trunk height minus the standing height plus the body target's offset, m."""
        env = self._env
        target_m = env.cfg.base_height_target_m + env.body_targets_at(0)[:, 0]
        return env.robot.base_pos_w[:, 2] - target_m

    @functools.cached_property
    def gravity_target_b(self) -> torch.Tensor:
        """(N, 3) gravity direction in the trunk frame at the body target's roll and pitch."""
        return target_gravity_b(self._env.body_targets_at(0))

    @functools.cached_property
    def body_tilt(self) -> torch.Tensor:
        """(N,) distance of the gravity direction from the target's (about the tilt, rad)."""
        return (self._env.robot.projected_gravity_b - self.gravity_target_b).norm(dim=1)

    @functools.cached_property
    def body_yaw_rad(self) -> torch.Tensor:
        """(N,) heading minus the target yaw, wrapped; episodes start facing yaw 0."""
        env = self._env
        return wrap_angle_rad(env.robot.base_yaw_rad - env.body_targets_at(0)[:, 3])


def front_tracking(env: DanceEnv, c_f: float, lambda_f: float) -> torch.Tensor:
    """Eq. 2: sum over FL, FR of c_f (exp(-lambda_f |h - h*|) - 1); 0 when tracked (Table 1
    of the paper varies c_f and lambda_f together, so they are the term's parameters)."""
    err = env.errors.front_m
    return (c_f * (torch.exp(-lambda_f * err.abs()) - 1.0)).sum(dim=1)


def front_tracking_l2(env: DanceEnv) -> torch.Tensor:
    """The released code's form of eq. 2: (h - h*)^2 summed over FL, FR."""
    return (env.errors.front_m**2).sum(dim=1)


def rear_lift(env: DanceEnv) -> torch.Tensor:
    """Eq. 3: h_rl^2 + h_rr^2 (its weight is the paper's c_r)."""
    h = env.robot.foot_height_m[:, 2:].clamp(min=0.0)
    return (h**2).sum(dim=1)


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
    g_star = env.errors.gravity_target_b
    return ((env.robot.projected_gravity_b[:, :2] - g_star[:, :2]) ** 2).sum(dim=1)


def base_height(env: DanceEnv) -> torch.Tensor:
    """Squared trunk height error (standing height plus the body target's offset)."""
    return env.errors.body_height_m**2


def _exp_tracking(err: torch.Tensor, lam: float, c: float) -> torch.Tensor:
    return c * (torch.exp(-lam * err.abs()) - 1.0)


def body_height_tracking(env: DanceEnv, c: float, lambda_per_m: float) -> torch.Tensor:
    """Trunk height vs standing height + the target's offset, eq. 2's exp form."""
    return _exp_tracking(env.errors.body_height_m, lambda_per_m, c)


def body_tilt_tracking(env: DanceEnv, c: float, lambda_per_rad: float) -> torch.Tensor:
    """Roll and pitch vs the target's: the gravity direction's distance (about the angle)."""
    return _exp_tracking(env.errors.body_tilt, lambda_per_rad, c)


def body_yaw_tracking(env: DanceEnv, c: float, lambda_per_rad: float) -> torch.Tensor:
    """Heading vs the target yaw; episodes start facing yaw 0, so heading = twist."""
    return _exp_tracking(env.errors.body_yaw_rad, lambda_per_rad, c)


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


def fall(env: DanceEnv) -> torch.Tensor:
    """1 where the robot fell this step (`quaddance.sim.terminations.fell`), else 0."""
    return env.fell.float()
