"""Termination terms: (N,) bool."""

from __future__ import annotations

from typing import TYPE_CHECKING

import torch

if TYPE_CHECKING:
    from quaddance.sim.task import DanceEnv


def fell(env: DanceEnv) -> torch.Tensor:
    """The trunk touches the floor, tilts past `max_tilt_rad`, or sinks below the minimum."""
    s = env.robot
    cos_tilt = -s.projected_gravity_b[:, 2]
    tilted = cos_tilt < torch.cos(torch.tensor(env.cfg.max_tilt_rad))
    low = s.base_pos_w[:, 2] < env.cfg.min_base_height_m
    return s.base_contact | tilted | low


def time_out(env: DanceEnv) -> torch.Tensor:
    return env.episode_length_buf >= env.max_episode_length
