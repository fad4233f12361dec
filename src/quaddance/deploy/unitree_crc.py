"""The CRC that Unitree's low-level SDKs put in their messages' last word: the Go1's UDP
datagrams (unitree_legged_sdk) and the Go2's ``LowCmd_`` / ``LowState_`` (unitree_sdk2)."""

from __future__ import annotations

import zlib

import numpy as np

_BIT_REVERSED_BYTES = bytes(int(f"{b:08b}"[::-1], 2) for b in range(256))


def crc32(data: bytes) -> int:
    """The SDKs' CRC of a message packed as their C struct (the value stored in its last 4
    bytes).

    The SDKs run CRC-32/MPEG-2 (polynomial 0x04C11DB7, initial value 0xFFFFFFFF, no
    reflection, no final XOR) over the message as little-endian 32-bit words, each word's bits
    most significant first, covering ``len(data) // 4 - 1`` words: the CRC field and, for a
    length that is not a multiple of 4, the bytes before it are not covered. zlib's CRC-32 is
    the reflected form of the same polynomial, so it gives the same value on bit-reversed
    words, bit-reversed back: in C, ~20 times faster than the SDK's bit loop through ctypes.
    """
    n_words = len(data) // 4 - 1
    words = np.frombuffer(data, dtype="<u4", count=n_words).byteswap().tobytes()
    reflected = zlib.crc32(words.translate(_BIT_REVERSED_BYTES)) ^ 0xFFFFFFFF
    return int(f"{reflected:032b}"[::-1], 2)
