"""The Go1's low-level UDP wire format, pinned against unitree_legged_sdk 3.8's own binding.

Everything runs on 127.0.0.1 with free ports; nothing is sent to a robot's address.
"""

from __future__ import annotations

import dataclasses
import socket
import struct
import threading
import time

import numpy as np
import pytest

from quaddance.deploy import go1_wire as wire
from quaddance.deploy.go1_backend import Go1Robot
from quaddance.deploy.go1_sim import Go1UdpLink, free_udp_port, go1_sim_robot
from quaddance.deploy.remote import DAMP_KEYS
from quaddance.deploy.robot import JointCommand
from quaddance.deploy.simulator import SensorState
from quaddance.robots import GO1

sdk = pytest.importorskip(
    "unitree_legged_sdk.robot_interface",
    reason="unitree-legged-sdk not installed (pip install 'quaddance[go1]')",
)

LOCALHOST = "127.0.0.1"


@pytest.fixture
def robot_socket():
    """A plain UDP socket standing where the robot would be."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind((LOCALHOST, 0))
        s.settimeout(2.0)
        yield s


@pytest.fixture
def sdk_udp(robot_socket):
    """The SDK's low-level UDP object, its target the robot socket; (udp, its local port)."""
    local_port = free_udp_port()
    udp = sdk.UDP(wire.LOWLEVEL, local_port, LOCALHOST, robot_socket.getsockname()[1])
    yield udp, local_port
    del udp


def sdk_low_cmd_datagram(udp, robot_socket, low_cmd) -> bytes:
    udp.SetSend(low_cmd)
    udp.Send()
    return robot_socket.recvfrom(4096)[0]


def test_layout_sizes_and_offsets():
    assert (wire.HEADER.size, wire.MOTOR_CMD.size, wire.MOTOR_STATE.size) == (22, 27, 32)
    assert (wire.IMU.size, wire.BMS_STATE.size, wire.STATE_TAIL.size) == (53, 24, 64)
    assert (wire.CMD_MOTORS_AT, wire.CMD_BMS_AT, wire.CMD_REMOTE_AT) == (22, 562, 566)
    assert (wire.CMD_CRC_AT, wire.LOW_CMD_LENGTH) == (610, 614)
    assert (wire.IMU_AT, wire.STATE_MOTORS_AT, wire.STATE_BMS_AT, wire.BMS_SOC_AT) == (
        22,
        75,
        715,
        718,
    )
    assert (wire.STATE_TAIL_AT, wire.STATE_CRC_AT, wire.LOW_STATE_LENGTH) == (739, 803, 807)


def test_sdk_low_cmd_decodes_to_every_field(sdk_udp, robot_socket):
    udp, _ = sdk_udp
    low = sdk.LowCmd()
    udp.InitCmdData(low)
    # Distinct values per slot, each exact on the wire (tau in 1/256, Kp in 1/32, Kd in 1/16).
    for i in range(wire.NUM_MOTOR_SLOTS):
        m = low.motorCmd[i]
        m.mode = wire.SERVO_MODE if i % 3 else i
        m.q = 0.25 * i - 2.0
        m.dq = -0.5 * i + 1.0
        m.tau = (37 * i - 300) / 256
        m.Kp = (51 * i + 3) / 32
        m.Kd = (7 * i + 1) / 16
    data = sdk_low_cmd_datagram(udp, robot_socket, low)
    assert len(data) == wire.LOW_CMD_LENGTH
    frame = wire.decode_low_cmd(data)
    assert frame.crc_ok and frame.valid
    assert frame.head == b"\xfe\xef" and frame.level_flag == 0xFF
    for i in range(wire.NUM_MOTOR_SLOTS):
        m = low.motorCmd[i]
        sent = (m.mode, m.q, m.dq, m.Kp, m.Kd, m.tau)
        got = (frame.mode[i], frame.q[i], frame.dq[i], frame.kp[i], frame.kd[i], frame.tau[i])
        assert got == sent, f"motor slot {i}"


def test_sdk_packs_tau_kp_kd_as_truncated_fixed_point(sdk_udp, robot_socket):
    udp, _ = sdk_udp
    low = sdk.LowCmd()
    udp.InitCmdData(low)
    low.motorCmd[0].tau, low.motorCmd[0].Kp, low.motorCmd[0].Kd = -0.3, 20.3, 0.55
    low.motorCmd[1].tau = 200.0  # past int16 / 256: wraps, as the SDK's C casts do
    frame = wire.decode_low_cmd(sdk_low_cmd_datagram(udp, robot_socket, low))
    assert (frame.tau[0], frame.kp[0], frame.kd[0]) == (-76 / 256, 649 / 32, 8 / 16)
    assert frame.tau[1] == -56.0


def test_crc_is_the_sdks_and_a_bad_one_is_seen(sdk_udp, robot_socket):
    udp, _ = sdk_udp
    low = sdk.LowCmd()
    udp.InitCmdData(low)
    data = sdk_low_cmd_datagram(udp, robot_socket, low)
    assert struct.unpack_from("<I", data, wire.CMD_CRC_AT)[0] == wire.crc32(data)
    corrupt = bytearray(data)
    corrupt[wire.CMD_MOTORS_AT + 1] ^= 0x01
    frame = wire.decode_low_cmd(bytes(corrupt))
    assert not frame.crc_ok and not frame.valid
    with pytest.raises(wire.WireError):
        wire.decode_low_cmd(data[:-1])


RPY_RAD = (0.3, -0.2, 0.5)


def _quat_from_rpy(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """w x y z of the Z-Y-X rotation (yaw, then pitch, then roll)."""
    cr, sr = np.cos(roll / 2), np.sin(roll / 2)
    cp, sp = np.cos(pitch / 2), np.sin(pitch / 2)
    cy, sy = np.cos(yaw / 2), np.sin(yaw / 2)
    return np.array(
        [
            cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
        ]
    )


def _state_kwargs(tick: int) -> dict:
    i = np.arange(12)
    return dict(
        tick=tick,
        quat_wxyz=_quat_from_rpy(*RPY_RAD),
        gyro_rad_s=np.array([0.5, -1.25, 2.0]),
        accel_m_s2=np.array([0.25, -0.75, 9.5]),
        q=0.125 * i - 0.75,
        dq=-0.375 * i + 1.5,
        tau_est=(29 * i - 150) / 256,
        foot_force=np.array([11, -22, 33, 444]),
        wireless_remote=bytes(range(100, 140)),
        battery_soc=77,
    )


def _sdk_receives(udp, local_port: int, robot_socket, data: bytes, state) -> int:
    """Send ``data`` from the robot's address (the SDK's socket is connected to it and takes
    nothing from elsewhere); the SDK's receive code and what it decoded into ``state``."""
    robot_socket.sendto(data, (LOCALHOST, local_port))
    time.sleep(0.02)
    rc = udp.Recv()
    udp.GetRecv(state)
    return rc


def test_state_encoded_here_decodes_in_the_sdk_to_every_field(sdk_udp, robot_socket):
    udp, local_port = sdk_udp
    kw = _state_kwargs(tick=4242)
    data = wire.encode_low_state(**kw)
    assert len(data) == wire.LOW_STATE_LENGTH
    state = sdk.LowState()
    assert _sdk_receives(udp, local_port, robot_socket, data, state) == 0
    f32 = lambda a: np.asarray(a, dtype=np.float32).tolist()  # noqa: E731
    assert state.tick == 4242
    assert state.imu.quaternion == f32(kw["quat_wxyz"])
    assert state.imu.gyroscope == f32(kw["gyro_rad_s"])
    assert state.imu.accelerometer == f32(kw["accel_m_s2"])
    np.testing.assert_allclose(state.imu.rpy, RPY_RAD, atol=1e-6)
    motors = [state.motorState[i] for i in range(12)]
    assert [m.q for m in motors] == f32(kw["q"])
    assert [m.dq for m in motors] == f32(kw["dq"])
    assert [m.tauEst for m in motors] == f32(kw["tau_est"])
    assert all(m.mode == wire.SERVO_MODE for m in motors)
    assert list(state.footForce) == kw["foot_force"].tolist()
    assert bytes(state.wirelessRemote) == kw["wireless_remote"]
    assert state.bms.SOC == 77


def test_what_the_sdk_checks_on_receive(sdk_udp, robot_socket):
    udp, local_port = sdk_udp
    state = sdk.LowState()
    good = wire.encode_low_state(**_state_kwargs(tick=1))
    assert _sdk_receives(udp, local_port, robot_socket, good, state) == 0
    bad_crc = bytearray(wire.encode_low_state(**_state_kwargs(tick=2)))
    bad_crc[wire.STATE_CRC_AT] ^= 0x01
    bad_head = bytearray(wire.encode_low_state(**_state_kwargs(tick=3)))
    bad_head[0] = 0
    short = wire.encode_low_state(**_state_kwargs(tick=4))[:-1]
    for data, rc in ((bad_crc, -3), (bad_head, -1), (short, -3)):
        assert _sdk_receives(udp, local_port, robot_socket, bytes(data), state) == rc
        assert state.tick == 1
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as elsewhere:
        elsewhere.bind((LOCALHOST, 0))
        good_elsewhere = wire.encode_low_state(**_state_kwargs(tick=5))
        assert _sdk_receives(udp, local_port, elsewhere, good_elsewhere, state) == -1
    assert state.tick == 1
    # What it does not check: levelFlag (with the CRC made right), the bytes past its 807.
    other_level = bytearray(wire.encode_low_state(**_state_kwargs(tick=6)))
    other_level[2] = 0x12
    struct.pack_into("<I", other_level, wire.STATE_CRC_AT, wire.crc32(bytes(other_level)))
    assert _sdk_receives(udp, local_port, robot_socket, bytes(other_level), state) == 0
    assert state.tick == 6
    long = wire.encode_low_state(**_state_kwargs(tick=7)) + bytes(8)
    assert _sdk_receives(udp, local_port, robot_socket, long, state) == 0
    assert state.tick == 7


# --- the go1-sim link: the robot's side of the wire ------------------------------------------

# Left and right legs swapped, hips mirrored, feet shuffled: maps that are not the identity,
# so both sides must use the same tables (hips are symmetric, so the SDK's PositionLimit
# keeps the values).
MIRRORED = dataclasses.replace(
    GO1,
    sdk_joint_index=(3, 4, 5, 0, 1, 2, 9, 10, 11, 6, 7, 8),
    sdk_joint_sign=(-1.0, 1.0, 1.0) * 4,
    sdk_foot_index=(2, 0, 3, 1),
)


def sensor_state(tick: int) -> SensorState:
    """Distinct values in every field the Go1's LowState carries."""
    i = np.arange(12)
    return SensorState(
        tick=tick,
        time_s=0.002 * tick,
        mono_s=time.monotonic(),
        quat_wxyz=_quat_from_rpy(*RPY_RAD),
        gyro_rad_s=np.array([0.5, -1.25, 2.0]),
        accel_m_s2=np.array([0.25, -0.75, 9.5]),
        joint_pos_rad=np.asarray(GO1.nominal_joint_pos_rad) + 0.01 * i,
        joint_vel_rad_s=0.125 * i - 0.5,
        joint_tau_nm=(29 * i - 150) / 256,
        foot_force_n=np.array([10.0, 20.0, 30.0, 40.0]),
        battery_pct=64.0,
        remote_keys=DAMP_KEYS,
    )


@pytest.fixture
def link():
    link = Go1UdpLink(MIRRORED, free_udp_port())
    yield link
    link.close()


def test_link_refuses_bad_datagrams_and_idles_motors_out_of_servo_mode(link, sdk_udp, robot_socket):
    udp, _ = sdk_udp
    low = sdk.LowCmd()
    udp.InitCmdData(low)
    for i in range(12):
        m = low.motorCmd[i]
        m.mode = 0 if i == 4 else wire.SERVO_MODE  # SDK motor 4: model joint 1 (FR thigh)
        m.q, m.dq, m.Kp, m.Kd, m.tau = 0.5, 0.25, 20.0, 0.5, 1.0
    low.motorCmd[6].q = wire.POS_STOP_F  # model joint 9 (RL hip): its position loop off
    good = sdk_low_cmd_datagram(udp, robot_socket, low)
    bad_crc = bytearray(good)
    bad_crc[wire.CMD_MOTORS_AT + 2] ^= 0x10
    high_level = bytearray(good)
    high_level[2] = 0xEE
    struct.pack_into("<I", high_level, wire.CMD_CRC_AT, wire.crc32(bytes(high_level)))
    assert link.peer is None
    link.publish(sensor_state(tick=1))  # before any command nobody is answered: no error
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sender:
        for data in (bytes(bad_crc), good[:-2], good + bytes(4), bytes(high_level), good):
            sender.sendto(data, (LOCALHOST, link.port))
        time.sleep(0.02)
        (cmd,) = link.poll()
        assert link.rejected == 4
        assert link.peer == (LOCALHOST, sender.getsockname()[1])
    sign = np.array(MIRRORED.sdk_joint_sign)
    servo = np.ones(12)
    servo[1] = 0
    position = servo.copy()
    position[9] = 0
    np.testing.assert_array_equal(cmd.q_rad, 0.5 * sign * position)
    np.testing.assert_array_equal(cmd.kp, 20 * position)
    np.testing.assert_array_equal(cmd.dq_rad_s, 0.25 * sign * servo)
    np.testing.assert_array_equal(cmd.kd, 0.5 * servo)
    np.testing.assert_array_equal(cmd.tau_ff_nm, sign * servo)


def test_go1_backend_drives_the_link_through_the_sdk(link):
    """The real robot's `Go1Robot` (the SDK binding, its PositionLimit and PowerProtect) against
    the link: commands and states cross the wire with the joint map both sides share."""
    robot = Go1Robot(robot_ip=LOCALHOST, robot_port=link.port, local_port=free_udp_port())
    robot.robot_cfg = MIRRORED
    state = sensor_state(tick=1)
    received: list[JointCommand] = []
    stop = threading.Event()

    def robot_side() -> None:  # the simulated robot's loop: commands in, a state out
        while not stop.is_set():
            received.extend(link.poll())
            state.tick += 1
            state.time_s += 0.002
            link.publish(state)
            time.sleep(0.002)

    thread = threading.Thread(target=robot_side, daemon=True)
    thread.start()
    try:
        first = robot.start(timeout_s=5.0)
        # Before the runner's first command the SDK sends its initial one: no torque.
        assert received and not any(
            np.any(c.kp) or np.any(c.kd) or np.any(c.tau_ff_nm) for c in received
        )
        i = np.arange(12)
        sent = JointCommand(
            q_rad=np.asarray(GO1.nominal_joint_pos_rad) + 0.02 * i - 0.1,
            dq_rad_s=0.25 * i - 1.0,
            kp=(640 + 3 * i) / 32,
            kd=(8 + i) / 16,
            tau_ff_nm=(37 * i - 200) / 256,
        )
        robot.send(sent)
        end = time.monotonic() + 2.0
        while time.monotonic() < end and not (received and np.any(received[-1].kp)):
            time.sleep(0.01)
        reading = robot.read()
    finally:
        robot.close()
        stop.set()
        thread.join(timeout=1.0)
    assert robot.power_protect_trips == 0
    got = received[-1]
    np.testing.assert_allclose(got.q_rad, sent.q_rad, rtol=0, atol=1e-6)  # float32 on the wire
    np.testing.assert_allclose(got.dq_rad_s, sent.dq_rad_s, rtol=0, atol=1e-6)
    np.testing.assert_array_equal(got.kp, sent.kp)
    np.testing.assert_array_equal(got.kd, sent.kd)
    np.testing.assert_array_equal(got.tau_ff_nm, sent.tau_ff_nm)
    assert link.rejected == 0
    for r in (first, reading):
        assert r.seq > 2 and r.stamp_s == r.seq / 1000  # the robot's clock, ms
        np.testing.assert_allclose(r.joint_pos_rad, state.joint_pos_rad, rtol=0, atol=1e-6)
        np.testing.assert_allclose(r.joint_vel_rad_s, state.joint_vel_rad_s, rtol=0, atol=1e-6)
        np.testing.assert_allclose(r.quat_wxyz, state.quat_wxyz, rtol=0, atol=1e-6)
        np.testing.assert_allclose(r.gyro_rad_s, state.gyro_rad_s, rtol=0, atol=1e-6)
        np.testing.assert_array_equal(r.foot_force_n, state.foot_force_n)
        assert (r.battery_pct, r.remote_keys) == (64.0, DAMP_KEYS)


def test_go1_sim_process_answers_the_backend_and_counts_what_it_applied():
    """``python -m quaddance.deploy.go1_sim`` behind `ProtocolSimRobot`, driven by `Go1Robot`."""
    robot = go1_sim_robot()
    try:
        first = robot.start(timeout_s=30.0)
        assert (first.battery_pct, first.remote_keys) == (90.0, 0)
        assert robot.press(DAMP_KEYS)
        damping = JointCommand.damping(first.joint_pos_rad, GO1.safety_limits.damp_kd)
        end = time.monotonic() + 0.5
        while time.monotonic() < end:
            robot.send(damping)
            time.sleep(0.02)
        reading = robot.read()
    finally:
        robot.close()
    assert reading.seq > first.seq and reading.remote_keys == DAMP_KEYS
    counts = robot.received()
    assert counts["torque_commands"] > 0 and counts["rejected"] == 0
    assert counts["commands"] > counts["torque_commands"]  # the SDK's idle ones came first
    assert reading.seq in np.rint(robot.truth()["time_s"] * 1e3)  # the robot's clock, ms


def test_a_taken_local_port_is_named_not_called_a_network_fault():
    """The SDK binds its local port for the robot's replies; taken, it printed a line and no
    state came, which read as "no state from the Go1 ... (network set-up)"."""
    from quaddance.errors import QuaddanceError

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as holder:
        holder.bind((LOCALHOST, 0))
        port = holder.getsockname()[1]
        robot = Go1Robot(robot_ip=LOCALHOST, robot_port=free_udp_port(), local_port=port)
        with pytest.raises(QuaddanceError, match=rf"local UDP port {port}, which the Go1 SDK"):
            robot.start(timeout_s=0.5)
