"""The safety layer every backend goes through: a state machine and per-tick guards.

States: ``passive`` (damping) -> ``stand`` (soft start from the measured pose to the nominal
one, gains ramped) -> ``ready`` (holds the stand; Enter or --auto-start) -> ``dance`` ->
``done`` (the policy stands, feet down, then damping). Any state but passive may fall into
``damp``: damping commands until the runner exits. The ideas follow public Go1 deploy code
(Walk These Ways: soft start, stop on large roll/pitch; unitree_rl_gym: zero torque -> 2 s to
the default pose -> run, damping on demand); the code is ours.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from quaddance.deploy.remote import damp_pressed
from quaddance.deploy.robot import JointCommand, Reading
from quaddance.deploy.states import DeployState
from quaddance.robots import RobotCfg


def soft_joint_limits_rad(joint_range_rad: np.ndarray, margin_rad: float) -> np.ndarray:
    """(12, 2) target limits: each joint's range (the robot's model) less ``margin_rad`` at
    both ends. Not the task's 0.9-of-range reward limits: the front-lift feed-forward asks
    the calves for -2.70 rad at 0.25 m, inside the range (-2.82) but outside 0.9 of it."""
    return np.stack([joint_range_rad[:, 0] + margin_rad, joint_range_rad[:, 1] - margin_rad], 1)


def joint_range_rad(robot: RobotCfg) -> np.ndarray:
    """(12, 2) joint ranges of the robot's model, rad (read from its MJCF: one source)."""
    from quaddance.sim.scene import SceneCfg, build_model

    return np.asarray(build_model(SceneCfg(robot=robot)).jnt_range[1:], dtype=np.float64)


def roll_pitch_rad(
    projected_gravity_b: np.ndarray,
) -> tuple[float | np.ndarray, float | np.ndarray]:
    """Roll and pitch of the trunk from the unit gravity direction in its frame: (3,) ->
    two floats, (T, 3) -> two (T,) arrays."""
    g = np.asarray(projected_gravity_b, dtype=np.float64)
    gx, gy, gz = g[..., 0], g[..., 1], g[..., 2]
    return np.arctan2(-gy, -gz), np.arctan2(gx, np.hypot(gy, gz))


def battery_problem(pct: float, min_pct: float) -> str | None:
    """Why a battery at ``pct`` % must not start a run (None: it may, or it is not
    reported)."""
    if np.isfinite(pct) and pct < min_pct:
        return f"battery at {pct:.0f} %, below {min_pct:g} %: charge it first"
    return None


@dataclass(frozen=True)
class SafetyCfg:
    """Timings of the safety layer; ticks are policy ticks (50 Hz). Its limits are the
    robot's (`RobotCfg.safety_limits`)."""

    passive_s: float = 0.5  #: damping before the soft start (the pose is measured at its end)
    stand_s: float = 2.5  #: soft start duration (the issue asks >= 2 s; unitree_rl_gym: 2 s)
    gain_ramp_s: float = 1.5  #: kp ramps from 0 to the policy's kp over this part of it
    ready_settle_s: float = 0.5  #: --auto-start waits this long in `ready`
    #: After the dance the policy keeps balancing while its targets fade over `done_fade_s`
    #: to feet down (a whole-body policy also crouches: `DanceController.rest_row`), and
    #: stands so for `done_stand_s` in all (without a dance: the nominal pose is held). A PD
    #: move to the nominal joints instead tilted the trunk 0.14-0.33 rad and tipped it over in
    #: 1 of 24 runs under +50 ms lag: the feet stay where the dance left them, not where the
    #: nominal joints would put them. A 0.4 s fade still tilted it 0.05-0.26 rad right after
    #: the switch under +50 ms lag (29 runs and a CI run); over 0.8 s, 0.07-0.18 rad (12 runs).
    done_fade_s: float = 0.8
    done_stand_s: float = 2.0
    done_damp_s: float = 1.0  #: then damping before the runner exits
    damp_hold_s: float = 1.0  #: damping commands sent after a fault before exiting
    stale_ticks: int = 3  #: this many ticks in a row without a new state: damp
    inference_budget_s: float = 0.010  #: half a tick: past it the last command is held
    #: A run does not start below this state of charge: the robot's own low-battery
    #: behaviour must not take over in the middle of a dance.
    min_battery_pct: float = 25.0


@dataclass
class Event:
    clock_s: float  #: runner clock (time.monotonic) of the transition
    frm: DeployState
    to: DeployState
    reason: str

    def to_json(self, zero_s: float) -> dict:
        """With ``t_s`` relative to ``zero_s`` (dance time 0 on the runner clock)."""
        t_s = round(self.clock_s - zero_s, 4)
        return {"t_s": t_s, "from": self.frm.value, "to": self.to.value, "reason": self.reason}


@dataclass
class GuardCounts:
    """How often each per-tick guard acted (deploy.json)."""

    soft_limit: int = 0
    target_step: int = 0
    torque: int = 0
    held_inference: int = 0

    def to_json(self) -> dict:
        return dict(self.__dict__)


@dataclass
class Safety:
    """The state machine and the per-tick guards; the runner drives it, one call per tick."""

    cfg: SafetyCfg
    robot: RobotCfg
    kp: float
    kd: float
    nominal_rad: np.ndarray
    joint_range_rad: np.ndarray
    state: DeployState = DeployState.PASSIVE
    events: list[Event] = field(default_factory=list)
    counts: GuardCounts = field(default_factory=GuardCounts)

    def __post_init__(self) -> None:
        self.limits = self.robot.safety_limits
        self.limits_nm = np.asarray(self.robot.effort_limit_nm)
        self.soft = soft_joint_limits_rad(self.joint_range_rad, self.limits.soft_limit_margin_rad)
        self.entered_s = 0.0  # runner time when the current state began
        self.last_target: np.ndarray | None = None
        self._last_seq: int | None = None
        self._stale = 0
        self.stand_from: np.ndarray | None = None

    # --- transitions ----------------------------------------------------------------------
    def go(self, to: DeployState, reason: str, now_s: float) -> None:
        """Change state at ``now_s`` (runner clock)."""
        if to == self.state:
            return
        self.events.append(Event(now_s, self.state, to, reason))
        self.state = to
        self.entered_s = now_s

    def damp(self, reason: str, now_s: float) -> None:
        if self.state != DeployState.DAMP:
            self.go(DeployState.DAMP, reason, now_s)

    # --- checks on what came in ------------------------------------------------------------
    def check_reading(self, reading: Reading | None) -> str | None:
        """Why the robot must damp now (None: keep going): no state, stale or non-finite."""
        if reading is None or reading.seq == self._last_seq:
            self._stale += 1
        else:
            self._stale = 0
            self._last_seq = reading.seq
        if self._stale >= self.cfg.stale_ticks:
            return f"no new state for {self._stale} ticks"
        if reading is not None and not reading.is_finite():
            return "NaN/Inf in the robot state"
        if reading is not None and damp_pressed(reading.remote_keys):
            return "the remote's L2 + B"
        return None

    def check_battery(self, reading: Reading) -> str | None:
        """Why the run must not start (None: it may): a battery below `min_battery_pct`."""
        return battery_problem(reading.battery_pct, self.cfg.min_battery_pct)

    def check_posture(self, gravity_b: np.ndarray, trunk_height_m: float) -> str | None:
        """Toppling or collapsing: roll/pitch past the limit, or the trunk too low."""
        roll, pitch = roll_pitch_rad(gravity_b)
        lim = self.limits.max_roll_pitch_rad
        if abs(roll) > lim or abs(pitch) > lim:
            return f"roll {roll:+.2f} / pitch {pitch:+.2f} rad past {lim:g}"
        if (
            self.state in (DeployState.READY, DeployState.DANCE)
            and trunk_height_m < self.limits.min_trunk_height_m
        ):
            return f"trunk collapsing ({trunk_height_m:.3f} m above the feet)"
        return None

    # --- what goes out ---------------------------------------------------------------------
    def damping_command(self, q_meas_rad: np.ndarray) -> JointCommand:
        q = np.where(np.isfinite(q_meas_rad), q_meas_rad, 0.0)
        self.last_target = None
        return JointCommand.damping(q, self.limits.damp_kd)

    def stand_target(self, now_s: float) -> tuple[np.ndarray, float]:
        """Soft start: target and kp at ``now_s`` in `stand` (smoothstep from the measured
        pose to the nominal one; kp ramps linearly from 0)."""
        u = min(1.0, (now_s - self.entered_s) / self.cfg.stand_s)
        s = u * u * (3 - 2 * u)
        start = self.stand_from if self.stand_from is not None else self.nominal_rad
        kp = self.kp * min(1.0, (now_s - self.entered_s) / self.cfg.gain_ramp_s)
        return start + s * (self.nominal_rad - start), kp

    def guard(
        self, q_target: np.ndarray, kp: float, reading: Reading
    ) -> tuple[JointCommand, np.ndarray]:
        """Clamp a target to the soft limits, to `max_target_step_rad` from the last one, and
        so that the torque the motor boards will start from, kp (q* - q) - kd dq, stays in
        the motor limits. Returns the command and the torque estimate before clamping."""
        q, dq = reading.joint_pos_rad, reading.joint_vel_rad_s
        target = np.clip(q_target, self.soft[:, 0], self.soft[:, 1])
        self.counts.soft_limit += int(not np.array_equal(target, q_target))
        if self.last_target is not None:
            step = self.limits.max_target_step_rad
            stepped = np.clip(target, self.last_target - step, self.last_target + step)
            self.counts.target_step += int(not np.array_equal(stepped, target))
            target = stepped
        tau_est = kp * (target - q) - self.kd * dq
        tau_ok = np.clip(tau_est, -self.limits_nm, self.limits_nm)
        if kp > 0 and not np.array_equal(tau_ok, tau_est):
            self.counts.torque += 1
            target = q + (tau_ok + self.kd * dq) / kp
        self.last_target = target
        z = np.zeros(self.robot.num_joints)
        cmd = JointCommand(target, z, np.full_like(z, kp), np.full_like(z, self.kd), z.copy())
        return cmd, tau_est
