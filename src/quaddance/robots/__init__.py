"""Robot configs: every fact about a robot that quaddance uses, one module per robot.

A robot is one frozen `RobotCfg` (`quaddance.robots.go1.GO1` is the first). The scene, the
kinematics, the feed-forwards, the body IK, the terminations, the feasible targets, the safety
layer and the backends all read it; nothing else holds a robot number. A new robot is a new
module here with its `RobotCfg`, added to `ROBOTS`.

Torch-free and cheap to import (numpy only): a policy reader or a robot runner loads it.
"""

from __future__ import annotations

from quaddance.errors import QuaddanceError
from quaddance.robots.config import BodyLimits, FrontLiftCfg, RobotCfg, SafetyLimits
from quaddance.robots.go1 import GO1
from quaddance.robots.go2 import GO2

__all__ = [
    "GO1",
    "GO2",
    "ROBOTS",
    "BodyLimits",
    "FrontLiftCfg",
    "RobotCfg",
    "SafetyLimits",
    "get_robot",
]

ROBOTS: dict[str, RobotCfg] = {GO1.name: GO1, GO2.name: GO2}
"""Every robot by name."""


def get_robot(name: str) -> RobotCfg:
    """The robot called ``name`` (`ROBOTS`; the short form ``go2`` names ``unitree_go2``),
    or one error listing those there are."""
    robot = ROBOTS.get(name) or ROBOTS.get(f"unitree_{name}")
    if robot is None:
        known = ", ".join(r.short_name for r in ROBOTS.values())
        raise QuaddanceError(f"unknown robot {name!r}; known: {known}")
    return robot
