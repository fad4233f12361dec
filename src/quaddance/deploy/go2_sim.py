"""The simulated Go2 behind the Go2's own DDS topics: `quaddance deploy --robot go2-sim`.

A process that the `go2` backend cannot tell from the robot (`python -m
quaddance.deploy.go2_sim`, started by the harness): the physics core of
`quaddance.deploy.simulator` behind unitree_sdk2's channels, with the SDK's own IDL types and
CRC. It subscribes ``rt/lowcmd`` (a command whose CRC fails is counted and dropped), publishes
``rt/lowstate`` and answers the motion switcher's ``CheckMode`` / ``ReleaseMode`` as a Go2
does: its sport mode runs until released.
"""

from __future__ import annotations

import json
import os
import threading
from typing import Any

import numpy as np

from quaddance.deploy.dds import GO2_DOMAIN_ID, init_dds, polled_reader, take_serialized
from quaddance.deploy.go2_backend import (
    LOW_CMD_TOPIC,
    LOW_STATE_TOPIC,
    SERVO_MODE,
    Go2Robot,
    freeze_serialized,
)
from quaddance.deploy.go2_wire import LowCmdMotors, decode_low_cmd, seal_low_state
from quaddance.deploy.remote import encode_remote
from quaddance.deploy.robot import JointCommand
from quaddance.deploy.simulator import (
    ProtocolSimRobot,
    SensorState,
    SimLink,
    SimRobotCfg,
    rpy_from_quat,
    run_sim_process,
)
from quaddance.robots import GO2, RobotCfg, get_robot

SPORT_MODE = "normal"  #: the mode a Go2 runs when it boots (the SDK's name for sport mode)
_INT16_MAX = 32767
#: Commands kept between two polls (1 ms apart): the newest 64, 128 ms at 500 Hz.
COMMAND_QUEUE = 64


def joint_command_from_low_cmd(motors: LowCmdMotors, robot: RobotCfg) -> JointCommand:
    """A ``LowCmd_``'s motor commands as a `JointCommand` in model order; a motor not in
    servo mode is idle (no gain, no torque), as the motor boards treat it."""
    n = robot.num_joints
    servo = robot.from_sdk(motors.mode[:n] == SERVO_MODE, signed=False) > 0
    q, dq, tau = (robot.from_sdk(v[:n]) for v in (motors.q, motors.dq, motors.tau))
    kp, kd = (robot.from_sdk(v[:n], signed=False) for v in (motors.kp, motors.kd))
    return JointCommand(
        q_rad=q,
        dq_rad_s=dq,
        kp=np.where(servo, kp, 0.0),
        kd=np.where(servo, kd, 0.0),
        tau_ff_nm=np.where(servo, tau, 0.0),
    )


def fill_low_state(msg: Any, state: SensorState, robot: RobotCfg) -> bytes:
    """Write a `SensorState` (model order) into an SDK ``LowState_``, with its CRC; returns
    it serialized."""
    msg.tick = state.clock_ms
    imu = msg.imu_state
    imu.quaternion[:] = [float(v) for v in state.quat_wxyz]
    imu.gyroscope[:] = [float(v) for v in state.gyro_rad_s]
    imu.accelerometer[:] = [float(v) for v in state.accel_m_s2]
    imu.rpy[:] = rpy_from_quat(state.quat_wxyz)
    q, dq, tau = (
        robot.to_sdk(v) for v in (state.joint_pos_rad, state.joint_vel_rad_s, state.joint_tau_nm)
    )
    for i, m in enumerate(msg.motor_state[: robot.num_joints]):
        m.q, m.dq, m.tau_est = float(q[i]), float(dq[i]), float(tau[i])
    force = np.clip(np.rint(state.foot_force_n), -_INT16_MAX, _INT16_MAX)
    msg.foot_force[:] = [int(f) for f in robot.feet_to_sdk(force)]
    msg.wireless_remote[:] = list(encode_remote(state.remote_keys))
    msg.bms_state.soc = int(np.clip(round(state.battery_pct), 0, 100))
    return seal_low_state(msg)


class Go2DdsLink(SimLink):
    """The Go2's DDS side: ``rt/lowcmd`` in, ``rt/lowstate`` out, the motion switcher."""

    def __init__(self, iface: str = "lo", domain: int = GO2_DOMAIN_ID, robot: RobotCfg = GO2):
        init_dds(iface, domain)
        from unitree_sdk2py.core.channel import ChannelPublisher
        from unitree_sdk2py.idl.default import unitree_go_msg_dds__LowState_
        from unitree_sdk2py.idl.unitree_go.msg.dds_ import LowCmd_, LowState_

        self.robot = robot
        self.rejected = 0
        self._state_msg = unitree_go_msg_dds__LowState_()
        self.switcher = MotionSwitcher()
        self._pub = ChannelPublisher(LOW_STATE_TOPIC, LowState_)
        self._pub.Init()
        # Taken and decoded in `poll`, on the simulator's real-time thread.
        self._reader = polled_reader(LOW_CMD_TOPIC, LowCmd_, depth=COMMAND_QUEUE)

    def poll(self) -> list[JointCommand | str]:
        out: list[JointCommand | str] = []
        for data in take_serialized(self._reader, COMMAND_QUEUE):
            motors = decode_low_cmd(data)
            if motors is None or not motors.crc_ok:
                self.rejected += 1
            else:
                out.append(joint_command_from_low_cmd(motors, self.robot))
        return out

    def publish(self, state: SensorState) -> None:
        msg = self._state_msg
        freeze_serialized(msg, fill_low_state(msg, state, self.robot))
        self._pub.Write(msg)

    def close(self) -> None:
        self._reader = None


class MotionSwitcher:
    """The robot's motion switcher service (the SDK's RPC server): ``CheckMode`` names the
    running mode, the sport mode until ``ReleaseMode``; ``releases`` counts those calls."""

    def __init__(self) -> None:
        from unitree_sdk2py.comm.motion_switcher import motion_switcher_api as api
        from unitree_sdk2py.rpc.server import Server

        self.mode = SPORT_MODE
        self.releases = 0
        self._lock = threading.Lock()
        self._server = Server(api.MOTION_SWITCHER_SERVICE_NAME)
        self._server._SetApiVersion(api.MOTION_SWITCHER_API_VERSION)
        self._server._RegistHandler(api.MOTION_SWITCHER_API_ID_CHECK_MODE, self._check, False)
        self._server._RegistHandler(api.MOTION_SWITCHER_API_ID_RELEASE_MODE, self._release, False)
        self._server.Start(False)

    def _check(self, parameter: str) -> tuple[int, str]:
        with self._lock:
            return 0, json.dumps({"form": "0", "name": self.mode})

    def _release(self, parameter: str) -> tuple[int, str]:
        with self._lock:
            self.mode = ""
            self.releases += 1
        return 0, ""


def make_link(cfg: SimRobotCfg, options: dict[str, Any]) -> Go2DdsLink:
    """The link for `run_sim_process`: ``options`` ``{"iface": "lo", "domain": 0}``."""
    return Go2DdsLink(
        iface=str(options.get("iface", "lo")),
        domain=int(options.get("domain", GO2_DOMAIN_ID)),
        robot=get_robot(cfg.robot),
    )


def sim_domain_id() -> int:
    """The DDS domain of this process's simulated Go2s, 100-199 (not the robot's 0): one per
    controller process, which holds one domain, so that runs on one machine do not mix."""
    return 100 + os.getpid() % 100


def go2_sim_robot(cfg: SimRobotCfg | None = None) -> ProtocolSimRobot:
    """`deploy --robot go2-sim`: a simulated Go2 driven by the unchanged `go2` backend, over
    DDS on the loopback interface."""
    domain = sim_domain_id()
    return ProtocolSimRobot(
        "go2-sim",
        Go2Robot(domain, "lo"),
        "quaddance.deploy.go2_sim",
        cfg or SimRobotCfg(robot=GO2.name),
        {"iface": "lo", "domain": domain},
    )


def main(argv: list[str] | None = None) -> None:
    run_sim_process(make_link, argv, "a simulated Go2 behind unitree_sdk2's DDS (internal)")


if __name__ == "__main__":
    main()
