"""`go1-sim`: the simulated robot behind the Go1's low-level UDP wire format.

The process binds UDP on 127.0.0.1 at the robot's port and behaves as the Go1's motor
controller board does for unitree_legged_sdk 3.8: it takes ``LowCmd`` datagrams (`go1_wire`)
and answers ``LowState`` datagrams to the address the last valid command came from, from the
port the SDK targets (the SDK's socket is connected there and takes nothing from elsewhere).
So the `Go1Robot` backend that drives a real Go1, its target set to 127.0.0.1 and this port,
drives it through the real SDK binding. A datagram of the wrong length, head or level, or with a bad
CRC, is counted in `Go1UdpLink.rejected` and never applied.

Run as ``python -m quaddance.deploy.go1_sim --link '{"port": N}' ...`` (`run_sim_process`).
"""

from __future__ import annotations

import socket
from typing import Any

import numpy as np

from quaddance.deploy import go1_wire as wire
from quaddance.deploy import simulator
from quaddance.deploy.go1_backend import ROBOT_PORT, Go1Robot
from quaddance.deploy.remote import encode_remote
from quaddance.deploy.robot import JointCommand
from quaddance.deploy.simulator import SensorState, SimLink, SimRobotCfg
from quaddance.robots import GO1, RobotCfg, get_robot

#: Receive buffer: past any valid datagram, so a longer one is seen whole and refused.
_RECV_BYTES = 4096


def command_from_frame(frame: wire.LowCmdFrame, robot: RobotCfg) -> JointCommand:
    """A decoded LowCmd as the motor boards apply it, in model joint order: a motor not in
    servo mode exerts nothing (kp = kd = tau = 0), and the SDK's stop values of q (dq) turn
    the position (velocity) loop off."""
    servo = robot.from_sdk(frame.mode == wire.SERVO_MODE, signed=False) > 0
    q, dq, tau = robot.from_sdk(frame.q), robot.from_sdk(frame.dq), robot.from_sdk(frame.tau)
    position_on = servo & (np.abs(q) < wire.POS_STOP_F)
    velocity_on = servo & (np.abs(dq) < wire.VEL_STOP_F)
    return JointCommand(
        q_rad=np.where(position_on, q, 0.0),
        dq_rad_s=np.where(velocity_on, dq, 0.0),
        kp=np.where(position_on, robot.from_sdk(frame.kp, signed=False), 0.0),
        kd=np.where(velocity_on, robot.from_sdk(frame.kd, signed=False), 0.0),
        tau_ff_nm=np.where(servo, tau, 0.0),
    )


def low_state_datagram(state: SensorState, robot: RobotCfg) -> bytes:
    """A `SensorState` (model joint order, task foot order) as the Go1's LowState datagram
    (SDK motor and foot order, SDK signs: `RobotCfg.to_sdk`)."""
    return wire.encode_low_state(
        tick=state.clock_ms,
        quat_wxyz=state.quat_wxyz,
        gyro_rad_s=state.gyro_rad_s,
        accel_m_s2=state.accel_m_s2,
        q=robot.to_sdk(state.joint_pos_rad),
        dq=robot.to_sdk(state.joint_vel_rad_s),
        tau_est=robot.to_sdk(state.joint_tau_nm),
        foot_force=robot.feet_to_sdk(state.foot_force_n),
        wireless_remote=encode_remote(state.remote_keys),
        battery_soc=min(max(round(state.battery_pct), 0), 100),
    )


class Go1UdpLink(SimLink):
    """The Go1's low-level UDP protocol on the robot's side, at 127.0.0.1:``port``."""

    def __init__(self, robot: RobotCfg = GO1, port: int = ROBOT_PORT) -> None:
        self.robot = robot
        self.rejected = 0
        self.peer: tuple[str, int] | None = None  #: where the last valid command came from
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._sock.bind((simulator.LOOPBACK, port))
        self._sock.setblocking(False)

    @property
    def port(self) -> int:
        return self._sock.getsockname()[1]

    def poll(self) -> list[JointCommand | str]:
        commands: list[JointCommand | str] = []
        while True:
            try:
                data, addr = self._sock.recvfrom(_RECV_BYTES)
            except BlockingIOError:
                return commands
            try:
                frame = wire.decode_low_cmd(data)
            except wire.WireError:
                frame = None
            if frame is None or not frame.valid:
                self.rejected += 1
                continue
            self.peer = addr
            commands.append(command_from_frame(frame, self.robot))

    def publish(self, state: SensorState) -> None:
        if self.peer is not None:  # before any command there is nobody to answer
            self._sock.sendto(low_state_datagram(state, self.robot), self.peer)

    def close(self) -> None:
        self._sock.close()


def make_link(cfg: SimRobotCfg, options: dict[str, Any]) -> Go1UdpLink:
    """The link `run_sim_process` builds: link options ``{"port": N}`` (default 8007)."""
    return Go1UdpLink(get_robot(cfg.robot), int(options.get("port", ROBOT_PORT)))


def free_udp_port() -> int:
    """A UDP port on 127.0.0.1 that is free now (the system's pick for port 0)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind((simulator.LOOPBACK, 0))
        return s.getsockname()[1]


def go1_sim_robot(
    cfg: SimRobotCfg | None = None, power_level: int = 1
) -> simulator.ProtocolSimRobot:
    """`deploy --robot go1-sim`: the real Go1's backend (`Go1Robot`) through the SDK to a
    simulated Go1 at 127.0.0.1 on a free port (the SDK's own side takes any free port)."""
    cfg = cfg or SimRobotCfg()
    port = free_udp_port()
    backend = Go1Robot(simulator.LOOPBACK, power_level, local_port=0, robot_port=port)
    return simulator.ProtocolSimRobot(
        "go1-sim", backend, "quaddance.deploy.go1_sim", cfg, {"port": port}
    )


def main(argv: list[str] | None = None) -> None:
    simulator.run_sim_process(
        make_link, argv, "go1-sim: a simulated Go1 behind its low-level UDP format"
    )


if __name__ == "__main__":
    main()
