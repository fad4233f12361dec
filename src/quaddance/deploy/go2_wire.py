"""The Go2's ``LowCmd_`` and ``LowState_`` (unitree_sdk2, IDL package ``unitree_go``) as bytes.

cyclonedds-python serializes and deserializes these messages in Python, ~0.3-0.6 ms each, and
the SDK computes their CRC by packing every field in Python: at 500 messages a second each
way that took most of a core. Here both are done with `struct`:

- on the wire, cyclonedds's XCDR1 (plain CDR, little-endian): the fields in the IDL's order,
  each aligned to its size from the payload's start, after a 4-byte encapsulation header;
- for the CRC, the SDK's C struct (`unitree_crc.crc32` over it): the same fields in the same
  order, but each nested struct (a motor, the IMU, the battery) also aligned to its widest
  field and padded to a multiple of it.

tests/test_go2_dds.py pins the bytes to cyclonedds's own and the CRC to the SDK's.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from quaddance.deploy.unitree_crc import crc32

XCDR1_LE = b"\x00\x01"  #: encapsulation kind: plain CDR, little-endian (then 2 option bytes)
NUM_MOTOR_SLOTS = 20  #: motor records per message (the Go2 drives 12)

_HEADER = (("2B",), ("B",), ("B",), ("2I",), ("2I",), ("H",))  # head .. bandwidth
_MOTOR_CMD = ("B", "5f", "3I")  # mode, q, dq, tau, kp, kd, reserve
_LOW_CMD = (
    *_HEADER,
    *(_MOTOR_CMD,) * NUM_MOTOR_SLOTS,
    ("B", "3B"),  # bms_cmd
    *(("40B",), ("12B",), ("2B",), ("B",), ("I",), ("I",)),  # wireless_remote .. crc
)
_LOW_STATE = (
    *_HEADER,
    ("4f", "3f", "3f", "3f", "B"),  # imu_state
    *(("B", "7f", "B", "I", "2I"),) * NUM_MOTOR_SLOTS,  # motor_state
    ("B", "B", "B", "B", "i", "H", "2B", "2B", "15H"),  # bms_state
    *(("4h",), ("4h",), ("I",), ("40B",), ("B",), ("f",), ("B",), ("B",)),  # foot_force ..
    *(("f",), ("f",), ("4H",), ("I",), ("I",)),  # power_v .. crc
)


def _layout(groups: Sequence[tuple[str, ...]], c_struct: bool) -> struct.Struct:
    """The struct of fields (struct codes with a count: "4f", "B") grouped as the IDL nests
    them (a nested struct is a group of several): XCDR1, or the C struct (`c_struct`)."""
    fmt, offset = "<", 0

    def pad_to(align: int) -> None:
        nonlocal fmt, offset
        fmt += "x" * (-offset % align)
        offset += -offset % align

    for group in groups:
        sizes = [struct.calcsize("<" + f[-1]) for f in group]
        if c_struct:
            pad_to(max(sizes))
        for f, size in zip(group, sizes, strict=True):
            pad_to(size)
            fmt += f
            offset += int(f[:-1] or 1) * size
        if c_struct:
            pad_to(max(sizes))
    return struct.Struct(fmt)


def _group_starts(groups: Sequence[tuple[str, ...]]) -> list[int]:
    """The index of each group's first value in the unpacked tuple."""
    starts, n = [], 0
    for group in groups:
        starts.append(n)
        n += sum(int(f[:-1] or 1) for f in group)
    return starts


LOW_CMD_CDR, LOW_CMD_C = _layout(_LOW_CMD, False), _layout(_LOW_CMD, True)
LOW_STATE_CDR, LOW_STATE_C = _layout(_LOW_STATE, False), _layout(_LOW_STATE, True)
_MOTORS_AT = 9  #: values before the first motor (head .. bandwidth)
_MOTOR_CMD_VALUES = 9  #: values per motor command
_STATE_AT = _group_starts(_LOW_STATE)
_IMU_AT = _STATE_AT[len(_HEADER)]
_STATE_MOTORS_AT = _STATE_AT[len(_HEADER) + 1]
_MOTOR_STATE_VALUES = _STATE_AT[len(_HEADER) + 2] - _STATE_MOTORS_AT
_BMS_AT = _STATE_AT[len(_HEADER) + 1 + NUM_MOTOR_SLOTS]
_FOOT_FORCE_AT = _STATE_AT[len(_HEADER) + 2 + NUM_MOTOR_SLOTS]
_TICK_AT = _FOOT_FORCE_AT + 8  #: after foot_force[4] and foot_force_est[4]


def _sealed(values: list, cdr: struct.Struct, c_struct: struct.Struct) -> tuple[int, bytes]:
    """The SDK's CRC of a message's values (the last one, its CRC field, not covered) and
    the message serialized with that CRC."""
    values[-1] = crc32(c_struct.pack(*values))
    return values[-1], XCDR1_LE + b"\x00\x00" + cdr.pack(*values)


def seal_low_cmd(msg: Any) -> bytes:
    """Set a ``LowCmd_``'s CRC to the SDK's and return it as cyclonedds serializes it."""
    values = [*msg.head, msg.level_flag, msg.frame_reserve, *msg.sn, *msg.version]
    values.append(msg.bandwidth)
    for m in msg.motor_cmd:
        values += [m.mode, m.q, m.dq, m.tau, m.kp, m.kd, *m.reserve]
    values += [msg.bms_cmd.off, *msg.bms_cmd.reserve, *msg.wireless_remote, *msg.led]
    values += [*msg.fan, msg.gpio, msg.reserve, msg.crc]
    msg.crc, wire = _sealed(values, LOW_CMD_CDR, LOW_CMD_C)
    return wire


def seal_low_state(msg: Any) -> bytes:
    """Set a ``LowState_``'s CRC to the SDK's and return it as cyclonedds serializes it."""
    i, b = msg.imu_state, msg.bms_state
    values = [*msg.head, msg.level_flag, msg.frame_reserve, *msg.sn, *msg.version]
    values += [msg.bandwidth, *i.quaternion, *i.gyroscope, *i.accelerometer, *i.rpy]
    values.append(i.temperature)
    for m in msg.motor_state:
        values += [m.mode, m.q, m.dq, m.ddq, m.tau_est, m.q_raw, m.dq_raw, m.ddq_raw]
        values += [m.temperature, m.lost, *m.reserve]
    values += [b.version_high, b.version_low, b.status, b.soc, b.current, b.cycle]
    values += [*b.bq_ntc, *b.mcu_ntc, *b.cell_vol, *msg.foot_force, *msg.foot_force_est]
    values += [msg.tick, *msg.wireless_remote, msg.bit_flag, msg.adc_reel]
    values += [msg.temperature_ntc1, msg.temperature_ntc2, msg.power_v, msg.power_a]
    values += [*msg.fan_frequency, msg.reserve, msg.crc]
    msg.crc, wire = _sealed(values, LOW_STATE_CDR, LOW_STATE_C)
    return wire


@dataclass
class LowCmdMotors:
    """The motor commands of a serialized ``LowCmd_``, per motor slot (SDK order)."""

    crc_ok: bool  #: its CRC field is the SDK's CRC of the rest
    mode: np.ndarray  #: (20,)
    q: np.ndarray  #: (20,) rad
    dq: np.ndarray  #: (20,) rad/s
    tau: np.ndarray  #: (20,) N m
    kp: np.ndarray  #: (20,) N m / rad
    kd: np.ndarray  #: (20,) N m s / rad


def decode_low_cmd(data: bytes) -> LowCmdMotors | None:
    """A ``LowCmd_`` from its serialized bytes (with the encapsulation header, as a reader
    takes them); None if they are not one in XCDR1, little-endian."""
    if data[:2] != XCDR1_LE or len(data) < 4 + LOW_CMD_CDR.size:
        return None
    values = LOW_CMD_CDR.unpack_from(data, 4)
    end = _MOTORS_AT + NUM_MOTOR_SLOTS * _MOTOR_CMD_VALUES
    motors = np.array(values[_MOTORS_AT:end], dtype=np.float64).reshape(NUM_MOTOR_SLOTS, -1)
    mode, q, dq, tau, kp, kd = motors[:, :6].T
    crc_ok = values[-1] == crc32(LOW_CMD_C.pack(*values))
    return LowCmdMotors(crc_ok, mode, q, dq, tau, kp, kd)


@dataclass
class LowStateFields:
    """What a controller reads of a serialized ``LowState_`` (SDK motor and foot order)."""

    crc_ok: bool  #: its CRC field is the SDK's CRC of the rest
    tick: int  #: the robot's clock, ms
    quat_wxyz: np.ndarray  #: (4,) IMU orientation
    gyro_rad_s: np.ndarray  #: (3,)
    q: np.ndarray  #: (20,) rad
    dq: np.ndarray  #: (20,) rad/s
    foot_force: np.ndarray  #: (4,) the sensors' raw units
    soc: int  #: battery state of charge, %
    wireless_remote: bytes  #: (40,) the remote's raw bytes


def decode_low_state(data: bytes) -> LowStateFields | None:
    """A ``LowState_`` from its serialized bytes, as a reader takes them (with the
    encapsulation header): ~20 us with struct, where cyclonedds-python's deserializing takes
    ~0.3 ms. None if they are not one in XCDR1, little-endian."""
    if data[:2] != XCDR1_LE or len(data) < 4 + LOW_STATE_CDR.size:
        return None
    values = LOW_STATE_CDR.unpack_from(data, 4)
    end = _STATE_MOTORS_AT + NUM_MOTOR_SLOTS * _MOTOR_STATE_VALUES
    motors = np.array(values[_STATE_MOTORS_AT:end], dtype=np.float64)
    motors = motors.reshape(NUM_MOTOR_SLOTS, _MOTOR_STATE_VALUES)
    return LowStateFields(
        crc_ok=values[-1] == crc32(LOW_STATE_C.pack(*values)),
        tick=int(values[_TICK_AT]),
        quat_wxyz=np.array(values[_IMU_AT : _IMU_AT + 4], dtype=np.float64),
        gyro_rad_s=np.array(values[_IMU_AT + 4 : _IMU_AT + 7], dtype=np.float64),
        q=motors[:, 1].copy(),
        dq=motors[:, 2].copy(),
        foot_force=np.array(values[_FOOT_FORCE_AT : _FOOT_FORCE_AT + 4], dtype=np.float64),
        soc=int(values[_BMS_AT + 3]),
        wireless_remote=bytes(values[_TICK_AT + 1 : _TICK_AT + 41]),
    )
