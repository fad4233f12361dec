"""`quaddance deploy --dry-run`: read the robot, log and check its state, send no torque.

The first thing to do with a robot on a new set-up: the link works (states arrive at the
robot's rate), the joints read inside their ranges (encoders and the joint map are right),
the IMU says upright (it is mounted and read the right way round), the battery is charged
enough for a run. Nothing is sent: `Robot.send` is never called, so the robot stays as the
vendor's firmware holds it (a Go1's SDK link still exchanges its idle, zero-gain command).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from quaddance.deploy.robot import Reading, Robot
from quaddance.deploy.safety import SafetyCfg, battery_problem, joint_range_rad
from quaddance.robots import RobotCfg


@dataclass(frozen=True)
class DryRunCfg:
    seconds: float = 3.0  #: how long the state is read
    read_hz: float = 50.0  #: the runner's rate
    #: Encoders may read a little outside the model's range: calibration, and a leg
    #: resting on its stop under the robot's weight (0.06-0.08 rad in the simulators).
    joint_margin_rad: float = 0.1
    max_tilt_rad: float = 0.35  #: trunk z axis from vertical: upright, standing or lying
    #: Reads that must find a new state (robots send at 500 Hz, far above the read rate).
    min_fresh_fraction: float = 0.9


def tilt_rad(quat_wxyz: np.ndarray) -> float:
    """Angle between the trunk's z axis and the vertical, from the IMU quaternion."""
    _, x, y, _ = np.asarray(quat_wxyz, dtype=np.float64) / np.linalg.norm(quat_wxyz)
    return float(np.arccos(np.clip(1 - 2 * (x * x + y * y), -1.0, 1.0)))


def check_readings(
    readings: list[Reading], reads: int, robot: RobotCfg, cfg: DryRunCfg = DryRunCfg()
) -> dict[str, dict]:
    """Each check's verdict (``ok``) and what it saw (``detail``), from the distinct
    ``readings`` that ``reads`` reads found."""
    checks: dict[str, dict] = {}
    fresh = len(readings) / max(reads, 1)
    checks["states"] = {
        "ok": fresh >= cfg.min_fresh_fraction,
        "detail": f"a new state at {len(readings)} of {reads} reads at {cfg.read_hz:g} Hz",
    }
    if not readings:
        return checks
    finite = all(r.is_finite() for r in readings)
    checks["finite"] = {"ok": finite, "detail": "all finite" if finite else "NaN/Inf read"}
    q = np.array([r.joint_pos_rad for r in readings])
    rng = joint_range_rad(robot)
    lo, hi = rng[:, 0] - cfg.joint_margin_rad, rng[:, 1] + cfg.joint_margin_rad
    out = ~((q >= lo) & (q <= hi)).all(axis=0)
    names = [robot.joint_names[j] for j in np.flatnonzero(out)]
    checks["joints_in_range"] = {
        "ok": not names,
        "detail": "all 12 inside their ranges"
        if not names
        else "out of range: " + ", ".join(names),
    }
    tilt_deg = np.degrees(max(tilt_rad(r.quat_wxyz) for r in readings))
    limit_deg = np.degrees(cfg.max_tilt_rad)
    checks["imu_upright"] = {
        "ok": bool(tilt_deg <= limit_deg),
        "detail": f"tilt up to {tilt_deg:.1f} deg (limit {limit_deg:.0f})",
    }
    battery = readings[-1].battery_pct
    min_pct = SafetyCfg().min_battery_pct
    checks["battery"] = {
        "ok": battery_problem(battery, min_pct) is None,
        "detail": f"{battery:.0f} % (a run needs {min_pct:g} %)"
        if np.isfinite(battery)
        else "not reported",
    }
    return checks


def dry_run(
    robot: Robot,
    robot_cfg: RobotCfg,
    cfg: DryRunCfg = DryRunCfg(),
    status: Callable[[str], None] = lambda m: None,
) -> tuple[dict, dict[str, np.ndarray]]:
    """Read ``robot`` for ``cfg.seconds`` without sending; deploy.json's summary and
    log.npz's arrays."""
    status(f"dry run: reading the robot ({robot.name}) for {cfg.seconds:g} s, sending nothing")
    readings = [robot.start()]
    t0 = time.monotonic()
    k = 1
    try:
        while (now := time.monotonic()) - t0 < cfg.seconds:
            pause = t0 + k / cfg.read_hz - now
            if pause > 0:
                time.sleep(pause)
            reading = robot.read()
            if reading is not None and reading.seq != readings[-1].seq:
                readings.append(reading)
            k += 1
    finally:
        robot.close()
    checks = check_readings(readings, k, robot_cfg, cfg)
    summary = {
        "robot": robot.name,
        "dry_run": True,
        "ok": all(c["ok"] for c in checks.values()),
        "checks": checks,
        robot.name: robot.info(),
    }
    log = {
        "seq": np.array([r.seq for r in readings]),
        "stamp_s": np.array([r.stamp_s for r in readings]),
        "quat_wxyz": np.array([r.quat_wxyz for r in readings]),
        "gyro_rad_s": np.array([r.gyro_rad_s for r in readings]),
        "q": np.array([r.joint_pos_rad for r in readings]),
        "dq": np.array([r.joint_vel_rad_s for r in readings]),
        "foot_force": np.array([r.foot_force_n for r in readings]),
        "battery_pct": np.array([r.battery_pct for r in readings]),
        "remote_keys": np.array([r.remote_keys for r in readings]),
    }
    return summary, log
