"""The dance task as plain data: the policy JSON's ``task`` and a checkpoint's config.

Apart from `sim/config.py` because reading a record written before reward terms were
entries needs `quaddance.sim.tasks`, which builds on the config.
"""

from __future__ import annotations

import dataclasses
import functools
import inspect
from typing import Any

from quaddance.robots import GO1, RobotCfg
from quaddance.sim.config import DanceTaskCfg, DomainRandCfg, ObsCfg, RewardTerm
from quaddance.sim.scene import SceneCfg


def task_record(cfg: DanceTaskCfg) -> dict[str, Any]:
    """The task as plain data (the policy JSON's ``task``, a checkpoint's config): each reward
    term's function by its name in `quaddance.sim.rewards`; without the robot, which the
    policy JSON's top-level ``robot`` names."""
    record = dataclasses.asdict(dataclasses.replace(cfg, rewards={}))
    del record["scene"]["robot"]
    record["rewards"] = {
        name: {
            "fn": term.fn.__name__,
            "weight": term.weight,
            "params": dict(term.params),
            "curriculum": term.curriculum,
            "per_step": term.per_step,
        }
        for name, term in cfg.rewards.items()
    }
    return record


def task_from_record(record: dict[str, Any], robot: RobotCfg = GO1) -> DanceTaskCfg:
    """The task of ``robot`` in a `task_record` (or in a record written before reward terms
    were entries, whose flat ``rewards`` `quaddance.sim.tasks.rewards_from_flat` turns into
    terms)."""
    task = dict(record)
    # Checkpoints of earlier versions hold the robot in the scene; it is ``robot`` here.
    task["scene"] = {k: v for k, v in task.get("scene", {}).items() if k != "robot"}
    parts = {
        "scene": functools.partial(SceneCfg, robot=robot),
        "domain_rand": DomainRandCfg,
        "obs": ObsCfg,
    }
    built: dict[str, Any] = {
        key: cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in task.pop(key).items()})
        for key, cls in parts.items()
        if key in task
    }
    rewards = task.pop("rewards", {})
    if any(not isinstance(v, dict) for v in rewards.values()):
        from quaddance.sim.tasks import rewards_from_flat  # torch: only for older records

        built["rewards"], task["base_height_target_m"] = rewards_from_flat(
            rewards, task.get("whole_body", False)
        )
    else:
        built["rewards"] = {name: reward_term(entry) for name, entry in rewards.items()}
    if task.get("curriculum_env_steps") is not None:
        task["curriculum_env_steps"] = tuple(task["curriculum_env_steps"])
    return DanceTaskCfg(**task, **built)


def reward_term(entry: dict[str, Any]) -> RewardTerm:
    """A `RewardTerm` of its record; the function must be one of `quaddance.sim.rewards`."""
    from quaddance.sim import rewards  # torch: only when a record is read

    name = entry["fn"]
    fn = None if name.startswith("_") else getattr(rewards, name, None)
    if not inspect.isfunction(fn) or fn.__module__ != rewards.__name__:
        raise ValueError(f"{name!r} is not a reward function of quaddance.sim.rewards")
    try:
        inspect.signature(fn).bind(None, **entry["params"])
    except TypeError as err:
        raise ValueError(f"{name}'s parameters: {err}") from None
    return RewardTerm(
        fn, entry["weight"], dict(entry["params"]), entry["curriculum"], entry["per_step"]
    )
