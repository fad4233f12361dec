"""Simulated robots for `quaddance deploy`: one physics core behind a robot's protocol.

A simulated robot is another process, another simulator: MuJoCo at 1 kHz (training: 200 Hz)
with torque motors, and the PD law computed on the "robot" side at `pd_hz` (>= 500 Hz, like
the motor boards) from the last command that has arrived. The controller sees only what the
robot reports (IMU, encoders, foot forces, battery, the remote's buttons), with sensor noise,
an encoder calibration offset and a network latency, through a `SimLink`: quaddance's own
UDP protocol (`sim_backend`), the Go1's low-level UDP wire format (`go1_sim`) or the Go2's
DDS topics (`go2_sim`).

Faults (``push``, ``freeze``, ``nan``, ``lag``), the remote's buttons and the end of the run
come on a control socket on 127.0.0.1 that only the test harness (`ProtocolSimRobot`)
uses; the simulator's truth (foot heights, trunk pose, falls, the commands it received)
never goes to the controller during the run: the process writes it to a file when it ends.
"""

from __future__ import annotations

import abc
import argparse
import dataclasses
import json
import math
import os
import socket
import subprocess
import sys
import tempfile
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from quaddance.children import ignore_sigint, sigint_blocked_for_children
from quaddance.deploy.robot import FAULTS, JointCommand, Reading, Robot, realtime_priority
from quaddance.errors import QuaddanceError
from quaddance.robots import GO1, get_robot
from quaddance.sim.scene import SceneCfg, build_spec

LOOPBACK = "127.0.0.1"
SIM_RT_PRIORITY = 20  #: above the runner's: the robot's own boards never wait for the PC
GRAVITY_M_S2 = 9.81


@dataclass(frozen=True)
class SimRobotCfg:
    """The simulated robot. Noise figures are per reading, Gaussian standard deviations."""

    physics_dt_s: float = 0.001  #: 1 kHz, 5x finer than training's 0.005 s
    pd_hz: float = 1000.0  #: robot-side PD rate; Go1 motor boards run >= 500 Hz (FACTS 2)
    state_hz: float = 500.0  #: LowState rate of the SDK's 2 ms example loop (FACTS 6)
    #: Sensor-to-actuation delay, drawn per message, split evenly between the state and the
    #: command direction, ms: the range issue 9 names as realistic for a Go1 over the SDK
    #: (training saw 0-30 ms of action lag).
    latency_ms: tuple[float, float] = (5.0, 20.0)
    lag_extra_ms: float = 50.0  #: added to the state stream by the ``lag`` fault
    #: Half of legged_gym's uniform noise scales (0.01 rad, 1.5 rad/s, 0.2 rad/s), as a
    #: standard deviation: Go1 encoders are much finer than that, its velocity estimate not.
    encoder_noise_rad: float = 0.005
    joint_vel_noise_rad_s: float = 0.3
    gyro_noise_rad_s: float = 0.05
    imu_tilt_noise_rad: float = 0.005  #: random small rotation of the IMU quaternion
    encoder_offset_rad: float = 0.01  #: fixed calibration error per joint, uniform +-
    foot_friction: float = 0.8  #: not training's 1.0: another floor
    # Strong enough to topple any policy (the whole-body one rides out 2 m/s and 8 rad/s):
    # the fault exists to show the safety layer catching a fall.
    push_vel_m_s: tuple[float, float, float] = (0.0, 3.0, 0.0)  #: ``push`` fault, world frame
    push_roll_rad_s: float = 16.0  #: ``push`` fault: roll rate added, rad/s
    battery_pct: float = 90.0  #: state of charge the robot reports
    seed: int = 0
    robot: str = GO1.name  #: the robot simulated (`quaddance.robots.ROBOTS`)

    def to_json(self) -> str:
        return json.dumps(dataclasses.asdict(self))

    @classmethod
    def from_json(cls, text: str) -> SimRobotCfg:
        raw = json.loads(text)
        return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in raw.items()})


def rpy_from_quat(quat_wxyz: Sequence[float]) -> tuple[float, float, float]:
    """Roll, pitch, yaw (rad, z-y-x) of a unit quaternion (w, x, y, z): the trunk's truth, and
    what the Go1's and Go2's IMUs report."""
    w, x, y, z = (float(v) for v in quat_wxyz)
    return (
        math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y)),
        math.asin(min(max(2 * (w * y - z * x), -1.0), 1.0)),
        math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)),
    )


def build_torque_model(cfg: SimRobotCfg) -> mujoco.MjModel:
    """The robot's scene with torque motors (limited to its effort limits) instead of the
    training scene's position actuators; same bodies, joints, sensors and home pose."""
    scene = SceneCfg(
        robot=get_robot(cfg.robot), timestep_s=cfg.physics_dt_s, foot_friction=cfg.foot_friction
    )
    spec = build_spec(scene, visual=False)
    for act in spec.actuators:
        act.set_to_motor()  # ctrl is a torque, N m; forcerange (motor limits) stays
    return spec.compile()


@dataclass
class SensorState:
    """What the simulated robot's sensors read at one instant (model joint order, task foot
    order): what a link turns into its protocol's state message."""

    tick: int  #: +1 per state (the seq of quaddance's own protocol and of the truth)
    time_s: float  #: the robot's clock (simulation time)
    mono_s: float  #: `time.monotonic()` of the measurement (the same machine's clock)
    quat_wxyz: np.ndarray  #: (4,)
    gyro_rad_s: np.ndarray  #: (3,) trunk frame
    accel_m_s2: np.ndarray  #: (3,) trunk frame, specific force (reads +g standing still)
    joint_pos_rad: np.ndarray  #: (12,)
    joint_vel_rad_s: np.ndarray  #: (12,)
    joint_tau_nm: np.ndarray  #: (12,) torque applied
    foot_force_n: np.ndarray  #: (4,) FL FR RL RR
    battery_pct: float
    remote_keys: int  #: buttons held on the remote (`quaddance.deploy.remote`)

    @property
    def clock_ms(self) -> int:
        """The robot's clock in whole milliseconds, as the Go1's and Go2's LowState ``tick``
        counts (uint32, wrapping)."""
        return round(self.time_s * 1e3) & 0xFFFFFFFF


class SimLink(abc.ABC):
    """A robot's protocol on the simulated robot's side."""

    rejected: int = 0  #: commands that failed their CRC or were malformed: never applied

    @abc.abstractmethod
    def poll(self) -> list[JointCommand | str]:
        """What arrived since the last call, oldest first, never blocking: valid commands in
        model order (an idle motor as kp = kd = tau = 0), or control words for protocols
        that carry them (a fault of `FAULTS`, ``quit``, ``remote KEYS``)."""

    @abc.abstractmethod
    def publish(self, state: SensorState) -> None:
        """Send one state to the controller (when it is due, after the latency)."""

    @abc.abstractmethod
    def close(self) -> None:
        """Release the protocol's sockets or participants."""


def issues_torque(cmd: JointCommand) -> bool:
    """Whether a command can move a joint (any gain or feed-forward torque)."""
    return bool(np.any(cmd.kp) or np.any(cmd.kd) or np.any(cmd.tau_ff_nm))


class SimulatedRobot:
    """Physics, motor boards, sensors, network delay, faults and truth of one robot."""

    def __init__(self, cfg: SimRobotCfg, control: socket.socket | None = None) -> None:
        self.cfg = cfg
        self.control = control
        self.rng = np.random.default_rng(cfg.seed)
        self.model = build_torque_model(cfg)
        self.data = mujoco.MjData(self.model)
        mujoco.mj_resetDataKeyframe(self.model, self.data, self.model.key("home").id)
        self.data.ctrl[:] = 0.0
        mujoco.mj_forward(self.model, self.data)
        robot = self.robot = get_robot(cfg.robot)
        n = robot.num_joints
        self.limits = np.asarray(robot.effort_limit_nm)
        self.offset = self.rng.uniform(-1, 1, n) * cfg.encoder_offset_rad
        # Motor boards start passive (no command yet): zero torque.
        z = np.zeros(n)
        self.cmd = JointCommand(self.data.qpos[7:].copy(), z, z.copy(), z.copy(), z.copy())
        self.cmd_queue: deque[tuple[float, JointCommand]] = deque()
        self.state_queue: deque[tuple[float, SensorState]] = deque()
        self.last_state_due = 0.0
        self.last_cmd_due = 0.0
        self.tau = np.zeros(n)
        self.tick = 0
        self.frozen = False
        self.encoder_failed = False
        self.extra_lag_s = 0.0
        self.remote_keys = 0
        self.running = True
        self.counts = {"commands": 0, "torque_commands": 0}
        self.foot_geoms = [self.model.geom(g).id for g in robot.foot_geoms]
        trunk = self.model.body(robot.trunk_body).id
        self.trunk_geoms = {int(g) for g in np.flatnonzero(self.model.geom_bodyid == trunk)}
        self.floor = self.model.geom("floor").id
        self.foot_of_geom = {g: i for i, g in enumerate(self.foot_geoms)}
        self.foot_sites = [self.model.site(s).id for s in robot.foot_sites]
        self.noise_std = np.concatenate(
            [
                np.full(n, cfg.encoder_noise_rad),
                np.full(n, cfg.joint_vel_noise_rad_s),
                np.full(3, cfg.gyro_noise_rad_s),
                np.full(3, cfg.imu_tilt_noise_rad),
            ]
        )
        self._noise_quat = np.zeros(4)
        self._force = np.zeros(6)
        cap = 4096
        self.truth: dict[str, np.ndarray] = {
            "seq": np.zeros(cap, np.int64),
            "time_s": np.zeros(cap),
            "mono_s": np.zeros(cap),
            "late_s": np.zeros(cap),
            "feet_m": np.zeros((cap, 4)),
            "base_height_m": np.zeros(cap),
            "tilt_rad": np.zeros(cap),
            "rpy_rad": np.zeros((cap, 3)),
            "trunk_contact": np.zeros(cap, bool),
            "tau_nm": np.zeros((cap, n)),
        }
        self.n_truth = 0

    # network
    def _delay_s(self) -> float:
        lo, hi = self.cfg.latency_ms
        return self.rng.uniform(lo, hi) / 2e3  # half of the loop delay in each direction

    def _take(self, item: JointCommand | str, now: float) -> None:
        if isinstance(item, str):
            self._control(item)
            return
        self.counts["commands"] += 1
        self.counts["torque_commands"] += issues_torque(item)
        # Messages keep their order: never due before the one sent earlier.
        due = max(self.last_cmd_due, now + self._delay_s())
        self.last_cmd_due = due
        self.cmd_queue.append((due, item))

    def _receive(self, link: SimLink, now: float) -> None:
        for item in link.poll():
            self._take(item, now)
        while self.control is not None:
            try:
                msg = self.control.recv(256)
            except BlockingIOError:
                return
            self._control(msg.decode(errors="replace"))

    def _control(self, word: str) -> None:
        name, _, arg = word.partition(" ")
        if name in FAULTS:
            self._fault(name)
        elif name == "remote" and arg.isdigit():
            self.remote_keys = int(arg)
        elif name == "quit":
            self.running = False

    def _fault(self, name: str) -> None:
        if name == "push":
            vx, vy, vz = self.cfg.push_vel_m_s
            self.data.qvel[0:3] += (vx, vy, vz)
            self.data.qvel[3] += self.cfg.push_roll_rad_s
        elif name == "freeze":
            self.frozen = True
            self.state_queue.clear()  # a dead link delivers nothing more
        elif name == "nan":
            self.encoder_failed = True  # joint 0's encoder reads NaN from now on
        elif name == "lag":
            self.extra_lag_s += self.cfg.lag_extra_ms / 1e3

    # motor boards
    def _pd(self) -> None:
        c, q, dq = self.cmd, self.data.qpos[7:], self.data.qvel[6:]
        tau = c.kp * (c.q_rad - q) + c.kd * (c.dq_rad_s - dq) + c.tau_ff_nm
        if not np.isfinite(tau).all():
            tau = -2.0 * dq  # a board fed garbage falls back to damping
        np.clip(tau, -self.limits, self.limits, out=self.tau)

    # sensors
    def _measure(self, mono_s: float) -> SensorState:
        """One state: noisy IMU and encoders, foot forces; records the truth beside it."""
        d = self.data
        z = self.rng.standard_normal(30) * self.noise_std
        q = d.qpos[7:] + self.offset + z[:12]
        dq = d.qvel[6:] + z[12:24]
        gyro = d.qvel[3:6] + z[24:27]
        # The IMU's orientation off by a small random rotation (axis-angle z[27:30]).
        angle = float(np.linalg.norm(z[27:30]))
        quat = d.qpos[3:7].copy()
        if angle > 0:
            mujoco.mju_axisAngle2Quat(self._noise_quat, z[27:30] / angle, angle)
            mujoco.mju_mulQuat(quat, d.qpos[3:7], self._noise_quat)
        accel = np.zeros(3)
        world = d.qacc[0:3] + np.array([0.0, 0.0, GRAVITY_M_S2])
        mujoco.mju_rotVecQuat(accel, world, np.array([d.qpos[3], *-d.qpos[4:7]]))
        forces = np.zeros(4)
        trunk_contact = False
        if d.ncon:
            pairs = d.contact.geom[: d.ncon]
            for i in np.flatnonzero((pairs == self.floor).any(axis=1)):
                other = int(pairs[i, 1] if pairs[i, 0] == self.floor else pairs[i, 0])
                foot = self.foot_of_geom.get(other)
                if foot is not None:
                    mujoco.mj_contactForce(self.model, d, int(i), self._force)
                    forces[foot] += self._force[0]
                elif other in self.trunk_geoms:
                    trunk_contact = True
        if self.encoder_failed:
            q[0] = np.nan
        self.tick += 1
        self._record_truth(trunk_contact, mono_s)
        return SensorState(
            tick=self.tick,
            time_s=float(d.time),
            mono_s=mono_s,
            quat_wxyz=quat,
            gyro_rad_s=gyro,
            accel_m_s2=accel,
            joint_pos_rad=q,
            joint_vel_rad_s=dq,
            joint_tau_nm=self.tau.copy(),
            foot_force_n=forces,
            battery_pct=self.cfg.battery_pct,
            remote_keys=self.remote_keys,
        )

    def _record_truth(self, trunk_contact: bool, mono_s: float) -> None:
        d, i = self.data, self.n_truth
        if i == len(self.truth["seq"]):  # grow by doubling
            self.truth = {k: np.concatenate([v, np.zeros_like(v)]) for k, v in self.truth.items()}
        t = self.truth
        t["seq"][i] = self.tick
        t["time_s"][i] = d.time
        t["mono_s"][i] = mono_s
        t["late_s"][i] = time.monotonic() - mono_s  # how far physics ran behind the clock
        t["feet_m"][i] = d.site_xpos[self.foot_sites, 2] - self.robot.foot_radius_m
        t["base_height_m"][i] = d.qpos[2]
        up_z = 1 - 2 * (d.qpos[4] ** 2 + d.qpos[5] ** 2)  # world z of the trunk's z axis
        t["tilt_rad"][i] = np.arccos(np.clip(up_z, -1.0, 1.0))
        t["rpy_rad"][i] = rpy_from_quat(d.qpos[3:7])
        t["trunk_contact"][i] = trunk_contact
        t["tau_nm"][i] = self.tau
        self.n_truth += 1

    def run(self, link: SimLink, truth_path: Path) -> None:
        """Step in real time until ``quit`` (or the parent process is gone), then write the
        truth to ``truth_path``."""
        cfg, m, d = self.cfg, self.model, self.data
        dt = cfg.physics_dt_s
        pd_every = max(1, round(1.0 / (cfg.pd_hz * dt)))
        state_every = max(1, round(1.0 / (cfg.state_hz * dt)))
        parent = os.getppid()
        t0 = time.monotonic()
        k = 0
        self.overruns = 0
        while self.running:
            now = time.monotonic()
            self._receive(link, now)
            due_steps = int((now - t0) / dt)
            if due_steps - k > 100:
                # More than 0.1 s behind (the machine stalled): drop the time, as a real
                # robot's clock would not wait either, but keep stepping from here.
                t0 += (due_steps - k - 100) * dt
                due_steps = k + 100
                self.overruns += 1
            while k < due_steps:
                step_time = t0 + k * dt
                while self.cmd_queue and self.cmd_queue[0][0] <= step_time:
                    self.cmd = self.cmd_queue.popleft()[1]
                if k % pd_every == 0:
                    self._pd()
                d.ctrl[:] = self.tau
                mujoco.mj_step(m, d)
                k += 1
                if k % state_every == 0 and not self.frozen:
                    state = self._measure(t0 + k * dt)
                    due = max(self.last_state_due, t0 + k * dt + self._delay_s() + self.extra_lag_s)
                    self.last_state_due = due
                    self.state_queue.append((due, state))
            now = time.monotonic()
            while self.state_queue and self.state_queue[0][0] <= now:
                link.publish(self.state_queue.popleft()[1])
            if k % 100 == 0 and os.getppid() != parent:
                break  # the runner died: a real robot would keep its last command; we stop
            wake = t0 + (k + 1) * dt
            if self.state_queue:
                wake = min(wake, self.state_queue[0][0])
            pause = wake - time.monotonic()
            if pause > 0:
                time.sleep(pause)
        self._write_truth(truth_path, link)

    def _write_truth(self, path: Path, link: SimLink) -> None:
        from quaddance.fileio import atomic_path

        arrays = {k: v[: self.n_truth] for k, v in self.truth.items()}
        arrays["overruns"] = np.asarray(self.overruns)
        arrays["rejected"] = np.asarray(link.rejected)
        for name, count in self.counts.items():
            arrays[name] = np.asarray(count)
        with atomic_path(path) as tmp:
            np.savez(tmp, **arrays)


def run_sim_process(
    make_link: Callable[[SimRobotCfg, dict[str, Any]], SimLink],
    argv: list[str] | None = None,
    description: str = "a simulated robot for quaddance deploy (internal)",
) -> None:
    """The ``main`` of a simulator module: the robot, its protocol link, the control socket;
    says ``ready`` on the control socket, runs until ``quit``, writes the truth."""
    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("--truth", type=Path, required=True)
    ap.add_argument("--config", default="{}", help="SimRobotCfg as JSON")
    ap.add_argument("--link", default="{}", help="the protocol's options as JSON")
    ap.add_argument("--control-port", type=int, required=True, help="the harness's UDP port")
    args = ap.parse_args(argv)
    # The runner's Ctrl-C reaches the whole process group; the robot keeps running until
    # the runner has sent its damping commands and says quit.
    ignore_sigint()
    cfg = SimRobotCfg.from_json(args.config)
    control = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    control.bind((LOOPBACK, 0))
    control.setblocking(False)
    with realtime_priority(SIM_RT_PRIORITY):
        sim = SimulatedRobot(cfg, control)
        link = make_link(cfg, json.loads(args.link))
        try:
            control.sendto(b"ready", (LOOPBACK, args.control_port))
            sim.run(link, args.truth)
        finally:
            link.close()
            control.close()


class ProtocolSimRobot(Robot):
    """A simulated robot process driven through an unchanged backend (`Go1Robot`,
    `Go2Robot`, or the own protocol's `SimUdpRobot`), plus what only a simulator offers:
    faults, the remote's buttons and the truth after the run."""

    def __init__(
        self,
        name: str,
        backend: Robot,
        module: str,
        cfg: SimRobotCfg,
        link_options: dict[str, Any] | None = None,
    ) -> None:
        self.name = name
        self.backend = backend
        self.module = module
        self.cfg = cfg
        self.link_options = link_options or {}
        self._tmp = tempfile.TemporaryDirectory(prefix="quaddance-sim-")
        self._truth_path = Path(self._tmp.name) / "truth.npz"
        self._stderr_path = Path(self._tmp.name) / "stderr.txt"
        self._control = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._control.bind((LOOPBACK, 0))
        self._proc: subprocess.Popen | None = None
        self._sim_addr: tuple[str, int] | None = None
        self._truth: dict[str, np.ndarray] | None = None

    def start(self, timeout_s: float = 30.0) -> Reading:
        cmd = [
            *(sys.executable, "-m", self.module, "--truth", str(self._truth_path)),
            *("--config", self.cfg.to_json(), "--link", json.dumps(self.link_options)),
            *("--control-port", str(self._control.getsockname()[1])),
        ]
        # It starts with SIGINT blocked, so a Ctrl-C while it imports cannot end it.
        with open(self._stderr_path, "wb") as err, sigint_blocked_for_children():
            self._proc = subprocess.Popen(
                cmd, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=err
            )
        end = time.monotonic() + timeout_s
        self._control.settimeout(0.05)
        while self._sim_addr is None and time.monotonic() < end and self._proc.poll() is None:
            try:
                msg, addr = self._control.recvfrom(64)
            except TimeoutError:
                continue
            if msg == b"ready":
                self._sim_addr = addr
        if self._sim_addr is None:
            self.close()
            lines = self._stderr_path.read_text(errors="replace").strip().splitlines()
            raise QuaddanceError(
                f"the simulated robot ({self.name}) did not start: {(lines or ['no output'])[-1]}"
            )
        try:
            return self.backend.start(max(1.0, end - time.monotonic()))
        except BaseException:
            self.close()
            raise

    def read(self) -> Reading | None:
        return self.backend.read()

    def send(self, cmd: JointCommand) -> None:
        self.backend.send(cmd)

    def _tell(self, word: str) -> bool:
        if self._sim_addr is None:
            return False
        self._control.sendto(word.encode(), self._sim_addr)
        return True

    def inject(self, fault: str) -> bool:
        return fault in FAULTS and self._tell(fault)

    def press(self, keys: int) -> bool:
        """Hold ``keys`` on the simulated remote (0 releases them)."""
        return self._tell(f"remote {int(keys)}")

    def close(self) -> None:
        if self._proc is None:
            return
        self.backend.close()
        for _ in range(3):  # UDP on loopback does not drop, but a quit costs nothing
            self._tell("quit")
        try:
            self._proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self._proc.kill()
            self._proc.wait()
        self._proc = None
        if self._truth_path.is_file():
            with np.load(self._truth_path) as z:
                self._truth = {k: z[k] for k in z.files}
        self._control.close()

    def received(self) -> dict[str, int]:
        """What the simulator counted after the run: commands, torque_commands, rejected."""
        t = self._truth or {}
        keys = ("commands", "torque_commands", "rejected", "overruns")
        return {k: int(t[k]) for k in keys if k in t}

    def info(self) -> dict:
        return {
            "physics_dt_s": self.cfg.physics_dt_s,
            "pd_hz": self.cfg.pd_hz,
            "latency_ms": list(self.cfg.latency_ms),
            "state_hz": self.cfg.state_hz,
            "foot_friction": self.cfg.foot_friction,
            **self.received(),
            **({"sdk": sdk} if (sdk := self.backend.info()) else {}),
        }

    def truth(self) -> dict[str, np.ndarray] | None:
        return self._truth

    def __del__(self) -> None:
        if getattr(self, "_proc", None) is not None:
            self._proc.kill()
