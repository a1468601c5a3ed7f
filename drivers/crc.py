"""Catalogue CRCs used by the wire protocols, computed by the C routines of the standard library, and
the same CRCs of many equal-length frames at once (:func:`crc_rows`)."""

from __future__ import annotations

import binascii
import functools
import zlib
from collections.abc import Callable

import numpy as np

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


@functools.cache
def _position_tables(crc: Callable[[bytes], int], length: int) -> tuple[np.ndarray, int]:
    """(tables (length, 256), constant) with ``crc(m) = constant ^ XOR_j tables[j, m[j]]`` for every message m
    of ``length`` bytes: a CRC is affine in the message bits over GF(2), whatever its init and xorout."""
    constant = crc(bytes(length))
    tables = np.empty((length, 256), dtype=np.uint32)
    message = bytearray(length)
    for j in range(length):
        for b in range(256):
            message[j] = b
            tables[j, b] = crc(bytes(message)) ^ constant
        message[j] = 0
    return tables, constant


def crc_rows(crc: Callable[[bytes], int], rows: np.ndarray) -> np.ndarray:
    """``crc`` of every row of ``rows`` (N, L) uint8 at once, from per-position tables (uint32 (N,))."""
    tables, constant = _position_tables(crc, rows.shape[1])
    return np.bitwise_xor.reduce(tables[np.arange(rows.shape[1]), rows], axis=1) ^ np.uint32(constant)


def crc16_modbus(data: bytes) -> int:
    """CRC-16/MODBUS: poly 0x8005 reflected (0xA001), init 0xFFFF, xorout 0 (check 0x4B37); sent low byte first."""
    crc = 0xFFFF
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
    return crc
