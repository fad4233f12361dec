"""`quaddance bench body-reach`: the trunk poses a Go1 holds with its feet where they stand.

For each body-target column (height offset, roll, pitch, yaw) and sign, a batch of robots
(one env each, nominal dynamics, no policy: the body feed-forward alone, as `bench reach`
measures the paws by kinematics and PD) ramps to a pose over `RAMP_S` and holds it for
`HOLD_S`, with four feet down and again with the front-left paw lifted to `PAW_UP_M`.
A pose is *held* when the robot does not fall, the feet that should be down stay within
`FOOT_DOWN_M` of the floor (and do not slide more than `FOOT_SLIDE_M`), and the trunk is
within `POSE_TOL` of the asked pose, relative, over the hold. The reported range is the
largest amplitude below which every amplitude of the grid is held.
"""

from __future__ import annotations

import numpy as np
import torch

from quaddance.robots import GO1, RobotCfg
from quaddance.sim.config import DanceTaskCfg

SETTLE_S = 0.5  # from the spawn pose to standing (the feet spread about 3 cm meanwhile)
RAMP_S = 1.0
HOLD_S = 1.5
PAW_UP_M = 0.15
FOOT_DOWN_M = 0.015
FOOT_SLIDE_M = 0.05  # soft PD feet creep a few cm under an asymmetric load
POSE_TOL = 0.35  # achieved pose within 35 % of the asked amplitude (the policy corrects)
#: Grids per column: amplitudes tried, in body-target units (m, rad).
GRIDS: dict[str, np.ndarray] = {
    "height_offset_m": np.round(np.arange(0.01, 0.101, 0.01), 3),
    "roll_rad": np.round(np.arange(0.05, 0.501, 0.05), 3),
    "pitch_rad": np.round(np.arange(0.05, 0.501, 0.05), 3),
    "yaw_rad": np.round(np.arange(0.05, 0.501, 0.05), 3),
}
COLUMNS = tuple(GRIDS)


def _trials() -> list[tuple[int, float]]:
    """(column, signed amplitude) of every robot of the batch; the first stands still (the
    baseline the others are measured from: the standing trunk pitches about 2 deg)."""
    return [(0, 0.0)] + [
        (c, sign * float(a))
        for c, name in enumerate(COLUMNS)
        for sign in (1.0, -1.0)
        for a in GRIDS[name]
    ]


def _run(
    trials: list[tuple[int, float]], paw_up: bool, policy=None, robot: RobotCfg = GO1
) -> list[dict]:
    import copy

    from quaddance.sim.scene import SceneCfg
    from quaddance.sim.task import DanceEnv

    if policy is None:
        cfg = DanceTaskCfg(whole_body=True, scene=SceneCfg(robot=robot))
    else:
        cfg = copy.deepcopy(policy.task)
    cfg.num_envs = len(trials)
    cfg.domain_rand.enabled = False
    n_settle = round(SETTLE_S * cfg.policy_hz)
    n_ramp, n_hold = round(RAMP_S * cfg.policy_hz), round(HOLD_S * cfg.policy_hz)
    n = n_settle + n_ramp + n_hold
    cfg.episode_length_s = (n + 2) / cfg.policy_hz
    ramp = np.clip((np.arange(n) - n_settle) / n_ramp, 0.0, 1.0)
    bank = np.zeros((len(trials), n, 8), dtype=np.float32)
    for i, (col, amp) in enumerate(trials):
        bank[i, :, 4 + col] = ramp * amp
        if paw_up:
            bank[i, :, 0] = ramp * PAW_UP_M
    env = DanceEnv(cfg, bank, random_start=False, compute_rewards=False, seed=0)
    env.bank_idx[:] = torch.arange(len(trials))
    feet0 = env.robot.foot_pos_w[:, :, :2].clone()
    down = [1, 2, 3] if paw_up else [0, 1, 2, 3]
    # Why a trial failed, each check kept apart so the results say which limit was hit.
    fell = torch.zeros(len(trials), dtype=torch.bool)
    lifted = torch.zeros(len(trials))  # highest foot that should be down, over the hold, m
    slid = torch.zeros(len(trials))  # farthest slide of a foot that should be down, m
    pose = torch.zeros(len(trials), 4)
    zero = torch.zeros(len(trials), 12)
    obs = env.get_observations()["actor"]
    for t in range(n):
        action = zero if policy is None else torch.from_numpy(policy.act(obs.numpy()))
        obs_td, _, done, _ = env.step(action)
        obs = obs_td["actor"]
        fell |= done
        if t == n_settle - 1:
            feet0 = env.robot.foot_pos_w[:, :, :2].clone()
        if t >= n_settle + n_ramp:
            r = env.robot
            lifted = torch.maximum(lifted, r.foot_height_m[:, down].amax(dim=1))
            slide = (r.foot_pos_w[:, down, :2] - feet0[:, down]).norm(dim=2).amax(dim=1)
            slid = torch.maximum(slid, slide)
            pose += torch.cat(
                [(r.base_pos_w[:, 2] - cfg.base_height_target_m)[:, None], r.base_rpy_rad],
                dim=1,
            )
    pose /= n_hold
    pose -= pose[0].clone()  # relative to the standing robot (trial 0)
    out = []
    for i, (col, amp) in enumerate(trials[1:], start=1):
        got = float(pose[i, col])
        failed = [
            why
            for why, bad in (
                ("fell", bool(fell[i])),
                ("foot lifted", float(lifted[i]) >= FOOT_DOWN_M),
                ("foot slid", float(slid[i]) >= FOOT_SLIDE_M),
                ("pose missed", abs(got - amp) > POSE_TOL * abs(amp)),
            )
            if bad
        ]
        out.append(
            {
                "column": COLUMNS[col],
                "amplitude": amp,
                "achieved": got,
                "held": not failed,
                "failed": failed,
                "max_lift_m": float(lifted[i]),
                "max_slide_m": float(slid[i]),
            }
        )
    return out


def _ranges(results: list[dict]) -> dict[str, list[float]]:
    """Per column [lowest, highest] amplitude held with every smaller one held too."""
    out = {}
    for name in COLUMNS:
        rng = []
        for sign in (-1.0, 1.0):
            best = 0.0
            for a in GRIDS[name]:
                hit = [r for r in results if r["column"] == name and r["amplitude"] == sign * a]
                if not hit or not hit[0]["held"]:
                    break
                best = float(a)
            rng.append(sign * best)
        out[name] = rng
    return out


def bench_body_reach(policy=None, robot: RobotCfg = GO1) -> dict:
    """Ranges held with four feet down and with the front-left paw up; every trial listed.
    ``policy``: a whole-body `OnnxPolicy` balancing on top of the feed-forward (on the robot
    it was trained for); None: the body feed-forward alone on ``robot`` (a robot on three
    legs then tips: its paw-up range is 0)."""
    if policy is not None and not policy.task.whole_body:
        from quaddance.errors import QuaddanceError

        raise QuaddanceError(f"{policy.onnx_path} is not a whole-body policy")
    trials = _trials()
    if policy is not None:
        robot = policy.task.scene.robot
    four = _run(trials, paw_up=False, policy=policy, robot=robot)
    paw = _run(trials, paw_up=True, policy=policy, robot=robot)
    who = "the body feed-forward alone" if policy is None else f"policy {policy.onnx_path.name}"
    return {
        "what": f"trunk poses held by {who}, nominal dynamics, cpu engine",
        "robot": robot.name,
        "criteria": {
            "ramp_s": RAMP_S,
            "hold_s": HOLD_S,
            "foot_down_m": FOOT_DOWN_M,
            "foot_slide_m": FOOT_SLIDE_M,
            "pose_tolerance_rel": POSE_TOL,
            "paw_up_m": PAW_UP_M,
        },
        "four_feet": _ranges(four),
        "paw_up": _ranges(paw),
        "trials": {"four_feet": four, "paw_up": paw},
    }
