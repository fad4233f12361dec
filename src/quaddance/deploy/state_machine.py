"""What each state of a run commands in a tick, and when it hands over to the next
(`DanceStates`); the states are `DeployState`, the transitions `Safety.go` / `Safety.damp`."""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np
import torch

from quaddance.deploy.audio_player import AudioPlayer
from quaddance.deploy.console import StopSignals, drain_stdin, enter_pressed
from quaddance.deploy.controller import DanceController
from quaddance.deploy.log import Tick
from quaddance.deploy.robot import JointCommand, Robot
from quaddance.deploy.safety import Safety
from quaddance.deploy.states import DeployState
from quaddance.layout import BODY, PAWS
from quaddance.play.policy import OnnxPolicy

PROGRESS_S = 5.0  #: a progress line every this many dance seconds


class DanceStates:
    """The run's progress through the states: `command` sets a tick's command from the state
    it is in, and may hand over to the next state in the same tick."""

    def __init__(
        self,
        safety: Safety,
        ctrl: DanceController,
        policy: OnnxPolicy,
        robot: Robot,
        audio: AudioPlayer,
        stop: StopSignals,
        *,
        auto_start: bool,
        inject: list[tuple[str, float]],
        dance_steps: int,
        tick_s: float,
        status: Callable[[str], None],
        feeder: Callable[[float], None] | None,
        last_cmd: JointCommand,
    ) -> None:
        """``feeder(t_dance)`` runs at each dance tick before the policy; ``last_cmd`` is
        the command the robot holds now (the runner updates it after each send)."""
        self.safety, self.ctrl, self.policy, self.robot = safety, ctrl, policy, robot
        self.audio, self.stop, self.status, self.feeder = audio, stop, status, feeder
        self.auto_start, self.dance_steps, self.tick_s = auto_start, dance_steps, tick_s
        self.injections = sorted(inject, key=lambda f: f[1])
        self.injected: list[dict] = []
        self.last_cmd = last_cmd
        self.dance_start: float | None = None  # runner clock at dance time 0
        self.dance_end_s: float | None = None  # dance time when the dance stopped
        self.finished = False

    def command(self, tick: Tick) -> None:
        """The state's command for this tick; a state may hand over to the next in it."""
        sf = self.safety
        if sf.state == DeployState.PASSIVE:
            self._passive(tick)
        if sf.state == DeployState.STAND:
            self._stand(tick)
        elif sf.state == DeployState.READY:
            self._ready(tick)
        if sf.state == DeployState.DANCE:
            self._dance(tick)
        if sf.state == DeployState.DONE:
            self._done(tick)
        if sf.state == DeployState.DAMP:
            self._damp(tick)

    def posture_matters(self, now: float) -> bool:
        """Roll, pitch and trunk height are checked from `stand` until `done` damps."""
        sf = self.safety
        if sf.state in (DeployState.PASSIVE, DeployState.DAMP):
            return False
        return not (sf.state == DeployState.DONE and now - sf.entered_s >= sf.cfg.done_stand_s)

    # --- one method per state: each sets tick.cmd (and may change the state) ----------------
    def _passive(self, tick: Tick) -> None:
        sf = self.safety
        tick.cmd = sf.damping_command(tick.reading.joint_pos_rad)
        if tick.now - sf.entered_s >= sf.cfg.passive_s:
            sf.stand_from = tick.reading.joint_pos_rad.copy()  # the soft start begins here
            sf.go(DeployState.STAND, "soft start", tick.now)
            self.status("stand: soft start to the nominal pose")

    def _stand(self, tick: Tick) -> None:
        sf = self.safety
        target, kp = sf.stand_target(tick.now)
        tick.cmd, tick.tau_est = sf.guard(target, kp, tick.reading)
        if tick.now - sf.entered_s >= sf.cfg.stand_s:
            if not self.auto_start:
                drain_stdin()  # an Enter typed before the prompt must not start the dance
            sf.go(DeployState.READY, "standing", tick.now)
            self.status(
                f"ready: dancing in {sf.cfg.ready_settle_s:g} s"
                if self.auto_start
                else "ready: press Enter to dance (Ctrl-C stops)"
            )

    def _ready(self, tick: Tick) -> None:
        sf = self.safety
        tick.cmd, tick.tau_est = sf.guard(sf.nominal_rad, sf.kp, tick.reading)
        if self.auto_start:
            start = tick.now - sf.entered_s >= sf.cfg.ready_settle_s
        else:
            pressed = enter_pressed()
            if pressed is None:
                sf.go(DeployState.DONE, "stdin closed: nobody to press Enter", tick.now)
                return
            start = pressed
        if start:
            self.ctrl.reset(tick.reading)
            self.dance_start, tick.t_dance = tick.now, 0.0
            sf.go(DeployState.DANCE, "start", tick.now)
            self.audio.start()  # the music's first sample is dance time 0
            self.status(f"dance: {self.dance_steps * self.tick_s:.1f} s")

    def _dance(self, tick: Tick) -> None:
        sf, dt, t = self.safety, self.tick_s, tick.t_dance
        step = round(t / dt)  # wall-clock time, not tick count: the music does not wait
        while self.injections and self.injections[0][1] <= t + 1e-9:
            name, at_s = self.injections.pop(0)
            sent = self.robot.inject(name)
            self.injected.append({"fault": name, "at_s": at_s, "t_s": round(t, 4), "sent": sent})
            self.status(f"injected {name} at {t:.2f} s")
        if step >= self.dance_steps:
            self.dance_end_s = t
            self.ctrl.fade_out(round(sf.cfg.done_fade_s / dt))
            sf.go(DeployState.DONE, "dance finished", tick.now)
            self.audio.stop()
            return
        if step > 0 and step % round(PROGRESS_S / dt) == 0:
            self.status(f"dance {step * dt:.0f} / {self.dance_steps * dt:.0f} s")
        if self.feeder is not None:
            self.feeder(t)
        self._policy_step(tick, step)

    def _policy_step(self, tick: Tick, step: int) -> None:
        """Observe, act, command: the policy's tick at dance step ``step``."""
        sf, now = self.safety, tick.now
        prop, obs = self.ctrl.observe(tick.reading, step)
        row = self.ctrl.target_row(0)[0].numpy()
        tick.targets, tick.body_targets = row[PAWS], row[BODY]
        # Checked in numpy: a torch op costs several times a numpy one on these few numbers.
        obs_np = obs.numpy()
        if not np.isfinite(obs_np).all():
            sf.damp("NaN/Inf in the observation", now)
            return
        t_inf = time.perf_counter()
        act_np = self.policy.act(obs_np)
        tick.infer_s = time.perf_counter() - t_inf
        act = torch.from_numpy(act_np)
        tick.action = act_np[0].astype(np.float64)
        if not np.isfinite(act_np).all():
            sf.damp("NaN/Inf in the action", now)
        elif tick.infer_s > sf.cfg.inference_budget_s:
            # Too late to answer this state: the last command stays, and so does the
            # action the policy will see as its last.
            tick.held = True
            sf.counts.held_inference += 1
            self.ctrl.commit(prop, self.ctrl.last_action)
            tick.cmd = self.last_cmd
        else:
            self.ctrl.commit(prop, act.clamp(-10.0, 10.0))  # the task's action clamp
            target = self.ctrl.joint_targets(self.ctrl.last_action)[0].numpy()
            tick.cmd, tick.tau_est = sf.guard(target.astype(np.float64), sf.kp, tick.reading)

    def _done(self, tick: Tick) -> None:
        """Stand (the policy balancing on targets faded to its rest row; without a dance the
        nominal pose held), then damping."""
        sf = self.safety
        cfg = sf.cfg
        into = tick.now - sf.entered_s
        if into < cfg.done_stand_s:
            if self.dance_start is not None:
                self._policy_step(tick, round((tick.now - self.dance_start) / self.tick_s))
            else:
                tick.cmd, tick.tau_est = sf.guard(sf.nominal_rad, sf.kp, tick.reading)
        else:  # lie down under damping
            tick.cmd = sf.damping_command(tick.reading.joint_pos_rad)
            self.finished = into >= cfg.done_stand_s + cfg.done_damp_s

    def _damp(self, tick: Tick) -> None:
        sf = self.safety
        if tick.state_before != DeployState.DAMP:
            self.audio.stop()
            self.status(f"DAMP: {sf.events[-1].reason}")
            if self.dance_start is not None and self.dance_end_s is None:
                self.dance_end_s = tick.t_dance
        tick.cmd = sf.damping_command(tick.reading.joint_pos_rad)
        # After a signal the user wants out: 0.2 s of damping commands suffice.
        hold_s = 0.2 if self.stop.signal is not None else sf.cfg.damp_hold_s
        self.finished = tick.now - sf.entered_s >= hold_s
