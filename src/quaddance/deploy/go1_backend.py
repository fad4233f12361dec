"""A real Go1 over unitree_legged_sdk 3.8 (low-level UDP): `quaddance deploy --robot go1`.

Optional: ``pip install 'quaddance[go1]'`` installs the SDK (PyPI ``unitree-legged-sdk``,
module ``unitree_legged_sdk.robot_interface``); it is imported only when this backend runs.

The SDK expects a command every 2 ms, so a 500 Hz thread exchanges LowCmd / LowState with the
robot and passes every command through the SDK's own guards (``Safety.PositionLimit`` and
``Safety.PowerProtect`` at the chosen level) before sending; the 50 Hz runner only swaps the
command that thread sends. Our safety layer (`quaddance.deploy.safety`) runs before that.
That thread keeps its Python work small, for it runs above the runner and holds the GIL while
it works: it keeps the newest state as the SDK's object (decoded when `read` asks, at 50 Hz)
and fills the LowCmd once per runner command (or after PowerProtect idled its motors).

The map from the SDK's motor and foot order to quaddance's (model joint order, task foot
order) and the joint signs are the robot's (`RobotCfg.sdk_joint_index`, `sdk_joint_sign`,
`sdk_foot_index`; for the Go1 the identity with signs +1, see `quaddance.robots.go1`).
"""

from __future__ import annotations

import threading
import time
from types import ModuleType

import numpy as np

from quaddance.deploy.remote import decode_remote
from quaddance.deploy.robot import JointCommand, Reading, Robot, realtime_priority
from quaddance.errors import QuaddanceError
from quaddance.robots import GO1, RobotCfg

LOWLEVEL = 0xFF  #: the SDK's low-level control flag
SERVO_MODE = 0x0A  #: motor mode: PD servo (0x00 is idle)
ROBOT_IP = "192.168.123.10"  #: the Go1's motor controller board on its wired network
ROBOT_PORT = 8007
LOCAL_PORT = 8080
LOOP_S = 0.002  #: 500 Hz, the SDK examples' low-level loop
#: The exchange thread's real-time priority: above the runner's (a thread does not inherit
#: it), so the robot hears from the PC every 2 ms whatever else the machine does.
LOOP_RT_PRIORITY = 15


def load_sdk() -> ModuleType:
    """The SDK's Python module, or one clear error saying how to get it."""
    try:
        from unitree_legged_sdk import robot_interface
    except ImportError as err:
        raise QuaddanceError(
            f"--robot go1 needs unitree_legged_sdk ({err}): pip install 'quaddance[go1]'"
        ) from None
    return robot_interface


def fill_low_cmd(low_cmd, cmd: JointCommand, robot: RobotCfg) -> None:
    """Write a `JointCommand` (model order) into an SDK ``LowCmd``, servo mode."""
    low_cmd.levelFlag = LOWLEVEL
    motors = low_cmd.motorCmd  # the binding builds this list on every access: once
    q, dq, tau = (robot.to_sdk(v).tolist() for v in (cmd.q_rad, cmd.dq_rad_s, cmd.tau_ff_nm))
    kp, kd = (robot.to_sdk(v, signed=False).tolist() for v in (cmd.kp, cmd.kd))
    for i in range(robot.num_joints):
        m = motors[i]
        m.mode = SERVO_MODE
        m.q, m.dq, m.Kp, m.Kd, m.tau = q[i], dq[i], kp[i], kd[i], tau[i]


def reading_from_low_state(state, robot: RobotCfg) -> Reading:
    """An SDK ``LowState`` as a `Reading` (model joint order, quaddance foot order).

    ``seq`` is the robot's millisecond ``tick``: it advances with every new state. The battery
    is the BMS's state of charge; the remote's buttons come from ``wirelessRemote``.
    """
    motors = state.motorState[: robot.num_joints]
    return Reading(
        seq=int(state.tick),
        stamp_s=int(state.tick) / 1000.0,
        quat_wxyz=np.asarray(state.imu.quaternion, dtype=np.float64),  # SDK order: w, x, y, z
        gyro_rad_s=np.asarray(state.imu.gyroscope, dtype=np.float64),
        joint_pos_rad=robot.from_sdk([m.q for m in motors]),
        joint_vel_rad_s=robot.from_sdk([m.dq for m in motors]),
        foot_force_n=robot.feet_from_sdk(state.footForce),  # raw sensor units on a Go1, not N
        battery_pct=float(state.bms.SOC),
        remote_keys=decode_remote(state.wirelessRemote),
    )


def _check_local_port(port: int) -> None:
    """The SDK binds this UDP port for the robot's replies; where another program holds it,
    the SDK only prints a line and no state ever arrives, which reads as a network fault."""
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        try:
            probe.bind(("0.0.0.0", port))
        except OSError as err:
            raise QuaddanceError(
                f"the local UDP port {port}, which the Go1 SDK listens on, is taken "
                f"({err.strerror or err}): another program (a second deploy?) holds it"
            ) from None


class Go1Robot(Robot):
    """`Robot` over the SDK's low-level UDP link, with its PositionLimit and PowerProtect."""

    name = "go1"
    robot_cfg = GO1  #: the robot this SDK drives (its joint map and signs)

    def __init__(
        self,
        robot_ip: str = ROBOT_IP,
        power_level: int = 1,
        local_port: int = LOCAL_PORT,
        robot_port: int = ROBOT_PORT,
    ) -> None:
        if not 1 <= power_level <= 10:
            raise QuaddanceError(f"--power-level must be 1-10, got {power_level}")
        self.robot_ip = robot_ip
        self.power_level = power_level
        self.local_port = local_port
        self.robot_port = robot_port
        self._sdk: ModuleType | None = None
        self._lock = threading.Lock()
        self._cmd: JointCommand | None = None
        # The SDK's newest LowState, from the exchange thread: a new object for each state,
        # never written after it is handed over.
        self._low_state = None
        self._decoded = None  # the LowState that `_latest` was decoded from
        self._latest: Reading | None = None
        self._running = False
        self._thread: threading.Thread | None = None
        self.power_protect_trips = 0

    def start(self, timeout_s: float = 5.0) -> Reading:
        sdk = self._sdk = load_sdk()
        _check_local_port(self.local_port)
        self._udp = sdk.UDP(LOWLEVEL, self.local_port, self.robot_ip, self.robot_port)
        self._safe = sdk.Safety(sdk.LeggedType.Go1)
        self._low_cmd = sdk.LowCmd()
        self._low_state = None
        self._udp.InitCmdData(self._low_cmd)
        self._running = True
        self._thread = threading.Thread(target=self._loop, name="go1-lowlevel", daemon=True)
        self._thread.start()
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            reading = self.read()
            if reading is not None and reading.seq != 0:
                return reading
            time.sleep(0.01)
        self.close()
        raise QuaddanceError(
            f"no state from the Go1 at {self.robot_ip}:{self.robot_port} within {timeout_s:g} s "
            "(network set-up: docs/DEPLOY.md)"
        )

    def _loop(self) -> None:
        with realtime_priority(LOOP_RT_PRIORITY):
            self._exchange()

    def _exchange(self) -> None:
        # Until the runner's first command: idle motors (mode 0, no torque), as the SDK starts.
        assert self._sdk is not None
        next_t = time.monotonic()
        packed: JointCommand | None = None  # the command in self._low_cmd
        while self._running:
            self._udp.Recv()
            state = self._sdk.LowState()
            self._udp.GetRecv(state)
            with self._lock:
                self._low_state = state
                cmd = self._cmd
            if cmd is not None:
                if cmd is not packed:
                    fill_low_cmd(self._low_cmd, cmd, self.robot_cfg)
                    # Clamping a clamped command changes nothing: once per command is enough.
                    self._safe.PositionLimit(self._low_cmd)
                    packed = cmd
                # 1: within the limit; -1: over it for several ticks, and the SDK has set
                # every motor idle (mode 0x00) and printed an error: for this send only, as
                # when the command is filled every loop.
                if self._safe.PowerProtect(self._low_cmd, state, self.power_level) < 0:
                    self.power_protect_trips += 1
                    packed = None
            self._udp.SetSend(self._low_cmd)
            self._udp.Send()
            next_t += LOOP_S
            pause = next_t - time.monotonic()
            if pause > 0:
                time.sleep(pause)
            else:
                next_t = time.monotonic()

    def read(self) -> Reading | None:
        with self._lock:
            state = self._low_state
        if state is None:
            return None
        if state is not self._decoded:  # a new state since the last read
            self._latest = reading_from_low_state(state, self.robot_cfg)
            self._decoded = state
        return self._latest

    def send(self, cmd: JointCommand) -> None:
        with self._lock:
            self._cmd = cmd

    def close(self) -> None:
        # The last command the runner sent (damping) keeps going out until here.
        self._running = False
        if self._thread is not None:
            self._thread.join(timeout=1.0)
            self._thread = None

    def info(self) -> dict:
        return {
            "robot_ip": self.robot_ip,
            "power_level": self.power_level,
            "power_protect_trips": self.power_protect_trips,
        }
