"""Observation terms: small functions of the env, each returning (N, k).

The policy input is [proprio, proprio history, front targets now, preview]; the critic adds
privileged terms. `observation_layout` names every slice (written into the policy's JSON).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import torch

from quaddance.sim import go1

if TYPE_CHECKING:
    from quaddance.sim.task import DanceEnv

PROPRIO_TERMS: tuple[tuple[str, int], ...] = (
    ("projected_gravity", 3),
    ("base_ang_vel_b", 3),
    ("joint_pos_rel", go1.NUM_JOINTS),
    ("joint_vel", go1.NUM_JOINTS),
    ("last_action", go1.NUM_JOINTS),
    ("foot_height_m", 4),
)
PROPRIO_DIM = sum(n for _, n in PROPRIO_TERMS)


def proprio(env: DanceEnv) -> torch.Tensor:
    """What the robot measures itself: gravity in the body frame, gyro, joint encoders
    (with their calibration offset), last action, and the 4 foot heights (paper, sec. 3)."""
    s = env.robot
    return torch.cat(
        [
            s.projected_gravity_b,
            s.base_ang_vel_b,
            s.joint_pos - env.nominal_joint_pos + env.joint_offset,
            s.joint_vel,
            env.last_action,
            s.foot_height_m,
        ],
        dim=1,
    )


def front_targets_now(env: DanceEnv) -> torch.Tensor:
    """(N, 2) current FL, FR target heights, m."""
    return env.targets_at(0)[:, :2]


def front_targets_preview(env: DanceEnv) -> torch.Tensor:
    """(N, 2 * len(preview_s)) upcoming FL, FR targets (our addition; can be switched off)."""
    steps = env.preview_steps
    if not steps:
        return torch.zeros(env.num_envs, 0, device=env.device)
    return torch.cat([env.targets_at(k)[:, :2] for k in steps], dim=1)


def privileged(env: DanceEnv) -> torch.Tensor:
    """Critic-only: dynamics of this env's variant, base velocity and height."""
    s = env.robot
    return torch.cat([env.dynamics, s.base_lin_vel_b, s.base_pos_w[:, 2:3]], dim=1)


def observation_layout(history_len: int, n_preview: int, privileged_critic: bool) -> dict:
    """Names and sizes of the actor's and critic's observation slices, in order."""
    actor = [(f"proprio.{n}", k) for n, k in PROPRIO_TERMS]
    actor += [(f"history[{h}].proprio", PROPRIO_DIM) for h in range(1, history_len + 1)]
    actor += [("front_targets_now_m", 2)]
    if n_preview:
        actor += [("front_targets_preview_m", 2 * n_preview)]
    critic = list(actor)
    if privileged_critic:
        critic += [
            ("privileged.dynamics", 3),
            ("privileged.base_lin_vel_b", 3),
            ("privileged.base_height_m", 1),
        ]
    return {
        "actor": [{"name": n, "size": k} for n, k in actor],
        "critic": [{"name": n, "size": k} for n, k in critic],
        "actor_dim": sum(k for _, k in actor),
        "critic_dim": sum(k for _, k in critic),
    }
