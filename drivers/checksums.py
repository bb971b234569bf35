"""Frame checksums by name: the 8-bit sums and the CRCs real serial links use.

Each is a pure function ``bytes -> int`` with its width in bytes; :func:`checksum_bytes` gives
the value as it goes on the wire (big-endian for the CRC-16/CCITT family and CRC-32 as their
specifications write them, little-endian for CRC-16/MODBUS, which Modbus RTU sends low byte
first). Parameters and check values (the CRC of the ASCII bytes ``123456789``) are those of the
CRC RevEng catalogue (Greg Cook, "Catalogue of parametrised CRC algorithms"):

============================  ======  ======  =====  =====  ======  ==========
name                          width   poly    init   refin  xorout  check
============================  ======  ======  =====  =====  ======  ==========
``crc16_ccitt_false``         16      0x1021  0xFFFF  no    0x0000  0x29B1
``crc16_modbus``              16      0x8005  0xFFFF  yes   0x0000  0x4B37
``crc32`` (ISO-HDLC, zlib)    32      0x04C11DB7 0xFFFFFFFF yes 0xFFFFFFFF 0xCBF43926
============================  ======  ======  =====  =====  ======  ==========

``xor8`` (all bytes XORed; check 0x31) and ``sum8`` (the byte sum mod 256; check 0xDD) are the
weak legacy checks: see ``docs/reliability.md`` for how many corrupt frames each lets through.
"""

from __future__ import annotations

import zlib
from collections.abc import Callable
from typing import Literal

ChecksumKind = Literal["none", "xor8", "sum8", "crc16_ccitt_false", "crc16_modbus", "crc32"]
KINDS: tuple[ChecksumKind, ...] = ("none", "xor8", "sum8", "crc16_ccitt_false",
                                   "crc16_modbus", "crc32")


def _table_msb(poly: int) -> list[int]:
    out = []
    for i in range(256):
        c = i << 8
        for _ in range(8):
            c = ((c << 1) ^ poly) if c & 0x8000 else (c << 1)
        out.append(c & 0xFFFF)
    return out


def _table_lsb(poly_reflected: int) -> list[int]:
    out = []
    for i in range(256):
        c = i
        for _ in range(8):
            c = (c >> 1) ^ poly_reflected if c & 1 else c >> 1
        out.append(c)
    return out


_CCITT = _table_msb(0x1021)
_MODBUS = _table_lsb(0xA001)  # 0x8005 reflected


def xor8(data: bytes) -> int:
    c = 0
    for b in data:
        c ^= b
    return c


def sum8(data: bytes) -> int:
    return sum(data) & 0xFF


def crc16_ccitt_false(data: bytes) -> int:
    crc = 0xFFFF
    t = _CCITT
    for b in data:
        crc = ((crc << 8) & 0xFF00) ^ t[(crc >> 8) ^ b]
    return crc


def crc16_modbus(data: bytes) -> int:
    crc = 0xFFFF
    t = _MODBUS
    for b in data:
        crc = (crc >> 8) ^ t[(crc ^ b) & 0xFF]
    return crc


def crc32(data: bytes) -> int:
    return zlib.crc32(data)


_FUNCS: dict[str, tuple[Callable[[bytes], int], int, Literal["big", "little"]]] = {
    "xor8": (xor8, 1, "big"),
    "sum8": (sum8, 1, "big"),
    "crc16_ccitt_false": (crc16_ccitt_false, 2, "big"),
    "crc16_modbus": (crc16_modbus, 2, "little"),
    "crc32": (crc32, 4, "big"),
}


def width(kind: ChecksumKind) -> int:
    """Bytes the checksum takes on the wire (0 for ``none``)."""
    return 0 if kind == "none" else _FUNCS[kind][1]


def checksum_bytes(kind: ChecksumKind, data: bytes) -> bytes:
    """The checksum of ``data`` as it is sent (``b""`` for ``none``)."""
    if kind == "none":
        return b""
    fn, n, order = _FUNCS[kind]
    return fn(data).to_bytes(n, order)
