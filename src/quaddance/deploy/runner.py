"""The dance runner: a 50 Hz loop on the wall clock that reads a `Robot`, runs the policy,
and sends joint commands through the `Safety` layer; then writes deploy.json and log.npz.

The policy side (`DanceController`) builds the actor's observation with the training code's
own `ActorObservation` and the joint targets with the task's own `sim.task.joint_targets`,
so what the policy sees and commands on a robot is what it saw and commanded in training.
"""

from __future__ import annotations

import math
import os
import select
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from quaddance.deploy.robot import JointCommand, Reading, Robot, realtime_priority
from quaddance.deploy.safety import (
    STATES,
    Safety,
    SafetyCfg,
    go1_joint_range_rad,
    roll_pitch_rad,
)
from quaddance.errors import QuaddanceError
from quaddance.play.policy import OnnxPolicy
from quaddance.sim import go1
from quaddance.sim.body import BodyFeedforward
from quaddance.sim.feedforward import FrontLiftFeedforward
from quaddance.sim.kinematics import foot_pos_b
from quaddance.sim.observations import ActorObservation, Measurement
from quaddance.sim.state import yaw_from_quat
from quaddance.sim.task import joint_targets
from quaddance.targets import BODY_LIMITS_FOUR_FEET

#: Real-time priority of the runner; the simulated robot's (a separate machine's motor
#: boards, in reality) is above it.
RUNNER_RT_PRIORITY = 10

PROGRESS_S = 5.0  #: a progress line every this many dance seconds


class DanceController:
    """One robot's policy step: reading -> observation -> action -> joint targets.

    Joint targets come from the task's own `sim.task.joint_targets` (one definition of the
    law), fed with the policy JSON's nominal pose, action scale and feed-forward table.
    """

    def __init__(
        self, policy: OnnxPolicy, targets_m: np.ndarray, body_targets: np.ndarray | None = None
    ) -> None:
        cfg = policy.task
        self.policy = policy
        self.cfg = cfg
        self.dev = torch.device("cpu")
        paws = torch.as_tensor(np.asarray(targets_m), dtype=torch.float32)
        if paws.ndim != 2 or paws.shape[1] != 4 or paws.shape[0] < 1:
            raise QuaddanceError(f"dance targets must be (T, 4), got {tuple(paws.shape)}")
        body = torch.zeros(paws.shape[0], 4)
        if body_targets is not None:
            body = torch.as_tensor(np.asarray(body_targets), dtype=torch.float32)
            if body.shape != paws.shape:
                raise QuaddanceError(
                    f"body targets must be (T, 4) like the paw targets {tuple(paws.shape)}, "
                    f"got {tuple(body.shape)}"
                )
        self.rows = torch.cat([paws, body], dim=1)  # (T, 8): paw targets, then body targets
        self.actor_obs = ActorObservation(cfg, 1, self.dev)
        spec = policy.spec  # the policy's JSON contract
        self.nominal_joint_pos = torch.tensor(spec.nominal_joint_pos_rad, dtype=torch.float32)
        self.action_scale = torch.tensor(spec.action_scale, dtype=torch.float32)
        ff = spec.front_feedforward
        self.feedforward = (
            FrontLiftFeedforward(cfg.scene, self.dev, np.asarray(ff.thigh_calf_offsets_rad))
            if cfg.front_feedforward and ff is not None
            else None
        )
        self.body_feedforward = BodyFeedforward(cfg.scene, self.dev) if cfg.whole_body else None
        self.step = 0  # dance step (policy ticks since dance time 0)
        self.heading_zero_rad = 0.0  # IMU yaw at dance time 0 (`reset`)
        self._fade: tuple[torch.Tensor, int, int] | None = None
        #: What `fade_out` ends at: feet down; a whole-body policy also crouches (the lowest
        #: trunk height it dances), so damping after the dance lets it down from lower.
        self.rest_row = torch.zeros(1, self.rows.shape[1])  # same columns as `rows`
        if cfg.whole_body:
            self.rest_row[0, paws.shape[1]] = BODY_LIMITS_FOUR_FEET.height_offset_m[0]
        self.last_action = torch.zeros(1, go1.NUM_JOINTS)
        self._ids = torch.zeros(1, dtype=torch.long)

    @property
    def n_steps(self) -> int:
        return int(self.rows.shape[0])

    def extend(self, targets_m: np.ndarray, body_targets: np.ndarray) -> None:
        """Append (K, 4) paw and (K, 4) body targets: a dance made while it is danced."""
        more = torch.cat(
            [
                torch.as_tensor(np.asarray(targets_m), dtype=torch.float32).reshape(-1, 4),
                torch.as_tensor(np.asarray(body_targets), dtype=torch.float32).reshape(-1, 4),
            ],
            dim=1,
        )
        self.rows = torch.cat([self.rows, more], dim=0)

    def _row(self, ahead_steps: int) -> torch.Tensor:
        k = self.step + ahead_steps
        if self._fade is not None:
            row, first, n = self._fade
            u = min(1.0, (k - first) / n)
            return row + u * (self.rest_row - row)
        return self.rows[min(k, self.n_steps - 1)][None]

    def targets_at(self, ahead_steps: int) -> torch.Tensor:
        """(1, 4) paw targets ``ahead_steps`` ticks from the current step (held at the end;
        faded to `rest_row` after `fade_out`)."""
        return self._row(ahead_steps)[:, :4]

    def body_targets_at(self, ahead_steps: int) -> torch.Tensor:
        """(1, 4) body targets, as `targets_at`."""
        return self._row(ahead_steps)[:, 4:]

    def fade_out(self, steps: int) -> None:
        """From the current step on, targets go linearly from their value now to `rest_row`
        over ``steps`` ticks, and stay there."""
        self._fade = (self._row(0).clone(), self.step, max(1, steps))

    def measurement(self, reading: Reading) -> Measurement:
        """The reading as the actor's `Measurement`, its heading relative to the dance's start."""
        t = lambda a: torch.as_tensor(np.asarray(a), dtype=torch.float32)[None]  # noqa: E731
        return Measurement.from_imu(
            t(reading.quat_wxyz),
            t(reading.gyro_rad_s),
            t(reading.joint_pos_rad),
            t(reading.joint_vel_rad_s),
            self.heading_zero_rad,
        )

    def reset(self, reading: Reading) -> None:
        """Dance time 0: no previous action, the history filled with the current frame, the
        heading measured from here."""
        self.step = 0
        self._fade = None
        self.last_action = torch.zeros(1, go1.NUM_JOINTS)
        quat = torch.as_tensor(np.asarray(reading.quat_wxyz), dtype=torch.float32)[None]
        self.heading_zero_rad = float(yaw_from_quat(quat)[0])
        prop = self.actor_obs.proprio(self.measurement(reading), self.last_action)
        self.actor_obs.reset(self._ids, prop)

    def observe(self, reading: Reading, step: int) -> tuple[torch.Tensor, torch.Tensor]:
        """(proprio frame, observation (1, D)) at dance step ``step``."""
        self.step = step
        prop = self.actor_obs.proprio(self.measurement(reading), self.last_action)
        return prop, self.actor_obs.build(prop, self.targets_at, self.body_targets_at)

    def commit(self, prop: torch.Tensor, action: torch.Tensor) -> None:
        """The frame just seen joins the history; ``action`` is what the robot now does."""
        self.actor_obs.push(prop)
        self.last_action = action

    def joint_targets(self, action: torch.Tensor) -> torch.Tensor:
        return joint_targets(action, self)


@dataclass
class DeployOptions:
    """What `quaddance deploy` was asked to do, besides the robot and the dance."""

    seconds: float | None = None  #: dance at most this long
    auto_start: bool = False  #: start the dance without waiting for Enter
    inject: list[tuple[str, float]] = field(default_factory=list)  #: (fault, dance time s)
    song: Path | None = None  #: played where an audio device exists
    song_start_s: float = 0.0  #: ... from this far into it
    safety: SafetyCfg = field(default_factory=SafetyCfg)


@dataclass
class DeployResult:
    summary: dict
    log: dict[str, np.ndarray]


class _Stop:
    """SIGINT / SIGTERM -> a flag the loop reads (the loop then damps and writes the log)."""

    def __init__(self) -> None:
        self.signal: int | None = None
        self._old: dict[int, object] = {}

    def __enter__(self) -> _Stop:
        def handler(signum: int, frame: object) -> None:
            self.signal = self.signal or signum

        for s in (signal.SIGINT, signal.SIGTERM):
            self._old[s] = signal.signal(s, handler)
        return self

    def __exit__(self, *exc: object) -> None:
        for s, h in self._old.items():
            signal.signal(s, h)  # type: ignore[arg-type]


class _Audio:
    """Music from an external player where the machine has a sound device; else silence."""

    def __init__(self, song: Path | None, start_s: float = 0.0) -> None:
        self.song = song
        self.proc: subprocess.Popen | None = None
        self._cmd: list[str] | None = None
        self.status = "no song"
        if song is None:
            return
        player = None
        # afplay cannot start part-way into a song.
        players = [["ffplay", "-nodisp", "-autoexit", "-loglevel", "quiet", "-ss", f"{start_s:g}"]]
        players += [["afplay"]] if start_s == 0 else []
        if os.path.exists("/dev/snd") or sys.platform == "darwin":
            for cmd in players:
                if shutil.which(cmd[0]):
                    player = cmd
                    break
        self._cmd = None if player is None else [*player, str(song)]
        self.status = "ready" if self._cmd else "no audio device or player: dancing silently"

    def start(self) -> None:
        if self._cmd is not None:
            self.proc = subprocess.Popen(
                self._cmd,
                stdin=subprocess.DEVNULL,
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
            )
            self.status = "played"

    def stop(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()


def _drain_stdin() -> None:
    """Discard lines already typed (stops at end of input: `_enter_pressed` reports that)."""
    for _ in range(1000):
        try:
            ready, _, _ = select.select([sys.stdin], [], [], 0)
        except (ValueError, OSError):
            return
        if not ready:
            return
        if sys.stdin.readline() == "":
            return


def _enter_pressed() -> bool | None:
    """True if a line came on stdin, False if none yet, None when stdin is closed."""
    try:
        ready, _, _ = select.select([sys.stdin], [], [], 0)
    except (ValueError, OSError):
        return None
    if not ready:
        return False
    return None if sys.stdin.readline() == "" else True


@dataclass
class _Tick:
    """What one tick read, decided and sent (one row of log.npz)."""

    now: float  #: runner clock, s
    reading: Reading
    state_before: str
    t_dance: float = math.nan
    cmd: JointCommand | None = None
    tau_est: np.ndarray = field(default_factory=lambda: np.full(go1.NUM_JOINTS, np.nan))
    action: np.ndarray = field(default_factory=lambda: np.full(go1.NUM_JOINTS, np.nan))
    feet: np.ndarray = field(default_factory=lambda: np.full(4, np.nan))
    targets: np.ndarray = field(default_factory=lambda: np.full(4, np.nan))
    body_targets: np.ndarray = field(default_factory=lambda: np.full(4, np.nan))
    trunk_m: float = math.nan  #: trunk height above the lowest foot, kinematic estimate
    held: bool = False
    infer_s: float = math.nan


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
        on_tick: Callable[[_Tick], None] | None = None,
        dance_s: float | None = None,
    ) -> None:
        """``feeder(t_dance)`` runs at each dance tick before the policy (a live dance
        extends ``self.ctrl``'s targets there); ``on_tick(tick)`` after each
        command is sent (NaN before the dance); ``dance_s`` sets the dance's length instead
        of the targets' (a dance made while it is danced)."""
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
            kp=policy.spec.kp,
            kd=policy.spec.kd,
            nominal_rad=np.asarray(policy.spec.nominal_joint_pos_rad, dtype=np.float64),
            joint_range_rad=go1_joint_range_rad(),
        )
        self.geom = self.ctrl.actor_obs.geom

    # --- helpers ---------------------------------------------------------------------------
    def _posture(self, reading: Reading) -> tuple[np.ndarray, np.ndarray, float]:
        """Gravity in the trunk frame, estimated foot heights (FL FR RL RR) and trunk height
        above the lowest foot's bottom, from the IMU and encoders."""
        meas = self.ctrl.measurement(reading)
        g = meas.projected_gravity_b[0].numpy().astype(np.float64)
        # Foot centres along world up, trunk frame origin at 0 (kinematics.py's estimator
        # subtracts the lowest one; the trunk height is minus it).
        z = foot_pos_b(meas.joint_pos_rad, self.geom)[0].numpy() @ (-g / np.linalg.norm(g))
        return g, z - z.min(), float(-z.min()) + go1.FOOT_RADIUS_M

    # --- the loop --------------------------------------------------------------------------
    def run(self) -> DeployResult:
        """Connect, run the states to the end (or a stop), close; the result for the files."""
        threads = torch.get_num_threads()
        torch.set_num_threads(1)  # one robot: threads only add latency
        try:
            with realtime_priority(RUNNER_RT_PRIORITY) as self.priority:
                return self._run()
        except BaseException:
            self._emergency_damp()
            raise
        finally:
            torch.set_num_threads(threads)

    def _emergency_damp(self) -> None:
        """A bug in the loop must not leave the robot holding a pose: damping, then close."""
        q = getattr(self, "_last_q", None)
        try:
            if q is not None:
                for _ in range(10):
                    self.robot.send(JointCommand.damping(q, self.opt.safety.damp_kd))
                    time.sleep(self.tick_s)
        finally:
            self.robot.close()

    def _run(self) -> DeployResult:
        self.audio = _Audio(self.opt.song, self.opt.song_start_s)
        if self.opt.song is not None:
            self.status(f"music: {self.audio.status}")
        self.status(f"connecting to the robot ({self.robot.name})")
        first = self.robot.start()
        sf, dt = self.safety, self.tick_s
        rows: dict[str, list] = {k: [] for k in _LOG_KEYS}
        self.injections = sorted(self.opt.inject, key=lambda f: f[1])
        self.injected: list[dict] = []
        self.last_cmd = sf.damping_command(first.joint_pos_rad)
        self.dance_start: float | None = None  # runner clock at dance time 0
        self.dance_end_s: float | None = None  # dance time when the dance stopped
        self.finished = False
        last_reading, last_gravity = first, np.array([0.0, 0.0, -1.0])
        overruns, last_seq = 0, -1
        t0 = time.monotonic()
        sf.entered_s = t0
        self.status("passive (damping); soft start follows")
        k = 0
        with _Stop() as self.stop:
            while not self.finished:
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
                tick = _Tick(now=now, reading=r, state_before=sf.state)
                if self.dance_start is not None:
                    tick.t_dance = now - self.dance_start

                # Checks first: whatever the state, they may end it in `damp`.
                if self.stop.signal is not None:
                    sf.damp(f"signal {signal.Signals(self.stop.signal).name}", now)
                if sf.state != "damp" and (why := sf.check_reading(reading)) is not None:
                    sf.damp(why, now)
                if r.is_finite():
                    self._last_q = r.joint_pos_rad
                if sf.state != "damp" and r.is_finite():
                    last_reading = r
                    last_gravity, tick.feet, trunk_m = self._posture(r)
                    tick.trunk_m = trunk_m
                    why = sf.check_posture(last_gravity, trunk_m)
                    if why is not None and self._posture_matters(now):
                        sf.damp(why, now)

                # Then the state's command; a state may hand over to the next in this tick.
                if sf.state == "passive":
                    self._passive(tick)
                if sf.state == "stand":
                    self._stand(tick)
                elif sf.state == "ready":
                    self._ready(tick)
                if sf.state == "dance":
                    self._dance(tick)
                if sf.state == "done":
                    self._done(tick)
                if sf.state == "damp":
                    self._damp(tick)
                cmd = tick.cmd
                if cmd is None or not cmd.is_finite():
                    sf.damp("NaN/Inf in the command", now)
                    cmd = sf.damping_command(r.joint_pos_rad)
                self.robot.send(cmd)
                self.last_cmd = cmd
                if self.on_tick is not None:
                    self.on_tick(tick)
                work_ms = (time.monotonic() - now) * 1e3
                new = reading is not None and reading.seq != last_seq
                last_seq = r.seq
                _append(rows, tick, now - t0, new, sf.state, last_gravity, cmd, work_ms)
                k += 1
        self.audio.stop()
        self.robot.close()
        if self.dance_start is not None and self.dance_end_s is None:
            self.dance_end_s = rows["t_s"][-1]
        return self._result(
            rows, self.dance_start, t0, self.dance_end_s, self.injected, overruns, self.audio
        )

    def _posture_matters(self, now: float) -> bool:
        """Roll, pitch and trunk height are checked from `stand` until `done` damps."""
        sf = self.safety
        if sf.state in ("passive", "damp"):
            return False
        return not (sf.state == "done" and now - sf.entered_s >= self.opt.safety.done_stand_s)

    # --- one method per state: each sets tick.cmd (and may change the state) ----------------
    def _passive(self, tick: _Tick) -> None:
        sf = self.safety
        tick.cmd = sf.damping_command(tick.reading.joint_pos_rad)
        if tick.now - sf.entered_s >= self.opt.safety.passive_s:
            sf.stand_from = tick.reading.joint_pos_rad.copy()  # the soft start begins here
            sf.go("stand", "soft start", tick.now)
            self.status("stand: soft start to the nominal pose")

    def _stand(self, tick: _Tick) -> None:
        sf = self.safety
        target, kp = sf.stand_target(tick.now)
        tick.cmd, tick.tau_est = sf.guard(target, kp, tick.reading)
        if tick.now - sf.entered_s >= self.opt.safety.stand_s:
            if not self.opt.auto_start:
                _drain_stdin()  # an Enter typed before the prompt must not start the dance
            sf.go("ready", "standing", tick.now)
            self.status(
                f"ready: dancing in {self.opt.safety.ready_settle_s:g} s"
                if self.opt.auto_start
                else "ready: press Enter to dance (Ctrl-C stops)"
            )

    def _ready(self, tick: _Tick) -> None:
        sf = self.safety
        tick.cmd, tick.tau_est = sf.guard(sf.nominal_rad, sf.kp, tick.reading)
        if self.opt.auto_start:
            start = tick.now - sf.entered_s >= self.opt.safety.ready_settle_s
        else:
            pressed = _enter_pressed()
            if pressed is None:
                sf.go("done", "stdin closed: nobody to press Enter", tick.now)
                return
            start = pressed
        if start:
            self.ctrl.reset(tick.reading)
            self.dance_start, tick.t_dance = tick.now, 0.0
            sf.go("dance", "start", tick.now)
            self.audio.start()  # the music's first sample is dance time 0
            self.status(f"dance: {self.dance_steps * self.tick_s:.1f} s")

    def _dance(self, tick: _Tick) -> None:
        sf, dt, t = self.safety, self.tick_s, tick.t_dance
        step = round(t / dt)  # wall-clock time, not tick count: the music does not wait
        while self.injections and self.injections[0][1] <= t + 1e-9:
            name, at_s = self.injections.pop(0)
            sent = self.robot.inject(name)
            self.injected.append({"fault": name, "at_s": at_s, "t_s": round(t, 4), "sent": sent})
            self.status(f"injected {name} at {t:.2f} s")
        if step >= self.dance_steps:
            self.dance_end_s = t
            self.ctrl.fade_out(round(self.opt.safety.done_fade_s / dt))
            sf.go("done", "dance finished", tick.now)
            self.audio.stop()
            return
        if step > 0 and step % round(PROGRESS_S / dt) == 0:
            self.status(f"dance {step * dt:.0f} / {self.dance_steps * dt:.0f} s")
        if self.feeder is not None:
            self.feeder(t)
        self._policy_step(tick, step)

    def _policy_step(self, tick: _Tick, step: int) -> None:
        """Observe, act, command: the policy's tick at dance step ``step``."""
        sf, now = self.safety, tick.now
        prop, obs = self.ctrl.observe(tick.reading, step)
        tick.targets = self.ctrl.targets_at(0)[0].numpy()
        tick.body_targets = self.ctrl.body_targets_at(0)[0].numpy()
        if not torch.isfinite(obs).all():
            sf.damp("NaN/Inf in the observation", now)
            return
        t_inf = time.perf_counter()
        act = torch.from_numpy(self.policy.act(obs.numpy()))
        tick.infer_s = time.perf_counter() - t_inf
        tick.action = act[0].numpy().astype(np.float64)
        if not torch.isfinite(act).all():
            sf.damp("NaN/Inf in the action", now)
        elif tick.infer_s > self.opt.safety.inference_budget_s:
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

    def _done(self, tick: _Tick) -> None:
        """Stand (the policy balancing on targets faded to its rest row; without a dance the
        nominal pose held), then damping."""
        sf, cfg = self.safety, self.opt.safety
        into = tick.now - sf.entered_s
        if into < cfg.done_stand_s:
            if self.dance_start is not None:
                self._policy_step(tick, round((tick.now - self.dance_start) / self.tick_s))
            else:
                tick.cmd, tick.tau_est = sf.guard(sf.nominal_rad, sf.kp, tick.reading)
        else:  # lie down under damping
            tick.cmd = sf.damping_command(tick.reading.joint_pos_rad)
            self.finished = into >= cfg.done_stand_s + cfg.done_damp_s

    def _damp(self, tick: _Tick) -> None:
        sf = self.safety
        if tick.state_before != "damp":
            self.audio.stop()
            self.status(f"DAMP: {sf.events[-1].reason}")
            if self.dance_start is not None and self.dance_end_s is None:
                self.dance_end_s = tick.t_dance
        tick.cmd = sf.damping_command(tick.reading.joint_pos_rad)
        # After a signal the user wants out: 0.2 s of damping commands suffice.
        hold_s = 0.2 if self.stop.signal is not None else self.opt.safety.damp_hold_s
        self.finished = tick.now - sf.entered_s >= hold_s

    def _result(self, rows, dance_start, t0, dance_end_s, injected, overruns, audio):
        from quaddance.play.dance import target_config_for
        from quaddance.play.metrics import feasible_mask, tracking_metrics

        log = {k: np.asarray(v) for k, v in rows.items()}
        log["state_names"] = np.asarray(STATES)
        # Dance time: 0 when the dance started (earlier events negative); runner time if the
        # dance never started.
        zero = dance_start if dance_start is not None else t0
        events = [e.to_json(zero) for e in self.safety.events]
        truth = self.robot.truth()
        dancing = log["state"] == STATES.index("dance")
        feet_source = "kinematic estimate (encoders + IMU)"
        feet = log["feet_est_m"]
        falls: int
        if truth is not None and len(truth.get("mono_s", [])):
            idx = np.searchsorted(truth["mono_s"], log["wall_s"] + t0, side="right") - 1
            idx = np.clip(idx, 0, len(truth["mono_s"]) - 1)
            log["feet_true_m"] = truth["feet_m"][idx]
            log["base_height_true_m"] = truth["base_height_m"][idx]
            log["tilt_true_rad"] = truth["tilt_rad"][idx]
            if "rpy_rad" in truth:
                log["rpy_true_rad"] = truth["rpy_rad"][idx]
            # How far the simulated robot's physics ran behind the wall clock (machine load).
            self.sim_late_ms = percentiles(truth["late_s"] * 1e3)
            feet, feet_source = log["feet_true_m"], "simulator truth"
            # Training's fall (trunk on the floor, tilt, trunk too low), except that sinking
            # to the floor under damping after a stop is the plan: only toppling counts then.
            damped = [e.clock_s for e in self.safety.events if e.to == "damp"]
            before_damp = truth["mono_s"] < (damped[0] if damped else np.inf)
            task = self.policy.task
            low = truth["trunk_contact"] | (truth["base_height_m"] < task.min_base_height_m)
            fallen = (truth["tilt_rad"] > task.max_tilt_rad) | (low & before_damp)
            # Only while it should stand: from `ready` on, and not in the damping that ends a
            # normal run (lying down then is the plan, not a fall).
            up = np.isin(log["state"], [STATES.index(s) for s in ("ready", "dance", "done")])
            start = t0 + log["wall_s"][up].min() if up.any() else np.inf
            end = np.inf
            done = [e for e in self.safety.events if e.to == "done"]
            if self.safety.state == "done" and done:
                end = done[-1].clock_s + self.opt.safety.done_stand_s
            fallen &= (truth["mono_s"] >= start) & (truth["mono_s"] < end)
            falls = int(np.count_nonzero(np.diff(fallen.astype(int), prepend=0) == 1))
        else:
            falls = sum(
                1
                for e in self.safety.events
                if e.to == "damp" and ("roll" in e.reason or "collapsing" in e.reason)
            )
        front, rear = None, None
        if dancing.sum() >= 2:
            tgt, fm = log["targets_m"][dancing], feet[dancing]
            feasible_max = target_config_for(self.policy, "feasible").max_height_m
            front = tracking_metrics(tgt, fm, feasible_mask(tgt, feasible_max))
            rear = float(np.clip(fm[:, 2:], 0.0, None).mean())
        work = log["tick_ms"]
        period = np.diff(log["wall_s"]) * 1e3
        summary = {
            "robot": self.robot.name,
            "policy": str(self.policy.onnx_path),
            "duration_s": round(float(dance_end_s), 3) if dance_end_s is not None else 0.0,
            "falls": falls,
            "final_state": self.safety.state,
            "events": events,
            "front": front,
            "rear_lift_mean_m": rear,
            "tick_ms": percentiles(work),
            "period_ms": percentiles(period),
            "feet_source": feet_source,
            "guards": self.safety.counts.to_json(),
            "overrun_ticks": overruns,
            "injected": injected,
            "audio": audio.status,
            "priority": self.priority,
        }
        info = self.robot.info()
        if self.robot.name == "sim":
            summary["sim"] = {**info, "late_ms": getattr(self, "sim_late_ms", None)}
        elif info:
            summary[self.robot.name] = info
        return DeployResult(summary=summary, log=log)


_LOG_KEYS = (
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


def _append(
    rows,
    tick: _Tick,
    wall_s: float,
    new: bool,
    state: str,
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
        "state": STATES.index(state),
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
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    if not v.size:
        return {"p50": None, "p99": None, "max": None}
    return {
        "p50": round(float(np.percentile(v, 50)), 3),
        "p99": round(float(np.percentile(v, 99)), 3),
        "max": round(float(v.max()), 3),
    }


def rollout_from_log(log: dict[str, np.ndarray], policy_hz: float):
    """The dancing ticks of a run as a `play.rollout.RolloutResult` (time = dance time), so
    `deploy` and `live` write the rollout.npz that `dance` writes. The robot's pose is the
    simulator's truth where there is one, else the robot's own estimate (kinematics + IMU;
    yaw unknown: 0)."""
    from quaddance.play.rollout import RolloutResult

    dancing = log["state"] == STATES.index("dance")
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
            standing_m = policy.task.rewards.base_height_target_m
            result.summary.update(whole_body_metrics(rollout, beats, standing_m))
    write_json(paths["summary"], result.summary)
    return paths
