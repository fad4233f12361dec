"""The vendor's wireless remote as the Go1 and the Go2 report it in LowState.

Both robots carry the remote in a 40-byte ``wirelessRemote`` field with one layout
(unitree_legged_sdk's and unitree_sdk2's ``xRockerBtnDataStruct``): 2 header bytes, the
buttons as a little-endian 16-bit mask, the sticks as floats (lx, rx, ry, L2, ly), 16 idle
bytes. quaddance reads only the buttons; `DAMP_KEYS` (L2 + B, the vendors' own damping
combination) damps the robot at once during a run.
"""

from __future__ import annotations

import struct

REMOTE_BYTES = 40
_BUTTONS = struct.Struct("<2xH")  #: header, then the button mask

# Bit of each button in the mask, in the vendors' order.
KEY_R1, KEY_L1, KEY_START, KEY_SELECT, KEY_R2, KEY_L2, KEY_F1, KEY_F2 = (1 << i for i in range(8))
KEY_A, KEY_B, KEY_X, KEY_Y, KEY_UP, KEY_RIGHT, KEY_DOWN, KEY_LEFT = (1 << i for i in range(8, 16))

DAMP_KEYS = KEY_L2 | KEY_B  #: held together: damping now, whatever the dance is doing


def decode_remote(data: bytes | bytearray | list[int]) -> int:
    """The mask of the buttons held, from a LowState's ``wirelessRemote`` (0 for a short or
    empty field: a robot with no remote paired reports zeros)."""
    raw = bytes(bytearray(data))
    if len(raw) < _BUTTONS.size:
        return 0
    return int(_BUTTONS.unpack_from(raw)[0])


def encode_remote(keys: int) -> bytes:
    """A ``wirelessRemote`` field with ``keys`` held and the sticks centred."""
    out = bytearray(REMOTE_BYTES)
    _BUTTONS.pack_into(out, 0, keys & 0xFFFF)
    return bytes(out)


def damp_pressed(keys: int) -> bool:
    """Whether the damping combination is held."""
    return keys & DAMP_KEYS == DAMP_KEYS
