"""Termination terms: one function each, ``fn(env) -> (N,)`` bool, listed in `TERMS`."""

from __future__ import annotations

import functools
import operator
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import torch

from quaddance.sim.state import scalar_tensor

if TYPE_CHECKING:
    from quaddance.sim.task import DanceEnv


@dataclass(frozen=True)
class TerminationTerm:
    """One way an episode ends; ``time_out``: the episode ran its length (rsl-rl bootstraps
    the value there), else the robot failed (the `rewards.fall` term pays for it)."""

    fn: Callable[[DanceEnv], torch.Tensor]
    time_out: bool = False


@functools.lru_cache(maxsize=8)
def _cos_f32(angle_rad: float) -> float:
    """The float32 cosine, exactly as a float32 tensor compares with it; made once."""
    return torch.cos(torch.tensor(angle_rad)).item()


def fell(env: DanceEnv) -> torch.Tensor:
    """The trunk touches the floor, tilts past `max_tilt_rad`, or sinks below the minimum."""
    s = env.robot
    # Tilted: cos(tilt) = -gravity_z below cos(max_tilt_rad), i.e. gravity_z above its negative.
    gravity_z, height_m = s.projected_gravity_b[:, 2], s.base_pos_w[:, 2]
    tilted = gravity_z > scalar_tensor(-_cos_f32(env.cfg.max_tilt_rad), gravity_z)
    low = height_m < scalar_tensor(env.cfg.min_base_height_m, height_m)
    return s.base_contact | tilted | low


def time_out(env: DanceEnv) -> torch.Tensor:
    return env.episode_length_buf >= env.max_episode_length


#: The task's terminations by name; a time-out of an env that also failed counts as a fall.
TERMS: dict[str, TerminationTerm] = {
    "fell": TerminationTerm(fell),
    "time_out": TerminationTerm(time_out, time_out=True),
}


def evaluate(env: DanceEnv) -> tuple[torch.Tensor, torch.Tensor]:
    """(failed, timed out), each (N,) bool, the or of the failure and of the time-out `TERMS`;
    an env that both failed and ran out of time failed."""
    failed = functools.reduce(operator.or_, (t.fn(env) for t in TERMS.values() if not t.time_out))
    timed_out = functools.reduce(operator.or_, (t.fn(env) for t in TERMS.values() if t.time_out))
    return failed, timed_out & ~failed
