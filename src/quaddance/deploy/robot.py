"""The one interface between the dance runner and a robot, simulated or real.

A backend reads the robot's latest measurements and sends joint commands; nothing else
crosses this line. Joint arrays are in quaddance's MODEL order (FR, FL, RR, RL x hip,
thigh, calf: `quaddance.robots.RobotCfg.joint_names`), feet in the task order (FL, FR, RL, RR).
"""

from __future__ import annotations

import abc
import contextlib
import os
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np

#: Faults a backend may offer for `deploy --inject FAULT@T` (the sim backend has them all):
#: a shove that topples the robot, the state stream stopping, a NaN encoder, +50 ms latency.
FAULTS: tuple[str, ...] = ("push", "freeze", "nan", "lag")


@dataclass
class Reading:
    """What a Go1 measures, one sample (the contents of the SDK's LowState we use)."""

    seq: int  #: counter of the robot's state messages: a repeated value is no new state
    stamp_s: float  #: the robot's clock, s (only differences are meaningful)
    quat_wxyz: np.ndarray  #: (4,) IMU orientation, w x y z
    gyro_rad_s: np.ndarray  #: (3,) IMU angular velocity, trunk frame
    joint_pos_rad: np.ndarray  #: (12,) encoders, model order
    joint_vel_rad_s: np.ndarray  #: (12,)
    foot_force_n: np.ndarray = field(default_factory=lambda: np.zeros(4))  #: (4,) FL FR RL RR
    #: Age of the reading when it was read, s, where the backend can tell (sim backend: both
    #: ends share the machine's monotonic clock); NaN on a real robot.
    age_s: float = float("nan")
    battery_pct: float = float("nan")  #: state of charge where the robot reports it
    remote_keys: int = 0  #: buttons held on the vendor's remote (`quaddance.deploy.remote`)

    def is_finite(self) -> bool:
        return all(
            np.isfinite(a).all()
            for a in (self.quat_wxyz, self.gyro_rad_s, self.joint_pos_rad, self.joint_vel_rad_s)
        )


@dataclass
class JointCommand:
    """One command for the 12 motors: tau = kp (q - q_meas) + kd (dq - dq_meas) + tau_ff,
    computed by the motor boards (PD on the robot side)."""

    q_rad: np.ndarray  #: (12,) position targets, model order
    dq_rad_s: np.ndarray  #: (12,) velocity targets
    kp: np.ndarray  #: (12,) N m / rad
    kd: np.ndarray  #: (12,) N m s / rad
    tau_ff_nm: np.ndarray  #: (12,) feed-forward torque

    @classmethod
    def damping(cls, q_rad: np.ndarray, kd: float) -> JointCommand:
        """No stiffness, only joint damping: what the robot does when it gives up."""
        q = np.asarray(q_rad, dtype=float).copy()
        zero = np.zeros_like(q)
        return cls(q, zero, zero, np.full_like(zero, kd), zero)

    def is_finite(self) -> bool:
        parts = (self.q_rad, self.dq_rad_s, self.kp, self.kd, self.tau_ff_nm)
        return all(np.isfinite(a).all() for a in parts)


class Robot(abc.ABC):
    """A robot the runner can drive: `start`, then `read` / `send` every tick, then `close`."""

    name: str = "robot"

    @abc.abstractmethod
    def start(self, timeout_s: float = 30.0) -> Reading:
        """Connect and return the first reading (raises `QuaddanceError` when none comes)."""

    @abc.abstractmethod
    def read(self) -> Reading | None:
        """The latest reading (never blocks); None if nothing has arrived yet."""

    @abc.abstractmethod
    def send(self, cmd: JointCommand) -> None:
        """Send one joint command (never blocks)."""

    @abc.abstractmethod
    def close(self) -> None:
        """Disconnect; after a run the robot is left in damping by the runner, not here."""

    def inject(self, fault: str) -> bool:
        """Fault injection hook (`deploy --inject`); False where the backend cannot."""
        return False

    def info(self) -> dict:
        """Backend settings for deploy.json."""
        return {}

    def truth(self) -> dict[str, np.ndarray] | None:
        """Simulator truth by reading `seq`, for evaluation after the run (None on hardware)."""
        return None


@contextlib.contextmanager
def realtime_priority(rt_priority: int, nice: int = -10) -> Iterator[str]:
    """Run the block ahead of ordinary processes, as robot control loops are run (a late
    tick is a stale command): real-time FIFO scheduling at ``rt_priority``, else a lower nice
    value, else nothing; yields what was granted and restores the old setting after. Needs
    root or CAP_SYS_NICE.

    The loops sleep between ticks (a few % of a core) and Linux caps real-time tasks at 95 %
    of the CPU, so a real-time loop cannot lock the machine. Children do not inherit it.
    """
    try:
        old_policy, old_param = os.sched_getscheduler(0), os.sched_getparam(0)
        old_nice = os.getpriority(os.PRIO_PROCESS, 0)
    except (OSError, AttributeError):
        yield "normal (no scheduler control on this system)"
        return
    granted = "normal (no permission to raise it)"
    try:
        policy = os.SCHED_FIFO | getattr(os, "SCHED_RESET_ON_FORK", 0)
        os.sched_setscheduler(0, policy, os.sched_param(rt_priority))
        granted = f"SCHED_FIFO {rt_priority}"
    except (PermissionError, OSError):
        try:
            os.setpriority(os.PRIO_PROCESS, 0, nice)
            granted = f"nice {nice}"
        except (PermissionError, OSError):
            pass
    try:
        yield granted
    finally:
        try:
            os.sched_setscheduler(0, old_policy, old_param)
            os.setpriority(os.PRIO_PROCESS, 0, old_nice)
        except (PermissionError, OSError):
            pass  # raising needed a privilege; lowering back never fails for its owner
