"""Catalogue CRCs used by the wire protocols, computed by the C routines of the standard library."""

from __future__ import annotations

import binascii
import zlib

# Byte -> the same byte with its bits in reverse order.
_REFLECT = bytes(int(f"{i:08b}"[::-1], 2) for i in range(256))


def crc32_mpeg2(data: bytes) -> int:
    """CRC-32/MPEG-2: poly 0x04C11DB7, init 0xFFFFFFFF, no reflection, xorout 0 (check 0x0376E6E7).

    zlib's CRC-32 is the reflected form of the same polynomial and init, so feeding it bit-reversed
    bytes and reversing its (un-xored) result gives the unreflected CRC at C speed.
    """
    reflected = zlib.crc32(data.translate(_REFLECT)) ^ 0xFFFFFFFF
    return int.from_bytes(reflected.to_bytes(4, "little").translate(_REFLECT), "big")


def crc16_xmodem(data: bytes) -> int:
    """CRC-16/XMODEM: poly 0x1021, init 0, no reflection, xorout 0 (check 0x31C3)."""
    return binascii.crc_hqx(data, 0)
