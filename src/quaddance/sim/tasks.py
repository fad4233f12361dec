"""The dance task's named variants, each a complete `DanceTaskCfg` built by one function.

`paws_only` is the paper's task (front paws track their targets, the trunk stands);
`whole_body` adds the trunk's pose targets, the actor's heading input, the trunk-tracking
rewards and the training curriculum; `playback` turns a trained policy's task into the one-env,
no-time-out task that plays a dance. `TASKS` names the trainable ones for the CLI.
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from typing import Any

from quaddance.robots import GO1, RobotCfg
from quaddance.sim import rewards
from quaddance.sim.config import DanceTaskCfg, ObsCfg, RewardTerm
from quaddance.sim.scene import SceneCfg

# Table 1 of the paper: (c_f, lambda_f) pairs tried for eq. 2; "table1-5" is the chosen one.
TABLE1: dict[str, tuple[float, float]] = {
    "table1-1": (100.0, 100.0),
    "table1-2": (100.0, 10.0),
    "table1-3": (60.0, 100.0),
    "table1-4": (30.0, 100.0),
    "table1-5": (30.0, 10.0),
}
#: Forms of the front-tracking term: eq. 2 (c_f 30, lambda_f 10), the released code's L2,
#: and the rows of Table 1.
REWARD_SETS: tuple[str, ...] = ("paper", "l2", *TABLE1)

#: eq. 3's rear-leg weight c_r, the paper's final choice (section 4.3.1).
C_R = -30.0
#: The reward terms that are ours, not the paper's (eq. 2, eq. 3, Walk These Ways' auxiliaries
#: and a fall penalty): leaving them all out gives the paper's reward table.
OUR_TERMS: tuple[str, ...] = ("rear_lift_l1", "foot_slide", "base_drift", "yaw_rate")

#: `whole_body`'s curriculum from scratch, env steps: the paws-only task for 3 M steps (the
#: policy learns to stand and tap first), then the whole-body task grows in until 13 M. A run
#: that ramped only the trunk targets, with the trunk rewards at full weight from the start,
#: never learnt to lift the paws (3.5 cm front error after 7 M steps; ramped too, 1.0 cm).
WHOLE_BODY_CURRICULUM_ENV_STEPS = (3_000_000, 13_000_000)


def front_tracking(reward_set: str = "paper") -> RewardTerm:
    """Eq. 2's term in one of `REWARD_SETS`."""
    if reward_set == "l2":
        return RewardTerm(rewards.front_tracking_l2, -30.0)  # released code: -c (h - h*)^2
    if reward_set == "paper":
        c_f, lambda_f = 30.0, 10.0
    elif reward_set in TABLE1:
        c_f, lambda_f = TABLE1[reward_set]
    else:
        raise ValueError(f"unknown reward set {reward_set!r}: use {', '.join(REWARD_SETS)}")
    return RewardTerm(rewards.front_tracking, 1.0, {"c_f": c_f, "lambda_f": lambda_f})


def dance_rewards(
    reward_set: str = "paper",
    whole_body: bool = False,
    c_r: float = C_R,
    without: tuple[str, ...] = (),
) -> dict[str, RewardTerm]:
    """The reward terms, in the order they are summed; ``c_r``: eq. 3's weight; ``without``:
    terms left out (names of `OUR_TERMS` or any other term)."""
    terms = {
        "front_tracking": front_tracking(reward_set),
        "rear_lift": RewardTerm(rewards.rear_lift, c_r),  # eq. 3
        # Ours: eq. 3 is tiny for cm-scale lifts (2 cm -> 0.012), so a linear term keeps the
        # rear feet down.
        "rear_lift_l1": RewardTerm(rewards.rear_lift_l1, -50.0),
        # Walk These Ways auxiliaries (weights from WTW's Go1 config, scaled for this task).
        "torques": RewardTerm(rewards.torques, -1e-4),
        "joint_vel": RewardTerm(rewards.joint_vel, -1e-4),
        "joint_acc": RewardTerm(rewards.joint_acc, -2.5e-7),
        "action_rate": RewardTerm(rewards.action_rate, -0.01),
        "action_smoothness": RewardTerm(rewards.action_smoothness, -0.01),
        "collision": RewardTerm(rewards.collision, -5.0),
        # Relative to the body target: the plain level / standing terms when there is none.
        "base_orientation": RewardTerm(rewards.base_orientation, -1.0),
        "base_height": RewardTerm(rewards.base_height, -10.0),
        "joint_limits": RewardTerm(rewards.joint_limits, -10.0),
        "foot_slip": RewardTerm(rewards.foot_slip, -0.04),
        # Ours: -20 per m/s slid; a foot creeping 1 cm/s costs what 0.7 mm of paw error does.
        # Holding the stance feet still makes lifting a paw costly: it grows in with the
        # curriculum, else the policy learnt never to lift.
        "foot_slide": RewardTerm(rewards.foot_slide, -20.0, curriculum=True),
        "base_drift": RewardTerm(rewards.base_drift, -1.0),  # horizontal velocity: dance in place
        "yaw_rate": RewardTerm(rewards.yaw_rate, -0.5),
    }
    if whole_body:
        # Trunk-pose tracking in eq. 2's exp form, c (exp(-lambda |e|) - 1): 1 cm off costs
        # -2.9 / s (like a front foot 1 cm off), 3 deg off -4.4 / s; grown in like foot_slide.
        height = {"c": 30.0, "lambda_per_m": 10.0}
        angle = {"c": 30.0, "lambda_per_rad": 3.0}
        terms |= {
            "body_height_tracking": RewardTerm(
                rewards.body_height_tracking, 1.0, height, curriculum=True
            ),
            "body_tilt_tracking": RewardTerm(
                rewards.body_tilt_tracking, 1.0, angle, curriculum=True
            ),
            "body_yaw_tracking": RewardTerm(rewards.body_yaw_tracking, 1.0, angle, curriculum=True),
        }
    # Once per fall; outweighs the discounted penalties it escapes.
    terms["termination"] = RewardTerm(rewards.fall, -200.0, per_step=False)
    unknown = [name for name in without if name not in terms]
    if unknown:
        raise ValueError(f"no reward term {unknown[0]!r}: the terms are {', '.join(terms)}")
    return {name: term for name, term in terms.items() if name not in without}


def paws_only(
    reward_set: str = "paper",
    num_envs: int = 256,
    front_feedforward: bool = True,
    robot: RobotCfg = GO1,
    c_r: float = C_R,
    without: tuple[str, ...] = (),
) -> DanceTaskCfg:
    """The paper's task: the front paws track their height targets, the rear feet stay down
    (``c_r``, ``without``: see `dance_rewards`)."""
    return DanceTaskCfg(
        num_envs=num_envs,
        front_feedforward=front_feedforward,
        scene=SceneCfg(robot=robot),
        rewards=dance_rewards(reward_set, c_r=c_r, without=without),
    )


def whole_body(
    reward_set: str = "paper",
    num_envs: int = 256,
    front_feedforward: bool = True,
    curriculum_env_steps: tuple[int, int] | None = WHOLE_BODY_CURRICULUM_ENV_STEPS,
    robot: RobotCfg = GO1,
    c_r: float = C_R,
    without: tuple[str, ...] = (),
) -> DanceTaskCfg:
    """The trunk dances too: body targets in the bank and the observation, the heading error
    (`ObsCfg.heading`), trunk-tracking rewards, the body feed-forward, and a curriculum
    (None: the full task from the start, as when starting from a trained policy);
    ``c_r``, ``without``: see `dance_rewards`."""
    return DanceTaskCfg(
        num_envs=num_envs,
        front_feedforward=front_feedforward,
        scene=SceneCfg(robot=robot),
        whole_body=True,
        obs=ObsCfg(heading=True),
        rewards=dance_rewards(reward_set, whole_body=True, c_r=c_r, without=without),
        curriculum_env_steps=curriculum_env_steps,
    )


#: The trainable variants by the name the CLI knows them by.
TASKS: dict[str, Callable[..., DanceTaskCfg]] = {"paws-only": paws_only, "whole-body": whole_body}


def playback(task: DanceTaskCfg, n_steps: int, randomize: bool = False) -> DanceTaskCfg:
    """A trained policy's ``task`` as one env dancing ``n_steps`` policy steps without a
    time-out; ``randomize``: its dynamics drawn as in training."""
    cfg = copy.deepcopy(task)
    cfg.num_envs = 1
    cfg.domain_rand.enabled = randomize
    cfg.episode_length_s = (n_steps + 1) / cfg.policy_hz  # no time-out inside the song
    return cfg


#: The flat ``rewards`` of policy files of format 1 and of older checkpoints, with the
#: defaults those files left out (their term weights are named by the term).
FLAT_REWARDS: dict[str, Any] = {
    "form": "paper",
    "c_f": 30.0,
    "lambda_f": 10.0,
    "c_l2": 30.0,
    "c_r": -30.0,
    "rear_lift_l1": -50.0,
    "torques": -1e-4,
    "joint_vel": -1e-4,
    "joint_acc": -2.5e-7,
    "action_rate": -0.01,
    "action_smoothness": -0.01,
    "collision": -5.0,
    "base_orientation": -1.0,
    "base_height": -10.0,
    "base_height_target_m": 0.27,
    "joint_limits": -10.0,
    "foot_slip": -0.04,
    "foot_slide": -20.0,
    "base_drift": -1.0,
    "yaw_rate": -0.5,
    "c_body": 30.0,
    "lambda_body_height_per_m": 10.0,
    "lambda_body_angle_per_rad": 3.0,
    "termination": -200.0,
    "curriculum_terms": (
        "body_height_tracking",
        "body_tilt_tracking",
        "body_yaw_tracking",
        "foot_slide",
    ),
}


def rewards_from_flat(
    flat: dict[str, Any], whole_body: bool
) -> tuple[dict[str, RewardTerm], float]:
    """The reward terms and the standing height of a flat ``rewards`` (`FLAT_REWARDS`)."""
    f = {**FLAT_REWARDS, **flat}
    terms = dance_rewards("l2" if f["form"] == "l2" else "paper", whole_body)
    front = terms["front_tracking"]
    if f["form"] == "l2":
        front.weight = -f["c_l2"]
    else:
        front.params = {"c_f": f["c_f"], "lambda_f": f["lambda_f"]}
    terms["rear_lift"].weight = f["c_r"]
    for name, term in terms.items():
        term.weight = f.get(name, term.weight)
        term.curriculum = name in f["curriculum_terms"]
    trunk = (
        ("body_height_tracking", "lambda_per_m", "lambda_body_height_per_m"),
        ("body_tilt_tracking", "lambda_per_rad", "lambda_body_angle_per_rad"),
        ("body_yaw_tracking", "lambda_per_rad", "lambda_body_angle_per_rad"),
    )
    for name, key, flat_key in trunk:
        if name in terms:
            terms[name].params = {"c": f["c_body"], key: f[flat_key]}
    return terms, f["base_height_target_m"]
