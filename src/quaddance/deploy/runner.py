"""The dance runner: a 50 Hz loop on the wall clock that reads a `Robot`, checks what came
in, lets the current state command (`DanceStates`: the policy through `DanceController`
while dancing) and sends the command through the `Safety` layer; then the run's summary
and log (`deploy.log`).
"""

from __future__ import annotations

import gc
import signal
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from quaddance.deploy.audio_player import AudioPlayer
from quaddance.deploy.console import StopSignals
from quaddance.deploy.controller import DanceController
from quaddance.deploy.log import LOG_KEYS, DeployResult, Tick, append_row, summarize
from quaddance.deploy.robot import JointCommand, Reading, Robot, realtime_priority
from quaddance.deploy.safety import Safety, SafetyCfg, joint_range_rad
from quaddance.deploy.state_machine import DanceStates
from quaddance.deploy.states import DeployState
from quaddance.errors import QuaddanceError
from quaddance.play.policy import OnnxPolicy

#: Real-time priority of the runner; the simulated robot's (a separate machine's motor
#: boards, in reality) is above it.
RUNNER_RT_PRIORITY = 10


@dataclass
class DeployOptions:
    """What `quaddance deploy` was asked to do, besides the robot and the dance."""

    seconds: float | None = None  #: dance at most this long
    auto_start: bool = False  #: start the dance without waiting for Enter
    inject: list[tuple[str, float]] = field(default_factory=list)  #: (fault, dance time s)
    song: Path | None = None  #: played where an audio device exists
    song_start_s: float = 0.0  #: ... from this far into it
    safety: SafetyCfg = field(default_factory=SafetyCfg)


class Runner:
    """Drives one robot through passive -> stand -> ready -> dance -> done (or damp)."""

    def __init__(
        self,
        robot: Robot,
        policy: OnnxPolicy,
        targets_m: np.ndarray,
        options: DeployOptions,
        status: Callable[[str], None] = lambda msg: None,
        body_targets: np.ndarray | None = None,
        feeder: Callable[[float], None] | None = None,
        on_tick: Callable[[Tick], None] | None = None,
        dance_s: float | None = None,
        stop: StopSignals | None = None,
    ) -> None:
        """``feeder(t_dance)`` runs at each dance tick before the policy (a live dance
        extends ``self.ctrl``'s targets there); ``on_tick(tick)`` after each
        command is sent (NaN before the dance); ``dance_s`` sets the dance's length instead
        of the targets' (a dance made while it is danced); ``stop``: the signals' flag, where
        the caller holds it past the run (`StopSignals`)."""
        self.stop = StopSignals() if stop is None else stop
        self.robot = robot
        self.feeder = feeder
        self.on_tick = on_tick
        self.policy = policy
        self.opt = options
        self.status = status
        self.ctrl = DanceController(policy, targets_m, body_targets)
        cfg = policy.task
        self.tick_s = 1.0 / cfg.policy_hz
        n = self.ctrl.n_steps if dance_s is None else max(1, round(dance_s * cfg.policy_hz))
        if options.seconds is not None:
            n = min(n, max(1, round(options.seconds * cfg.policy_hz)))
        self.dance_steps = n
        self.safety = Safety(
            options.safety,
            robot=cfg.scene.robot,
            kp=policy.spec.kp,
            kd=policy.spec.kd,
            nominal_rad=np.asarray(policy.spec.nominal_joint_pos_rad, dtype=np.float64),
            joint_range_rad=joint_range_rad(cfg.scene.robot),
        )
        self.geom = self.ctrl.actor_obs.geom

    # --- helpers ---------------------------------------------------------------------------
    def _posture(self, reading: Reading) -> tuple[np.ndarray, np.ndarray, float]:
        """Gravity in the trunk frame, estimated foot heights (FL FR RL RR) and trunk height
        above the lowest foot's bottom, from the IMU and encoders."""
        meas = self.ctrl.measurement(reading)
        g = meas.projected_gravity_b[0].numpy().astype(np.float64)
        # The observation's own foot heights along world up (made once per reading).
        z = meas.foot_up_m(self.geom)[0].numpy().astype(np.float64)
        return g, z - z.min(), float(-z.min()) + self.ctrl.cfg.scene.robot.foot_radius_m

    # --- the loop --------------------------------------------------------------------------
    def run(self) -> DeployResult:
        """Connect, run the states to the end (or a stop), close; the result for the files."""
        threads = torch.get_num_threads()
        torch.set_num_threads(1)  # one robot: threads only add latency
        # Everything made so far (torch, MuJoCo, the dance) is never scanned again: a full
        # collection of that heap inside a tick took tens of ms. Collected once here, before
        # the robot is connected.
        gc.collect()
        gc.freeze()
        try:
            # No autograd bookkeeping on the policy step's many small ops (as in playback).
            with realtime_priority(RUNNER_RT_PRIORITY) as self.priority, torch.inference_mode():
                return self._run()
        except BaseException:
            self._emergency_damp()
            raise
        finally:
            gc.unfreeze()
            torch.set_num_threads(threads)

    def _emergency_damp(self) -> None:
        """A bug in the loop must not leave the robot holding a pose: damping, then close."""
        q = getattr(self, "_last_q", None)
        try:
            if q is not None:
                for _ in range(10):
                    self.robot.send(JointCommand.damping(q, self.safety.limits.damp_kd))
                    time.sleep(self.tick_s)
        finally:
            self.robot.close()

    def _run(self) -> DeployResult:
        audio = AudioPlayer(self.opt.song, self.opt.song_start_s)
        if self.opt.song is not None:
            self.status(f"music: {audio.status}")
        self.status(f"connecting to the robot ({self.robot.name})")
        first = self.robot.start()
        sf, dt = self.safety, self.tick_s
        if (why := sf.check_battery(first)) is not None:
            self.robot.close()
            raise QuaddanceError(f"{self.robot.name}: {why}")
        rows: dict[str, list] = {k: [] for k in LOG_KEYS}
        stop = self.stop
        states = DanceStates(
            sf,
            self.ctrl,
            self.policy,
            self.robot,
            audio,
            stop,
            auto_start=self.opt.auto_start,
            inject=self.opt.inject,
            dance_steps=self.dance_steps,
            tick_s=dt,
            status=self.status,
            feeder=self.feeder,
            last_cmd=sf.damping_command(first.joint_pos_rad),
        )
        last_reading, last_gravity = first, np.array([0.0, 0.0, -1.0])
        overruns, last_seq = 0, -1
        t0 = time.monotonic()
        sf.entered_s = t0
        self.status("passive (damping); soft start follows")
        k = 0
        with stop:
            while not states.finished:
                pause = t0 + k * dt - time.monotonic()
                if pause > 0:
                    time.sleep(pause)
                elif pause < -dt:
                    # Missed whole ticks (machine stalled): skip them rather than burst.
                    overruns += int(-pause / dt)
                    k += int(-pause / dt)
                now = time.monotonic()
                reading = self.robot.read()
                r = reading if reading is not None else last_reading
                tick = Tick(now=now, reading=r, state_before=sf.state)
                if states.dance_start is not None:
                    tick.t_dance = now - states.dance_start

                # Checks first: whatever the state, they may end it in `damp`.
                if stop.signal is not None:
                    sf.damp(f"signal {signal.Signals(stop.signal).name}", now)
                if sf.state != DeployState.DAMP and (why := sf.check_reading(reading)) is not None:
                    sf.damp(why, now)
                if r.is_finite():
                    self._last_q = r.joint_pos_rad
                if sf.state != DeployState.DAMP and r.is_finite():
                    last_reading = r
                    last_gravity, tick.feet, trunk_m = self._posture(r)
                    tick.trunk_m = trunk_m
                    why = sf.check_posture(last_gravity, trunk_m)
                    if why is not None and states.posture_matters(now):
                        sf.damp(why, now)

                # Then the state's command; a state may hand over to the next in this tick.
                states.command(tick)
                cmd = tick.cmd
                if cmd is None or not cmd.is_finite():
                    sf.damp("NaN/Inf in the command", now)
                    cmd = sf.damping_command(r.joint_pos_rad)
                self.robot.send(cmd)
                states.last_cmd = cmd
                if self.on_tick is not None:
                    self.on_tick(tick)
                work_ms = (time.monotonic() - now) * 1e3
                new = reading is not None and reading.seq != last_seq
                last_seq = r.seq
                append_row(rows, tick, now - t0, new, sf.state, last_gravity, cmd, work_ms)
                k += 1
        audio.stop()
        self.robot.close()
        if states.dance_start is not None and states.dance_end_s is None:
            states.dance_end_s = rows["t_s"][-1]
        return summarize(
            rows,
            self.robot,
            self.policy,
            sf,
            t0,
            states.dance_start,
            states.dance_end_s,
            states.injected,
            overruns,
            audio.status,
            self.priority,
        )
