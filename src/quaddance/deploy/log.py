"""The record of a run: one row of log.npz per tick (`Tick`, `append_row`), the summary that
deploy.json holds (`summarize`: tracking, falls, timing, events), and the files themselves
(`write_outputs`: deploy.json, log.npz, rollout.npz)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from quaddance.deploy.robot import JointCommand, Reading, Robot
from quaddance.deploy.safety import Safety, roll_pitch_rad
from quaddance.deploy.states import STATES, DeployState
from quaddance.play.policy import OnnxPolicy


@dataclass
class Tick:
    """What one tick read, decided and sent (one row of log.npz)."""

    now: float  #: runner clock, s
    reading: Reading
    state_before: DeployState
    t_dance: float = math.nan
    cmd: JointCommand | None = None
    tau_est: np.ndarray = field(init=False)  #: NaN per joint until a command is made
    action: np.ndarray = field(init=False)
    feet: np.ndarray = field(default_factory=lambda: np.full(4, np.nan))
    targets: np.ndarray = field(default_factory=lambda: np.full(4, np.nan))
    body_targets: np.ndarray = field(default_factory=lambda: np.full(4, np.nan))
    trunk_m: float = math.nan  #: trunk height above the lowest foot, kinematic estimate
    held: bool = False
    infer_s: float = math.nan

    def __post_init__(self) -> None:
        self.tau_est = np.full(self.reading.joint_pos_rad.shape, np.nan)
        self.action = np.full(self.reading.joint_pos_rad.shape, np.nan)


@dataclass
class DeployResult:
    """A finished run: deploy.json's summary and log.npz's arrays."""

    summary: dict
    log: dict[str, np.ndarray]


LOG_KEYS = (
    "t_s",
    "wall_s",
    "seq",
    "new_state",
    "age_s",
    "state",
    "q",
    "dq",
    "q_target",
    "kp",
    "kd",
    "tau_est_nm",
    "gyro",
    "gravity",
    "foot_force",
    "feet_est_m",
    "action",
    "targets_m",
    "body_targets",
    "trunk_est_m",
    "held",
    "inference_ms",
    "tick_ms",
)


def append_row(
    rows,
    tick: Tick,
    wall_s: float,
    new: bool,
    state: DeployState,
    gravity,
    cmd: JointCommand,
    work_ms: float,
) -> None:
    r = tick.reading
    vals = {
        "t_s": tick.t_dance,
        "wall_s": wall_s,
        "seq": r.seq,
        "new_state": new,
        "age_s": r.age_s,
        "state": state.code,
        "q": r.joint_pos_rad,
        "dq": r.joint_vel_rad_s,
        "q_target": cmd.q_rad,
        "kp": cmd.kp[0],
        "kd": cmd.kd[0],
        "tau_est_nm": tick.tau_est,
        "gyro": r.gyro_rad_s,
        "gravity": gravity,
        "foot_force": r.foot_force_n,
        "feet_est_m": tick.feet,
        "action": tick.action,
        "targets_m": tick.targets,
        "body_targets": tick.body_targets,
        "trunk_est_m": tick.trunk_m,
        "held": tick.held,
        "inference_ms": tick.infer_s * 1e3,
        "tick_ms": work_ms,
    }
    for k, v in vals.items():
        rows[k].append(np.array(v, copy=True))


def percentiles(values: np.ndarray) -> dict:
    """p50, p99 and max of the finite values, rounded to 0.001 (None where there are none)."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    if not v.size:
        return {"p50": None, "p99": None, "max": None}
    return {
        "p50": round(float(np.percentile(v, 50)), 3),
        "p99": round(float(np.percentile(v, 99)), 3),
        "max": round(float(v.max()), 3),
    }


def summarize(
    rows: dict[str, list],
    robot: Robot,
    policy: OnnxPolicy,
    safety: Safety,
    t0: float,
    dance_start: float | None,
    dance_end_s: float | None,
    injected: list[dict],
    overruns: int,
    audio_status: str,
    priority: Any,
) -> DeployResult:
    """deploy.json's summary and log.npz's arrays of a run whose runner clock started at
    ``t0`` (and its dance at ``dance_start``; None: it never started)."""
    from quaddance.play.dance import feasible_max_height_m
    from quaddance.play.metrics import feasible_mask, tracking_metrics

    log = {k: np.asarray(v) for k, v in rows.items()}
    log["state_names"] = np.asarray([s.value for s in STATES])
    # Dance time: 0 when the dance started (earlier events negative); runner time if the
    # dance never started.
    zero = dance_start if dance_start is not None else t0
    events = [e.to_json(zero) for e in safety.events]
    truth = robot.truth()
    dancing = log["state"] == DeployState.DANCE.code
    feet_source = "kinematic estimate (encoders + IMU)"
    feet = log["feet_est_m"]
    falls: int
    sim_late_ms = None
    if truth is not None and len(truth.get("mono_s", [])):
        idx = np.searchsorted(truth["mono_s"], log["wall_s"] + t0, side="right") - 1
        idx = np.clip(idx, 0, len(truth["mono_s"]) - 1)
        log["feet_true_m"] = truth["feet_m"][idx]
        log["base_height_true_m"] = truth["base_height_m"][idx]
        log["tilt_true_rad"] = truth["tilt_rad"][idx]
        if "rpy_rad" in truth:
            log["rpy_true_rad"] = truth["rpy_rad"][idx]
        # How far the simulated robot's physics ran behind the wall clock (machine load).
        sim_late_ms = percentiles(truth["late_s"] * 1e3)
        feet, feet_source = log["feet_true_m"], "simulator truth"
        # Training's fall (trunk on the floor, tilt, trunk too low), except that sinking
        # to the floor under damping after a stop is the plan: only toppling counts then.
        damped = [e.clock_s for e in safety.events if e.to == DeployState.DAMP]
        before_damp = truth["mono_s"] < (damped[0] if damped else np.inf)
        task = policy.task
        low = truth["trunk_contact"] | (truth["base_height_m"] < task.min_base_height_m)
        fallen = (truth["tilt_rad"] > task.max_tilt_rad) | (low & before_damp)
        # Only while it should stand: from `ready` on, and not in the damping that ends a
        # normal run (lying down then is the plan, not a fall).
        standing = (DeployState.READY, DeployState.DANCE, DeployState.DONE)
        up = np.isin(log["state"], [s.code for s in standing])
        start = t0 + log["wall_s"][up].min() if up.any() else np.inf
        end = np.inf
        done = [e for e in safety.events if e.to == DeployState.DONE]
        if safety.state == DeployState.DONE and done:
            end = done[-1].clock_s + safety.cfg.done_stand_s
        fallen &= (truth["mono_s"] >= start) & (truth["mono_s"] < end)
        falls = int(np.count_nonzero(np.diff(fallen.astype(int), prepend=0) == 1))
    else:
        falls = sum(
            1
            for e in safety.events
            if e.to == DeployState.DAMP and ("roll" in e.reason or "collapsing" in e.reason)
        )
    front, rear = None, None
    if dancing.sum() >= 2:
        tgt, fm = log["targets_m"][dancing], feet[dancing]
        feasible_max = feasible_max_height_m(policy)
        front = tracking_metrics(tgt, fm, feasible_mask(tgt, feasible_max))
        rear = float(np.clip(fm[:, 2:], 0.0, None).mean())
    work = log["tick_ms"]
    period = np.diff(log["wall_s"]) * 1e3
    summary = {
        "robot": robot.name,
        "policy": str(policy.onnx_path),
        "duration_s": round(float(dance_end_s), 3) if dance_end_s is not None else 0.0,
        "falls": falls,
        "final_state": safety.state.value,
        "events": events,
        "front": front,
        "rear_lift_mean_m": rear,
        "tick_ms": percentiles(work),
        "period_ms": percentiles(period),
        "feet_source": feet_source,
        "guards": safety.counts.to_json(),
        "overrun_ticks": overruns,
        "injected": injected,
        "audio": audio_status,
        "priority": priority,
    }
    info = robot.info()
    if truth is not None:
        summary["sim"] = {**info, "late_ms": sim_late_ms}
    elif info:
        summary[robot.name] = info
    return DeployResult(summary=summary, log=log)


def rollout_from_log(log: dict[str, np.ndarray], policy_hz: float):
    """The dancing ticks of a run as a `play.rollout.RolloutResult` (time = dance time), so
    `deploy` and `live` write the rollout.npz that `dance` writes. The robot's pose is the
    simulator's truth where there is one, else the robot's own estimate (kinematics + IMU;
    yaw unknown: 0)."""
    from quaddance.play.rollout import RolloutResult

    dancing = log["state"] == DeployState.DANCE.code
    t = log["t_s"][dancing]
    feet = log.get("feet_true_m", log["feet_est_m"])[dancing]
    height = log.get("base_height_true_m", log["trunk_est_m"])[dancing]
    if "rpy_true_rad" in log:
        rpy = log["rpy_true_rad"][dancing]
    else:
        roll, pitch = roll_pitch_rad(log["gravity"][dancing])
        rpy = np.column_stack([roll, pitch, np.zeros_like(roll)])
    return RolloutResult(
        fps=policy_hz,
        time_s=t,
        qpos=np.zeros((t.size, 0)),
        feet_m=feet,
        targets_m=log["targets_m"][dancing],
        falls_s=[],
        sim_wall_s=float("nan"),
        base_height_m=height,
        base_rpy_rad=rpy,
        body_targets=log["body_targets"][dancing],
    )


def write_outputs(
    out_dir: Path,
    result: DeployResult,
    policy: OnnxPolicy | None = None,
    beats_s: np.ndarray | None = None,
) -> dict[str, Path]:
    """deploy.json and log.npz, and (given the policy) rollout.npz with the trunk's tracking
    and beat coverage in deploy.json; each written atomically."""
    from quaddance.fileio import atomic_path, ensure_dir, write_json

    out = ensure_dir(out_dir)
    paths = {"summary": out / "deploy.json", "log": out / "log.npz"}
    with atomic_path(paths["log"]) as tmp:
        np.savez_compressed(tmp, **result.log)
    if policy is not None and "t_s" in result.log:
        from quaddance.play.metrics import whole_body_metrics
        from quaddance.play.rollout import save_rollout

        beats = np.zeros(0) if beats_s is None else np.asarray(beats_s, dtype=float)
        rollout = rollout_from_log(result.log, policy.task.policy_hz)
        if rollout.time_s.size >= 2:
            paths["rollout"] = out / "rollout.npz"
            save_rollout(paths["rollout"], rollout, beats)
            standing_m = policy.task.base_height_target_m
            result.summary.update(whole_body_metrics(rollout, beats, standing_m))
    write_json(paths["summary"], result.summary)
    return paths
