"""The safety layer's per-tick guards, and the runner holding its last command when the
policy answers too late (an in-process stand-in robot: no simulator, no network)."""

from __future__ import annotations

import time

import numpy as np
import pytest

from quaddance.deploy.robot import Reading, Robot
from quaddance.deploy.runner import DeployOptions, Runner
from quaddance.deploy.safety import Safety, SafetyCfg, joint_range_rad
from quaddance.deploy.states import DeployState
from quaddance.play.policy import OnnxPolicy, shipped_policy_path
from quaddance.robots import GO1

NOMINAL = np.asarray(GO1.nominal_joint_pos_rad)


def reading(seq: int, q=NOMINAL, dq=None, quat=(1.0, 0.0, 0.0, 0.0)) -> Reading:
    return Reading(
        seq=seq,
        stamp_s=seq * 0.002,
        quat_wxyz=np.asarray(quat, dtype=float),
        gyro_rad_s=np.zeros(3),
        joint_pos_rad=np.asarray(q, dtype=float),
        joint_vel_rad_s=np.zeros(12) if dq is None else np.asarray(dq, dtype=float),
    )


def safety(**cfg) -> Safety:
    return Safety(
        SafetyCfg(**cfg),
        robot=GO1,
        kp=20.0,
        kd=0.5,
        nominal_rad=NOMINAL,
        joint_range_rad=joint_range_rad(GO1),
    )


def test_guard_keeps_targets_in_range_step_and_torque_limits():
    sf = safety()
    r = reading(1, dq=np.full(12, 3.0))
    # Far targets: the torque the boards would start from must land on the motor limits.
    cmd, tau_est = sf.guard(NOMINAL + 2.0, 20.0, r)
    limits = np.asarray(GO1.effort_limit_nm)
    assert (np.abs(tau_est) > limits).any()
    tau = cmd.kp * (cmd.q_rad - r.joint_pos_rad) - cmd.kd * r.joint_vel_rad_s
    assert (np.abs(tau) <= limits + 1e-9).all() and sf.counts.torque == 1
    lo, hi = joint_range_rad(GO1).T
    assert (cmd.q_rad >= lo).all() and (cmd.q_rad <= hi).all()
    # The next target may move at most max_target_step_rad from the one sent.
    first = cmd.q_rad.copy()
    cmd2, _ = sf.guard(NOMINAL - 1.0, 20.0, reading(2, q=first))
    assert np.abs(cmd2.q_rad - first).max() <= sf.limits.max_target_step_rad + 1e-12
    assert sf.counts.target_step == 1
    # Beyond the joint range: clamped inside it by the margin.
    cmd3, _ = safety().guard(np.full(12, -5.0), 0.0, reading(3))
    np.testing.assert_allclose(cmd3.q_rad, lo + GO1.safety_limits.soft_limit_margin_rad)


def test_stale_nan_and_tilt_checks():
    sf = safety()
    assert sf.check_reading(reading(1)) is None
    assert sf.check_reading(reading(1)) is None  # 1 tick without a new state
    assert sf.check_reading(reading(1)) is None  # 2
    assert "no new state" in sf.check_reading(reading(1))  # 3 ticks: damp
    sf = safety()
    bad = reading(1)
    bad.joint_vel_rad_s[4] = np.inf
    assert "NaN/Inf" in sf.check_reading(bad)
    # Roll of 0.9 rad about x (past 0.8), from the IMU quaternion.
    quat = (np.cos(0.45), np.sin(0.45), 0.0, 0.0)
    import torch

    from quaddance.sim.observations import Measurement

    r = reading(2, quat=quat)
    t = lambda a: torch.as_tensor(np.asarray(a), dtype=torch.float32)[None]  # noqa: E731
    meas = Measurement.from_imu(
        t(r.quat_wxyz), t(r.gyro_rad_s), t(r.joint_pos_rad), t(r.joint_vel_rad_s)
    )
    g = meas.projected_gravity_b[0].numpy()
    assert "roll +0.90" in safety().check_posture(g, 0.27)
    assert safety().check_posture(np.array([0.0, 0.0, -1.0]), 0.27) is None


class StandingRobot(Robot):
    """Reads a robot standing still in the nominal pose; records what it is sent."""

    name = "stand-in"

    def __init__(self) -> None:
        self.seq = 0
        self.sent = []

    def start(self, timeout_s: float = 30.0) -> Reading:
        return self.read()

    def read(self) -> Reading:
        self.seq += 1
        return reading(self.seq)

    def send(self, cmd) -> None:
        self.sent.append(cmd)

    def close(self) -> None:
        pass


class SlowEveryFifth:
    """The shipped policy, but every fifth answer comes after the inference budget."""

    def __init__(self, policy: OnnxPolicy, late_s: float) -> None:
        self._policy, self.late_s, self.calls = policy, late_s, 0

    def __getattr__(self, name):
        return getattr(self._policy, name)

    def act(self, obs):
        self.calls += 1
        out = self._policy.act(obs)
        if self.calls % 5 == 0:
            time.sleep(self.late_s)
        return out


def test_late_inference_holds_the_last_command():
    from quaddance.pipeline import target_bank

    policy = OnnxPolicy.load(shipped_policy_path())
    cfg = SafetyCfg(
        passive_s=0.1,
        stand_s=2.0,
        gain_ramp_s=1.0,
        ready_settle_s=0.1,
        done_stand_s=0.2,
        done_damp_s=0.1,
    )
    slow = SlowEveryFifth(policy, late_s=cfg.inference_budget_s + 0.004)
    targets = target_bank(1, 2.0, seed=1)[0]
    robot = StandingRobot()
    runner = Runner(robot, slow, targets, DeployOptions(seconds=1.0, auto_start=True, safety=cfg))
    result = runner.run()
    log, summary = result.log, result.summary
    assert summary["final_state"] == "done"
    held = log["held"].astype(bool)
    assert held.sum() == summary["guards"]["held_inference"] == slow.calls // 5
    idx = np.flatnonzero(held)
    policy_states = [DeployState.DANCE.code, DeployState.DONE.code]  # done: the settle phase
    assert idx.size >= 5 and np.isin(log["state"][idx], policy_states).all()
    # A held tick sends exactly the previous tick's targets; the others move on.
    np.testing.assert_array_equal(log["q_target"][idx], log["q_target"][idx - 1])
    moving = np.flatnonzero((log["state"] == DeployState.DANCE.code) & ~held)[1:]
    assert (np.abs(log["q_target"][moving] - log["q_target"][moving - 1]).max(1) > 0).mean() > 0.9


def test_done_keeps_the_policy_balancing_at_its_rest_targets_then_damps():
    """After the dance the policy itself stands the robot (feet down; a whole-body policy
    crouches) for `done_stand_s`, then damping: no joint-space move to a fixed pose, which
    drags the planted feet and tilted the trunk."""
    from quaddance.pipeline import target_bank

    policy = OnnxPolicy.load(shipped_policy_path())
    cfg = SafetyCfg(
        passive_s=0.1, stand_s=2.0, gain_ramp_s=1.0, ready_settle_s=0.1, done_stand_s=0.8
    )
    targets = target_bank(1, 2.0, seed=1)[0]
    runner = Runner(
        StandingRobot(), policy, targets, DeployOptions(seconds=1.0, auto_start=True, safety=cfg)
    )
    log = runner.run().log
    done = np.flatnonzero(log["state"] == DeployState.DONE.code)
    standing, damping = done[log["kp"][done] > 0], done[log["kp"][done] == 0]
    dt = 1.0 / policy.task.policy_hz
    assert standing.max() < damping.min()
    # Durations on the runner's clock (ticks a stalled machine skipped do not count); a late
    # tick moves a switch by up to a tick.
    wall = log["wall_s"]
    assert wall[damping.min()] - wall[standing.min()] == pytest.approx(cfg.done_stand_s, abs=2 * dt)
    assert wall[damping.max()] - wall[damping.min()] == pytest.approx(cfg.done_damp_s, abs=2 * dt)
    assert np.isfinite(log["action"][standing]).all()  # the policy, every tick
    fade = round(cfg.done_fade_s / dt)
    rest = standing[fade + 1 :]
    np.testing.assert_array_equal(log["targets_m"][rest], 0.0)
    assert policy.task.whole_body  # the shipped policy: it crouches to its lowest trunk
    crouch = GO1.body_four_feet.height_offset_m[0]
    np.testing.assert_allclose(log["body_targets"][rest][:, 0], crouch, atol=1e-6)
    np.testing.assert_array_equal(log["body_targets"][rest][:, 1:], 0.0)


@pytest.mark.parametrize("bad", ["joint", "inject"])
def test_deploy_job_refuses_bad_settings(tmp_path, bad):
    from quaddance.deploy.job import DeployJob, parse_inject, run_deploy
    from quaddance.errors import QuaddanceError

    with pytest.raises(QuaddanceError):
        if bad == "joint":
            run_deploy(DeployJob(out_dir=tmp_path, demo=True, dance=tmp_path / "x.npz"))
        else:
            parse_inject(["push@-1"])


def test_sigterm_damps_and_ends_the_run():
    import os
    import signal

    from quaddance.pipeline import target_bank

    policy = OnnxPolicy.load(shipped_policy_path())
    cfg = SafetyCfg(passive_s=0.1, stand_s=2.0, gain_ramp_s=1.0, ready_settle_s=0.1)
    sent: list[float] = []

    def sigterm_1s_into_the_dance(tick) -> None:
        # Timed by the dance's own clock, not the wall's: the runner's set-up time varies.
        if tick.t_dance >= 1.0 and not sent:
            sent.append(tick.t_dance)
            os.kill(os.getpid(), signal.SIGTERM)

    runner = Runner(
        StandingRobot(),
        policy,
        target_bank(1, 10.0, seed=2)[0],
        DeployOptions(auto_start=True, safety=cfg),
        on_tick=sigterm_1s_into_the_dance,
    )
    before = signal.getsignal(signal.SIGTERM)
    result = runner.run()
    summary, log = result.summary, result.log
    assert len(sent) == 1
    assert summary["final_state"] == "damp"
    assert summary["events"][-1]["reason"] == "signal SIGTERM"
    assert 0.5 < summary["duration_s"] < 2.0
    damping = log["state"] == DeployState.DAMP.code
    assert damping[-1] and (log["kp"][damping] == 0).all()
    assert signal.getsignal(signal.SIGTERM) is before  # its handler only while it ran
