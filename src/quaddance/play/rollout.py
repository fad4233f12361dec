"""Closed-loop playback: the ONNX policy dances a `Dance` on the cpu engine, one env, with
the very task code used in training."""

from __future__ import annotations

import copy
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch

from quaddance.dancefile import Dance
from quaddance.errors import QuaddanceError
from quaddance.play.policy import OnnxPolicy


@dataclass
class RolloutResult:
    """Per policy step (fps = policy rate): what the robot did."""

    fps: float
    time_s: np.ndarray  # (T,)
    qpos: np.ndarray  # (T, nq) for rendering
    feet_m: np.ndarray  # (T, 4) measured foot heights, FL FR RL RR
    targets_m: np.ndarray  # (T, 4)
    falls_s: list[float]
    sim_wall_s: float


def rollout(
    dance: Dance,
    policy: OnnxPolicy,
    randomize: bool = False,
    seed: int = 0,
    progress: Callable[[int, int], None] | None = None,
) -> RolloutResult:
    """Play the whole dance; after a fall the robot is stood up again and the dance goes on."""
    from quaddance.sim.task import DanceEnv

    cfg = copy.deepcopy(policy.task)
    if abs(dance.fps - cfg.policy_hz) > 1e-6:
        raise QuaddanceError(
            f"dance is at {dance.fps} Hz but the policy runs at {cfg.policy_hz} Hz"
        )
    cfg.num_envs = 1
    cfg.domain_rand.enabled = randomize
    n_steps = dance.targets_m.shape[0]
    cfg.episode_length_s = (n_steps + 1) / cfg.policy_hz  # no time-out inside the song
    ff = policy.meta.get("front_feedforward") or {}
    env = DanceEnv(
        cfg,
        dance.targets_m[None],
        engine="cpu",
        seed=seed,
        random_start=False,
        compute_rewards=False,
        feedforward_table=ff.get("thigh_calf_offsets_rad"),
    )
    if env.obs_layout["actor_dim"] != policy.obs_dim:
        raise QuaddanceError(
            f"policy {policy.onnx_path} expects {policy.obs_dim} observations, the task makes "
            f"{env.obs_layout['actor_dim']}"
        )
    # One env: torch's thread pool only adds synchronisation cost to these tiny tensors.
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        return _play(env, policy, n_steps, progress)
    finally:
        torch.set_num_threads(threads)


def _play(env, policy: OnnxPolicy, n_steps: int, progress) -> RolloutResult:
    cfg = env.cfg
    qpos = np.zeros((n_steps, env.engine.nq))
    feet = np.zeros((n_steps, 4))
    targets = np.zeros((n_steps, 4))
    falls: list[float] = []
    obs = env.get_observations()["actor"].numpy()
    start = time.perf_counter()
    for t in range(n_steps):
        qpos[t] = env.engine.read().qpos[0].numpy()
        feet[t] = env.robot.foot_height_m[0].numpy()
        targets[t] = env.targets_at(0)[0].numpy()
        action = torch.from_numpy(policy.act(obs))
        obs_td, _, done, extras = env.step(action)
        if bool(done[0]):
            if not bool(extras["time_outs"][0]):
                falls.append((t + 1) / cfg.policy_hz)
            env.bank_offset[0] = t + 1  # carry on from where the song is
            obs_td = env.get_observations()
        obs = obs_td["actor"].numpy()
        if progress is not None:
            progress(t + 1, n_steps)
    return RolloutResult(
        fps=cfg.policy_hz,
        time_s=np.arange(n_steps) / cfg.policy_hz,
        qpos=qpos,
        feet_m=feet,
        targets_m=targets,
        falls_s=falls,
        sim_wall_s=time.perf_counter() - start,
    )
