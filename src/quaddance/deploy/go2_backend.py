"""A Go2 over unitree_sdk2 (DDS): `quaddance deploy --robot go2`, and `go2-sim` unchanged.

Optional: ``pip install 'quaddance[go2]'`` (see `quaddance.deploy.dds`, which sets DDS up).

Low-level control needs the robot's own locomotion off: `start` asks the SDK's motion
switcher which mode runs (``CheckMode``) and releases it (``ReleaseMode``) until none does.
It then reads ``rt/lowstate``. From the runner's first command on, a 500 Hz thread publishes
``rt/lowcmd`` (the SDK's header, level flag and servo mode, its CRC) with the latest command;
the 50 Hz runner only swaps that command. Before the first command nothing is published,
so a dry run sends nothing. Our safety layer (`quaddance.deploy.safety`) runs before that.

The map from the SDK's motor and foot order to quaddance's (model joint order, task foot
order) and the joint signs are the robot's (`RobotCfg.sdk_joint_index`, `sdk_joint_sign`,
`sdk_foot_index`, in `quaddance.robots.go2`).
"""

from __future__ import annotations

import functools
import threading
import time
from typing import Any

from quaddance.deploy.dds import init_dds, load_sdk2, polled_reader, take_serialized
from quaddance.deploy.go2_wire import LowStateFields, decode_low_state, seal_low_cmd
from quaddance.deploy.remote import decode_remote
from quaddance.deploy.robot import JointCommand, Reading, Robot, realtime_priority
from quaddance.errors import QuaddanceError
from quaddance.robots import GO2, RobotCfg

LOW_CMD_TOPIC = "rt/lowcmd"
LOW_STATE_TOPIC = "rt/lowstate"
HEAD = (0xFE, 0xEF)  #: a Go2 LowCmd's first two bytes
LOWLEVEL = 0xFF  #: level_flag: low-level control
SERVO_MODE = 0x01  #: motor mode: PD servo (0x00 is idle)
LOOP_S = 0.002  #: 500 Hz, the SDK examples' low-level loop
#: The lowcmd thread's real-time priority: above the runner's, which a thread does not
#: inherit (the runner's resets on fork), so that the robot hears from the PC every 2 ms.
LOOP_RT_PRIORITY = 15
RPC_TIMEOUT_S = 1.0  #: the motion switcher's answer to one call


def fill_low_cmd(msg: Any, cmd: JointCommand, robot: RobotCfg) -> bytes:
    """Write a `JointCommand` (model order) into an SDK ``LowCmd_``, servo mode, with its CRC;
    returns it serialized."""
    msg.head[:] = HEAD
    msg.level_flag = LOWLEVEL
    q, dq, tau = (robot.to_sdk(v) for v in (cmd.q_rad, cmd.dq_rad_s, cmd.tau_ff_nm))
    kp, kd = (robot.to_sdk(v, signed=False) for v in (cmd.kp, cmd.kd))
    for i, m in enumerate(msg.motor_cmd[: robot.num_joints]):
        m.mode = SERVO_MODE
        m.q, m.dq, m.tau = float(q[i]), float(dq[i]), float(tau[i])
        m.kp, m.kd = float(kp[i]), float(kd[i])
    return seal_low_cmd(msg)


def freeze_serialized(msg: Any, wire: bytes) -> None:
    """Have the writes of ``msg`` send ``wire`` (``msg`` serialized by `go2_wire`) until
    frozen again.

    cyclonedds-python serializes in Python, ~0.5 ms for a LowCmd_: done 500 times a second
    that took a fifth of a core and held the GIL against the runner's tick, for a command
    that changes 50 times a second. A writer sends what ``sample.serialize(use_version_2=None)``
    returns (None: the SDK's channels set no data representation).
    """
    msg.serialize = lambda **_: wire


def reading_from_low_state(state: LowStateFields, robot: RobotCfg) -> Reading:
    """A ``LowState_`` (`decode_low_state`) as a `Reading` (model joint order, task foot
    order).

    ``seq`` is the state's ``tick`` (the robot's milliseconds), new with every state.
    """
    return Reading(
        seq=state.tick,
        stamp_s=state.tick / 1000.0,
        quat_wxyz=state.quat_wxyz,  # w, x, y, z
        gyro_rad_s=state.gyro_rad_s,
        joint_pos_rad=robot.from_sdk(state.q[: robot.num_joints]),
        joint_vel_rad_s=robot.from_sdk(state.dq[: robot.num_joints]),
        foot_force_n=robot.feet_from_sdk(state.foot_force),  # the sensors' raw units
        battery_pct=float(state.soc),
        remote_keys=decode_remote(state.wireless_remote),
    )


class Go2Robot(Robot):
    """`Robot` over unitree_sdk2's DDS topics, with sport mode released first."""

    name = "go2"
    robot_cfg = GO2  #: the robot this SDK drives (its joint map and signs)

    def __init__(self, domain_id: int, network: str, release_timeout_s: float = 10.0) -> None:
        load_sdk2()  # the missing-SDK error at once
        self.network = network
        self.domain_id = domain_id
        self.release_timeout_s = release_timeout_s
        self._lock = threading.Lock()
        self._reader: Any = None  # rt/lowstate
        self._latest: Reading | None = None
        self._cmd: JointCommand | None = None
        self._stop = threading.Event()  # ends the 500 Hz thread, and wakes it at once
        self._thread: threading.Thread | None = None
        self._pub: Any = None
        self.released_modes: list[str] = []  #: the modes `start` released, for deploy.json
        self.sent = 0  #: rt/lowcmd messages written

    def start(self, timeout_s: float = 5.0) -> Reading:
        init_dds(self.network, self.domain_id)
        from unitree_sdk2py.core.channel import ChannelPublisher
        from unitree_sdk2py.idl.unitree_go.msg.dds_ import LowCmd_, LowState_

        self._release_sport_mode()
        # Only the newest state, taken when `read` asks: the 500 Hz states are decoded at the
        # runner's 50 Hz only, from their bytes (`decode_low_state`).
        self._reader = polled_reader(LOW_STATE_TOPIC, LowState_, depth=1)
        self._pub = ChannelPublisher(LOW_CMD_TOPIC, LowCmd_)
        self._pub.Init()  # a writer, matched now; it writes from the first command on
        end = time.monotonic() + timeout_s
        while (reading := self.read()) is None and time.monotonic() < end:
            time.sleep(0.01)
        if reading is not None:
            return reading
        self.close()
        raise QuaddanceError(
            f"no {LOW_STATE_TOPIC} from the Go2 on {self.network} (DDS domain "
            f"{self.domain_id}) within {timeout_s:g} s (network set-up: docs/DEPLOY.md)"
        )

    def _release_sport_mode(self) -> None:
        """Release the robot's locomotion service until the motion switcher reports none."""
        client = _motion_switcher()
        end = time.monotonic() + self.release_timeout_s
        while True:
            code, mode = client.CheckMode()
            if code == 0 and not mode.get("name"):
                return
            if time.monotonic() > end:
                problem = (
                    f"it still runs {mode.get('name')!r}"
                    if code == 0
                    else f"no answer (SDK code {code})"
                )
                raise QuaddanceError(
                    f"cannot release the Go2's sport mode on {self.network} (DDS domain "
                    f"{self.domain_id}) within {self.release_timeout_s:g} s: {problem} "
                    "(is the robot on, in an edition that allows low-level control? "
                    "docs/DEPLOY.md)"
                )
            if code == 0:
                self.released_modes.append(str(mode["name"]))
                client.ReleaseMode()
            time.sleep(0.1)

    def read(self) -> Reading | None:
        if self._reader is not None:
            for data in take_serialized(self._reader, 1):
                state = decode_low_state(data)
                if state is not None:
                    self._latest = reading_from_low_state(state, self.robot_cfg)
        return self._latest

    def send(self, cmd: JointCommand) -> None:
        with self._lock:
            self._cmd = cmd
        if self._thread is None:
            self._stop.clear()
            self._thread = threading.Thread(target=self._loop, name="go2-lowcmd", daemon=True)
            self._thread.start()

    def _loop(self) -> None:
        with realtime_priority(LOOP_RT_PRIORITY):
            self._write_commands()

    def _write_commands(self) -> None:
        from unitree_sdk2py.idl.default import unitree_go_msg_dds__LowCmd_

        msg = unitree_go_msg_dds__LowCmd_()
        packed: JointCommand | None = None
        next_t = time.monotonic()
        while True:
            with self._lock:
                cmd = self._cmd
            if cmd is not packed:  # once per runner command, not 10 times
                freeze_serialized(msg, fill_low_cmd(msg, cmd, self.robot_cfg))
                packed = cmd
            self._pub.Write(msg)
            self.sent += 1
            next_t = max(next_t + LOOP_S, time.monotonic())  # late: no burst to catch up
            if self._stop.wait(next_t - time.monotonic()):
                return

    def close(self) -> None:
        # The last command the runner sent (damping) keeps going out until here.
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=1.0)
        if self._pub is not None and (self._thread is None or not self._thread.is_alive()):
            self._pub.Close()  # a writer still in use by a late thread is left to it
        self._thread = self._reader = self._pub = None

    def info(self) -> dict:
        return {
            "network": self.network,
            "dds_domain": self.domain_id,
            "released_modes": self.released_modes,
            "lowcmd_sent": self.sent,  # 0 after a dry run
        }


@functools.cache
def _motion_switcher() -> Any:
    """The process's motion switcher client: the SDK's RPC client has no close, and a
    dropped one's DDS listener may still be called (a second deploy in one process
    crashed), so it lives as long as the process's DDS domain."""
    from unitree_sdk2py.comm.motion_switcher.motion_switcher_client import (
        MotionSwitcherClient,
    )

    client = MotionSwitcherClient()
    client.SetTimeout(RPC_TIMEOUT_S)
    client.Init()
    return client
