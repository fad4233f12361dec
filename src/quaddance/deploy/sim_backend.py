"""quaddance's own robot protocol: `quaddance deploy --robot sim` (the default).

The simulated robot (`quaddance.deploy.simulator`) and the runner exchange datagrams over
UDP on 127.0.0.1 in a small format of our own: the states it reports, the commands it
takes. The runner's side is `SimUdpRobot`; the robot's side is `OwnLink`, run by
``python -m quaddance.deploy.sim_backend`` (started by `ProtocolSimRobot`).
"""

from __future__ import annotations

import socket
import struct
import time
from typing import Any

import numpy as np

from quaddance.deploy.robot import JointCommand, Reading, Robot
from quaddance.deploy.simulator import (
    LOOPBACK,
    ProtocolSimRobot,
    SensorState,
    SimLink,
    SimRobotCfg,
    run_sim_process,
)
from quaddance.errors import QuaddanceError
from quaddance.robots import get_robot

# Wire format (little-endian). State: kind, seq, robot time s, monotonic time of the
# measurement s, quat 4, gyro 3, q 12, dq 12, foot force 4, battery %, remote buttons.
_STATE = struct.Struct("<cIdd36fH")
_SEQ = struct.Struct("<xI")  # a state packet's seq, read before the rest is decoded
_CMD = struct.Struct("<cI60f")  # kind, seq, q 12, dq 12, kp 12, kd 12, tau_ff 12


class OwnLink(SimLink):
    """The simulated robot's side: states to the runner's port, commands from it."""

    def __init__(self, cfg: SimRobotCfg, options: dict[str, Any]) -> None:
        self.n = get_robot(cfg.robot).num_joints
        self.runner = (LOOPBACK, int(options["runner_port"]))
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind((LOOPBACK, 0))
        self.sock.setblocking(False)

    def poll(self) -> list[JointCommand | str]:
        out: list[JointCommand | str] = []
        while True:
            try:
                msg = self.sock.recv(1024)
            except BlockingIOError:
                return out
            if msg[:1] != b"C" or len(msg) != _CMD.size:
                self.rejected += 1
                continue
            v = np.asarray(_CMD.unpack(msg)[2:], dtype=np.float64).reshape(5, self.n)
            out.append(JointCommand(v[0], v[1], v[2], v[3], v[4]))

    def publish(self, state: SensorState) -> None:
        s = state
        values = (*s.quat_wxyz, *s.gyro_rad_s, *s.joint_pos_rad, *s.joint_vel_rad_s)
        packet = _STATE.pack(
            b"S",
            s.tick,
            s.time_s,
            s.mono_s,
            *values,
            *s.foot_force_n,
            s.battery_pct,
            s.remote_keys,
        )
        self.sock.sendto(packet, self.runner)

    def close(self) -> None:
        self.sock.close()


class SimUdpRobot(Robot):
    """The runner's side of the own protocol."""

    name = "sim"

    def __init__(self) -> None:
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._sock.bind((LOOPBACK, 0))
        self._sock.setblocking(False)
        self.port = self._sock.getsockname()[1]
        self._robot_addr: tuple[str, int] | None = None
        self._latest: Reading | None = None
        self._cmd_seq = 0

    def start(self, timeout_s: float = 30.0) -> Reading:
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            reading = self.read()
            if reading is not None:
                return reading
            time.sleep(0.005)
        raise QuaddanceError(f"no state from the simulated robot within {timeout_s:g} s")

    def read(self) -> Reading | None:
        # The robot sends at 1 kHz, the runner reads at 50 Hz: of the packets waiting, only
        # the newest is decoded.
        newest, newest_seq = None, -1 if self._latest is None else self._latest.seq
        while True:
            try:
                msg, addr = self._sock.recvfrom(1024)
            except BlockingIOError:
                break
            if msg[:1] != b"S" or len(msg) != _STATE.size:
                continue
            self._robot_addr = addr
            seq = _SEQ.unpack_from(msg)[0]
            if seq > newest_seq:
                newest, newest_seq = msg, seq
        if newest is not None:
            v = _STATE.unpack(newest)
            f = np.asarray(v[4:40], dtype=np.float64)
            self._latest = Reading(
                seq=v[1],
                stamp_s=v[2],
                quat_wxyz=f[0:4],
                gyro_rad_s=f[4:7],
                joint_pos_rad=f[7:19],
                joint_vel_rad_s=f[19:31],
                foot_force_n=f[31:35],
                age_s=time.monotonic() - v[3],
                battery_pct=float(f[35]),
                remote_keys=int(v[40]),
            )
        return self._latest

    def send(self, cmd: JointCommand) -> None:
        if self._robot_addr is None:
            return
        self._cmd_seq += 1
        values = np.concatenate([cmd.q_rad, cmd.dq_rad_s, cmd.kp, cmd.kd, cmd.tau_ff_nm])
        self._sock.sendto(_CMD.pack(b"C", self._cmd_seq, *values), self._robot_addr)

    def close(self) -> None:
        self._sock.close()


def sim_robot(cfg: SimRobotCfg | None = None) -> ProtocolSimRobot:
    """`deploy --robot sim`: the simulated robot over the own protocol."""
    cfg = cfg or SimRobotCfg()
    backend = SimUdpRobot()
    link = {"runner_port": backend.port}
    return ProtocolSimRobot("sim", backend, "quaddance.deploy.sim_backend", cfg, link)


if __name__ == "__main__":
    run_sim_process(OwnLink, description="quaddance's simulated robot, own protocol (internal)")
