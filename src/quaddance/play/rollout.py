"""Closed-loop playback: the ONNX policy dances a `Dance` on the cpu engine, one env, with
the very task code used in training.

Evaluation variants: the robot's dynamics drawn as in training (``randomize``) or pinned to
chosen values with scheduled pushes (`PinnedDynamics`, the robustness envelope), and the
feed-forward alone (``policy_output="zero"``) to show what the policy adds.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import numpy as np
import torch

from quaddance.dancefile import Dance
from quaddance.errors import QuaddanceError
from quaddance.layout import BODY, PAWS
from quaddance.play.policy import OnnxPolicy
from quaddance.robots import get_robot


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
    pushes_s: list[float] = dataclasses.field(default_factory=list)  # when a push was given
    base_height_m: np.ndarray | None = None  # (T,) trunk height above the floor
    base_rpy_rad: np.ndarray | None = None  # (T, 3) trunk roll, pitch, yaw
    body_targets: np.ndarray | None = None  # (T, 4) the dance's body targets

    def body_measured(self, standing_height_m: float) -> np.ndarray:
        """(T, 4) the trunk's pose in body-target units: height offset from the standing
        height, roll, pitch, and yaw as the twist since the first step (the heading the
        dance began with is its zero)."""
        n = self.time_s.size
        height = self.base_height_m if self.base_height_m is not None else np.zeros(n)
        rpy = self.base_rpy_rad if self.base_rpy_rad is not None else np.zeros((n, 3))
        out = np.column_stack([height - standing_height_m, rpy])
        if n:
            out[:, 3] = np.unwrap(out[:, 3]) - out[0, 3]
        return out


#: Keys of rollout.npz (`save_rollout`), written by `dance` and `live` alike.
ROLLOUT_KEYS: tuple[str, ...] = (
    "time_s",
    "foot_heights_m",
    "base_height_m",
    "base_rpy_rad",
    "targets_m",
    "body_targets",
    "beats_s",
)


def save_rollout(path, result: RolloutResult, beats_s: np.ndarray) -> None:
    """Write rollout.npz: what the simulated robot did at the policy rate (`ROLLOUT_KEYS`):
    time_s (T,), foot_heights_m (T, 4; FL, FR, RL, RR), base_height_m (T,), base_rpy_rad
    (T, 3), targets_m (T, 4), body_targets (T, 4), beats_s (B,). Atomic: complete or absent."""
    from quaddance.fileio import atomic_path

    n = result.time_s.size
    arrays = {
        "time_s": result.time_s,
        "foot_heights_m": result.feet_m,
        "base_height_m": result.base_height_m if result.base_height_m is not None else np.zeros(n),
        "base_rpy_rad": result.base_rpy_rad
        if result.base_rpy_rad is not None
        else np.zeros((n, 3)),
        "targets_m": result.targets_m,
        "body_targets": result.body_targets
        if result.body_targets is not None
        else np.zeros((n, 4)),
        "beats_s": np.asarray(beats_s, dtype=float),
    }
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        np.savez(f, **{k: np.asarray(v, dtype=np.float64) for k, v in arrays.items()})


PolicyOutput = Literal["policy", "zero"]
#: What drives the joints besides the front-lift feed-forward: the policy's actions, or
#: zero actions (the feed-forward alone on the nominal pose: the baseline the policy adds to).
POLICY_OUTPUTS: tuple[str, ...] = ("policy", "zero")

#: Directions of successive pushes (unit vectors, world x forward, y left): sideways first,
#: where a robot on three legs has the narrowest support, then backwards, right, forwards.
PUSH_DIRECTIONS: tuple[tuple[float, float], ...] = (
    (0.0, 1.0),
    (-1.0, 0.0),
    (0.0, -1.0),
    (1.0, 0.0),
)


@dataclass(frozen=True)
class PinnedDynamics:
    """One robot with chosen dynamics instead of random draws (the robustness envelope).

    Defaults are the nominal robot. Joint calibration offsets stay 0 and the start pose is
    the nominal one, so a run is deterministic. Ranges of training: `sim.config.DomainRandCfg`.
    """

    friction: float | None = None  #: foot friction; None: the scene's
    added_mass_kg: float = 0.0  #: added to the trunk
    motor_strength: float = 1.0  #: scales the PD gains
    action_lag_s: float = 0.0  #: delay of the joint targets, rounded to physics steps
    push_vel_m_s: float = 0.0  #: horizontal velocity added to the base at each push
    push_first_s: float = 2.0  #: time of the first push
    push_every_s: float = 3.0  #: time between pushes; directions cycle `PUSH_DIRECTIONS`

    def variant(self, scene) -> np.ndarray:
        """(1, 3) dynamics row (friction, added mass kg, motor strength) for the engine."""
        from quaddance.sim.engine import nominal_dynamics

        row = nominal_dynamics(scene)
        if self.friction is not None:
            row[0, 0] = self.friction
        row[0, 1], row[0, 2] = self.added_mass_kg, self.motor_strength
        return row

    def push_times_s(self, duration_s: float) -> list[float]:
        """Times of the pushes inside a dance of ``duration_s``; none without a velocity."""
        if self.push_vel_m_s <= 0 or self.push_every_s <= 0:
            return []
        n = max(0, int(np.ceil((duration_s - self.push_first_s) / self.push_every_s)))
        return [self.push_first_s + k * self.push_every_s for k in range(n)]

    def push_steps(self, n_steps: int, policy_hz: float) -> dict[int, tuple[float, float]]:
        """Policy step -> push velocity (vx, vy), m/s; directions cycle `PUSH_DIRECTIONS`."""
        pushes: dict[int, tuple[float, float]] = {}
        for k, t_s in enumerate(self.push_times_s(n_steps / policy_hz)):
            dx, dy = PUSH_DIRECTIONS[k % len(PUSH_DIRECTIONS)]
            pushes[round(t_s * policy_hz)] = (dx * self.push_vel_m_s, dy * self.push_vel_m_s)
        return pushes


def playback_env(
    dance: Dance,
    policy: OnnxPolicy,
    randomize: bool = False,
    seed: int = 0,
    pinned: PinnedDynamics | None = None,
):
    """The one-env task that plays ``dance`` for ``policy`` (see `rollout` for the args)."""
    from quaddance.sim import tasks
    from quaddance.sim.task import DanceEnv

    policy.require_robot(get_robot(dance.robot), "the dance's robot")
    cfg = tasks.playback(policy.task, dance.targets_m.shape[0], randomize)
    if abs(dance.fps - cfg.policy_hz) > 1e-6:
        raise QuaddanceError(
            f"dance is at {dance.fps} Hz but the policy runs at {cfg.policy_hz} Hz"
        )
    if randomize and pinned is not None:
        raise QuaddanceError("randomised and pinned dynamics exclude each other")
    lag_substeps = 0
    if pinned is not None:
        lag_substeps = round(pinned.action_lag_s / cfg.scene.timestep_s)
        # The task keeps the joint targets of the last 3 policy steps (sim/task.py).
        if not 0 <= lag_substeps <= 2 * cfg.decimation:
            raise QuaddanceError(
                f"action lag must be 0-{2 * cfg.decimation * cfg.scene.timestep_s * 1e3:.0f} ms, "
                f"got {pinned.action_lag_s * 1e3:.0f} ms"
            )
    ff = policy.meta.get("front_feedforward") or {}
    env = DanceEnv(
        cfg,
        np.concatenate([dance.targets_m, dance.body_targets], axis=1)[None],
        engine="cpu",
        seed=seed,
        random_start=False,
        compute_rewards=False,
        feedforward_table=ff.get("thigh_calf_offsets_rad"),
        dynamics=None if pinned is None else pinned.variant(cfg.scene),
    )
    if pinned is not None:
        # Without randomisation the task never redraws the lag, so it stays as set here.
        env.set_action_lag(lag_substeps)
    if env.obs_layout.actor_dim != policy.obs_dim:
        raise QuaddanceError(
            f"policy {policy.onnx_path} expects {policy.obs_dim} observations, the task makes "
            f"{env.obs_layout.actor_dim}"
        )
    return env


def rollout(
    dance: Dance,
    policy: OnnxPolicy,
    randomize: bool = False,
    seed: int = 0,
    progress: Callable[[int, int], None] | None = None,
    policy_output: PolicyOutput = "policy",
    pinned: PinnedDynamics | None = None,
    on_pose: Callable[[int, np.ndarray, np.ndarray], None] | None = None,
) -> RolloutResult:
    """Play the whole dance; after a fall the robot is stood up again and the dance goes on.

    Args:
        randomize: draw the dynamics as in training (friction, mass, strength, joint
            offsets, action lag, pushes), from ``seed``.
        policy_output: "policy", or "zero" for the feed-forward alone (the policy is not run).
        pinned: fixed dynamics and scheduled pushes instead (not with ``randomize``).
        on_pose: called with (step, qpos (nq,), targets (4,)) as each step is recorded, so
            that the video can be rendered while the dance is still being simulated.
    """
    if policy_output not in POLICY_OUTPUTS:
        raise QuaddanceError(
            f"policy output must be one of {POLICY_OUTPUTS}, got {policy_output!r}"
        )
    env = playback_env(dance, policy, randomize, seed, pinned)
    n_steps = dance.targets_m.shape[0]
    pushes = {} if pinned is None else pinned.push_steps(n_steps, env.cfg.policy_hz)
    # One env: torch's thread pool only adds synchronisation cost to these tiny tensors.
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        # No autograd bookkeeping on the task's many small ops: 10-20 % less CPU per step,
        # the same rollout (measured).
        with torch.inference_mode():
            return _play(env, policy, n_steps, progress, policy_output == "zero", pushes, on_pose)
    finally:
        torch.set_num_threads(threads)


def _play(
    env,
    policy: OnnxPolicy,
    n_steps: int,
    progress,
    zero_output: bool = False,
    pushes: dict[int, tuple[float, float]] | None = None,
    on_pose: Callable[[int, np.ndarray, np.ndarray], None] | None = None,
) -> RolloutResult:
    cfg = env.cfg
    pushes = pushes or {}
    pushed_s: list[float] = []
    zero_action = torch.zeros(1, env.num_actions)
    env0 = torch.zeros(1, dtype=torch.long)
    qpos = np.zeros((n_steps, env.engine.nq))
    feet = np.zeros((n_steps, 4))
    targets = np.zeros((n_steps, 4))
    body_targets = np.zeros((n_steps, 4))
    base_height = np.zeros(n_steps)
    base_rpy = np.zeros((n_steps, 3))
    falls: list[float] = []
    obs = env.get_observations()["actor"].numpy()
    start = time.perf_counter()
    for t in range(n_steps):
        # Rows read through numpy: indexing the tensors would cost a torch op each.
        robot = env.robot
        qpos[t] = robot.qpos.numpy()[0]
        feet[t] = robot.foot_height_m.numpy()[0]
        row = env.target_row(0).numpy()[0]
        targets[t], body_targets[t] = row[PAWS], row[BODY]
        base_height[t] = qpos[t, 2]  # `RobotState.base_pos_w` is qpos[:3]
        base_rpy[t] = robot.base_rpy_rad.numpy()[0]
        if on_pose is not None:
            on_pose(t, qpos[t], targets[t])
        if t in pushes:
            env.push_base(env0, torch.tensor([pushes[t]], dtype=torch.float32))
            pushed_s.append(t / cfg.policy_hz)
        action = zero_action if zero_output else torch.from_numpy(policy.act(obs))
        obs_td, _, done, extras = env.step(action)
        if done.numpy()[0]:
            if not extras["time_outs"].numpy()[0]:
                falls.append((t + 1) / cfg.policy_hz)
            env.start_at(env0, t + 1)  # carry on from where the song is
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
        pushes_s=pushed_s,
        base_height_m=base_height,
        base_rpy_rad=base_rpy,
        body_targets=body_targets,
    )
