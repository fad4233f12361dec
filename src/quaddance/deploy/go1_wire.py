"""The Go1's low-level UDP datagrams as unitree_legged_sdk 3.8 puts them on the wire.

The SDK does not send its C structs (``comm.h``'s ``LowCmd`` is 734 bytes, ``LowState`` 937):
``UDP::SetSend`` packs a ``LowCmd`` into a 614-byte datagram and ``UDP::GetRecv`` unpacks an
807-byte ``LowState`` datagram, with some fields as scaled integers. The layouts below were
read from the SDK's headers and its packing code, and pinned by sending every field through
the SDK's Python binding on 127.0.0.1 (tests/test_go1_wire.py).

Little-endian, packed. Both datagrams open with the same 22-byte header (head ``fe ef``,
levelFlag ``ff`` for low level, frameReserve, SN[2], version[2], bandWidth) and close with a
reserved uint32 and the CRC (`quaddance.deploy.unitree_crc.crc32`). Each carries 20 motor
slots; the Go1 uses the first 12, in the SDK's motor order (FR, FL, RR, RL x hip, thigh, calf).

On receive the SDK's socket is connected to the robot's address, so it takes states from that
address and port only; of the datagrams queued it keeps the newest. It drops one whose head
is not ``fe ef`` or whose CRC does not match (counting a CRC error, keeping the previous
state); it does not check levelFlag; it reads at most its 807 bytes and takes the CRC from the
last 4 of them, so a shorter datagram fails the CRC and a longer one is cut.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np

from quaddance.deploy.go1_backend import LOWLEVEL, SERVO_MODE
from quaddance.deploy.simulator import rpy_from_quat
from quaddance.deploy.unitree_crc import crc32

HEAD = b"\xfe\xef"
NUM_MOTOR_SLOTS = 20  #: motor records per datagram (the Go1 drives 12)
#: ``comm.h``: a motor command with this target position (velocity) turns its position
#: (velocity) loop off.
POS_STOP_F = 2.146e9
VEL_STOP_F = 16000.0

#: head[2], levelFlag, frameReserve, SN[2], version[2], bandWidth
HEADER = struct.Struct("<2sBB2I2IH")

# LowCmd, 614 bytes.
#: mode, q, dq, then tau, Kp, Kd as int16 / uint16 / uint16 of tau * 256, Kp * 32, Kd * 16
#: (truncated toward zero, wrapping), then reserve[3]
MOTOR_CMD = struct.Struct("<BffhHH12x")
TAU_SCALE, KP_SCALE, KD_SCALE = 256.0, 32.0, 16.0
CMD_MOTORS_AT = HEADER.size  # 22
CMD_MOTORS = struct.Struct("<" + MOTOR_CMD.format[1:] * NUM_MOTOR_SLOTS)  #: all slots
CMD_BMS_AT = CMD_MOTORS_AT + NUM_MOTOR_SLOTS * MOTOR_CMD.size  # 562: BmsCmd off, reserve[3]
CMD_REMOTE_AT = CMD_BMS_AT + 4  # 566: wirelessRemote[40]
CMD_CRC_AT = CMD_REMOTE_AT + 40 + 4  # 610, after a reserved uint32
LOW_CMD_LENGTH = CMD_CRC_AT + 4  # 614

# LowState, 807 bytes.
#: quaternion (w x y z), gyroscope, accelerometer, rpy, temperature
IMU = struct.Struct("<4f3f3f3fb")
IMU_AT = HEADER.size  # 22
#: mode, q, dq, ddq (int16), tauEst (int16 of tauEst * 256), q_raw, dq_raw, ddq_raw (int16),
#: temperature, reserve[2]
MOTOR_STATE = struct.Struct("<Bffhhffhb8x")
TAU_EST_SCALE = 256.0
STATE_MOTORS_AT = IMU_AT + IMU.size  # 75
STATE_MOTORS = struct.Struct("<" + MOTOR_STATE.format[1:] * NUM_MOTOR_SLOTS)  #: all slots
#: BmsState: version_h, version_l, bms_status, SOC (%), current (mA), cycle, BQ_NTC[2],
#: MCU_NTC[2], cell_vol[10] (one byte each: mV / 32)
BMS_STATE = struct.Struct("<BBBBiH2b2b10B")
STATE_BMS_AT = STATE_MOTORS_AT + NUM_MOTOR_SLOTS * MOTOR_STATE.size  # 715
BMS_SOC_AT = STATE_BMS_AT + 3  # 718
#: footForce[4], footForceEst[4] (int16, SDK foot order FR, FL, RR, RL), tick (ms),
#: wirelessRemote[40], reserve
STATE_TAIL = struct.Struct("<4h4hI40s4x")
STATE_TAIL_AT = STATE_BMS_AT + BMS_STATE.size  # 739
STATE_CRC_AT = STATE_TAIL_AT + STATE_TAIL.size  # 803
LOW_STATE_LENGTH = STATE_CRC_AT + 4  # 807

CRC = struct.Struct("<I")
_INT16_MIN, _INT16_MAX = -0x8000, 0x7FFF
_UNUSED_MOTOR_STATE = (0, 0.0, 0.0, 0, 0, 0.0, 0.0, 0, 0)


class WireError(ValueError):
    """A datagram that cannot be a Go1 low-level message."""


def _with_crc(buf: bytearray, crc_at: int) -> bytes:
    CRC.pack_into(buf, crc_at, crc32(bytes(buf)))
    return bytes(buf)


@dataclass
class LowCmdFrame:
    """A decoded LowCmd datagram: per motor slot (SDK order), as the motor boards read them."""

    head: bytes
    level_flag: int
    crc_ok: bool
    mode: np.ndarray  #: (20,) uint8: SERVO_MODE (0x0A) or idle
    q: np.ndarray  #: (20,) rad
    dq: np.ndarray  #: (20,) rad/s
    kp: np.ndarray  #: (20,) N m / rad
    kd: np.ndarray  #: (20,) N m s / rad
    tau: np.ndarray  #: (20,) N m
    wireless_remote: bytes

    @property
    def valid(self) -> bool:
        """A low-level command the robot accepts: the SDK's head and flag, the CRC matching."""
        return self.crc_ok and self.head == HEAD and self.level_flag == LOWLEVEL


def decode_low_cmd(data: bytes) -> LowCmdFrame:
    """The fields of a LowCmd datagram; `WireError` when it is not 614 bytes long."""
    if len(data) != LOW_CMD_LENGTH:
        raise WireError(f"LowCmd datagram of {len(data)} bytes, expected {LOW_CMD_LENGTH}")
    head, level_flag, *_ = HEADER.unpack_from(data)
    motors = np.array(CMD_MOTORS.unpack_from(data, CMD_MOTORS_AT), dtype=np.float64)
    mode, q, dq, tau, kp, kd = motors.reshape(NUM_MOTOR_SLOTS, -1).T
    (crc,) = CRC.unpack_from(data, CMD_CRC_AT)
    return LowCmdFrame(
        head=head,
        level_flag=level_flag,
        crc_ok=crc == crc32(data),
        mode=mode.astype(np.uint8),
        q=q,
        dq=dq,
        kp=kp / KP_SCALE,
        kd=kd / KD_SCALE,
        tau=tau / TAU_SCALE,
        wireless_remote=data[CMD_REMOTE_AT : CMD_REMOTE_AT + 40],
    )


def encode_low_state(
    tick: int,
    quat_wxyz: np.ndarray,
    gyro_rad_s: np.ndarray,
    accel_m_s2: np.ndarray,
    q: np.ndarray,
    dq: np.ndarray,
    tau_est: np.ndarray,
    foot_force: np.ndarray,
    wireless_remote: bytes,
    battery_soc: int,
) -> bytes:
    """A LowState datagram as a Go1 sends it, with its CRC.

    Motors (q rad, dq rad/s, tau_est N m) in SDK order fill the first slots, reported in servo
    mode; ``foot_force`` (4,) in the SDK's foot order, in the sensor's units (int16);
    ``wireless_remote`` the remote's 40 bytes; ``battery_soc`` the state of charge, % (uint8).
    The IMU's rpy is derived from the quaternion, as the robot reports it.
    """
    if len(wireless_remote) != 40:
        raise WireError(f"wirelessRemote must be 40 bytes, got {len(wireless_remote)}")
    buf = bytearray(LOW_STATE_LENGTH)
    HEADER.pack_into(buf, 0, HEAD, LOWLEVEL, 0, 0, 0, 0, 0, 0)
    quat = [float(v) for v in quat_wxyz]
    imu = (*quat, *map(float, gyro_rad_s), *map(float, accel_m_s2), *rpy_from_quat(quat))
    IMU.pack_into(buf, IMU_AT, *imu, 0)
    tau_int = np.trunc(np.asarray(tau_est, dtype=np.float64) * TAU_EST_SCALE)
    motors: list[float | int] = []
    for qi, dqi, ti in zip(q, dq, tau_int.tolist(), strict=True):
        motors += (SERVO_MODE, float(qi), float(dqi), 0, _int16(ti), 0.0, 0.0, 0, 0)
    motors += _UNUSED_MOTOR_STATE * (NUM_MOTOR_SLOTS - len(tau_int))
    STATE_MOTORS.pack_into(buf, STATE_MOTORS_AT, *motors)
    buf[BMS_SOC_AT] = battery_soc
    force = [_int16(round(float(f))) for f in foot_force]
    STATE_TAIL.pack_into(buf, STATE_TAIL_AT, *force, 0, 0, 0, 0, tick, wireless_remote)
    return _with_crc(buf, STATE_CRC_AT)


def _int16(value: float) -> int:
    """``value`` saturated to int16."""
    return int(min(max(value, _INT16_MIN), _INT16_MAX))
