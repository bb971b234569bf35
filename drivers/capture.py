"""The fdi-bridge capture format: raw serial bytes with timestamps, per channel.

Layout (all integers big-endian)::

    magic      8 bytes   b"FDICAP01"
    hlen       u32       length of the header
    header     hlen      UTF-8 JSON: {"version": 1, "created_utc": "...", "note": "...",
                                      "channels": [{"id", "name", "url", "baudrate", "bytesize",
                                                    "parity", "stopbits", "direction"}]}
    records    ...       each: t_us u64 | channel u8 | length u16 | data | crc32 u32

``t_us`` is microseconds since the Unix epoch when the bytes were read (or written, for a
``tx`` channel); ``crc32`` covers the 11-byte record head and the data. A record whose bytes
end early (the recorder was killed mid-write) is skipped cleanly and reported as
``truncated``; a record whose CRC does not match ends the read, reported as ``corrupt``.
The line settings in the header let a replay set up its pty like the original port (gpsfake
reads them from a capture's comments; here they are data).
"""

from __future__ import annotations

import json
import struct
import time
import zlib
from collections.abc import Iterator
from dataclasses import asdict, dataclass
from pathlib import Path
from types import TracebackType
from typing import BinaryIO, Literal

from fdi.errors import CaptureFormatError

MAGIC = b"FDICAP01"
_HEAD = struct.Struct(">QBH")
_CRC = struct.Struct(">I")
MAX_RECORD = 0xFFFF


@dataclass(frozen=True)
class Channel:
    name: str
    url: str = ""
    baudrate: int = 9600
    bytesize: int = 8
    parity: str = "N"
    stopbits: float = 1.0
    direction: Literal["rx", "tx"] = "rx"


@dataclass(frozen=True, slots=True)
class Record:
    t_us: int
    channel: int
    data: bytes


class CaptureWriter:
    """Append timestamped records. Not thread-safe: one writer thread per file."""

    def __init__(self, path: str | Path, channels: list[Channel], note: str = "") -> None:
        self.path = Path(path)
        self.channels = channels
        header = {
            "version": 1,
            "created_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
            "note": note,
            "channels": [dict(id=i, **asdict(c)) for i, c in enumerate(channels)],
        }
        blob = json.dumps(header).encode("utf-8")
        self._f: BinaryIO = open(self.path, "wb")  # noqa: SIM115 - closed in close()
        self._f.write(MAGIC + struct.pack(">I", len(blob)) + blob)
        self.bytes_written = 0
        self.records = 0

    def write(self, channel: int, data: bytes, t_us: int | None = None) -> None:
        if t_us is None:
            t_us = time.time_ns() // 1000
        for i in range(0, len(data), MAX_RECORD) if data else [0]:
            chunk = data[i : i + MAX_RECORD]
            head = _HEAD.pack(t_us, channel, len(chunk))
            self._f.write(head + chunk + _CRC.pack(zlib.crc32(head + chunk)))
            self.records += 1
            self.bytes_written += len(chunk)

    def flush(self) -> None:
        self._f.flush()

    def close(self) -> None:
        if not self._f.closed:
            self._f.close()

    def __enter__(self) -> CaptureWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


class CaptureReader:
    """Read a capture: ``header``, ``channels`` and an iterator of :class:`Record`."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.truncated = False
        self.corrupt = False
        try:
            raw = self.path.read_bytes()
        except OSError as err:
            raise CaptureFormatError(f"{self.path}: {err.strerror}") from err
        if not raw.startswith(MAGIC) or len(raw) < len(MAGIC) + 4:
            raise CaptureFormatError(f"{self.path}: not an fdi-bridge capture (bad magic)")
        (hlen,) = struct.unpack_from(">I", raw, len(MAGIC))
        start = len(MAGIC) + 4
        try:
            self.header = json.loads(raw[start : start + hlen].decode("utf-8"))
        except (UnicodeDecodeError, json.JSONDecodeError) as err:
            raise CaptureFormatError(f"{self.path}: damaged header: {err}") from err
        if not isinstance(self.header, dict) or self.header.get("version") != 1:
            raise CaptureFormatError(f"{self.path}: unsupported capture version")
        self.channels = [
            Channel(**{k: v for k, v in c.items() if k != "id"})
            for c in self.header.get("channels", [])
        ]
        self._raw = raw
        self._pos = start + hlen

    def __iter__(self) -> Iterator[Record]:
        raw, pos = self._raw, self._pos
        end = len(raw)
        while pos < end:
            if pos + _HEAD.size > end:
                self.truncated = True
                return
            t_us, ch, length = _HEAD.unpack_from(raw, pos)
            stop = pos + _HEAD.size + length + _CRC.size
            if stop > end:
                self.truncated = True
                return
            body = raw[pos : pos + _HEAD.size + length]
            (crc,) = _CRC.unpack_from(raw, pos + _HEAD.size + length)
            if zlib.crc32(body) != crc:
                self.corrupt = True
                return
            yield Record(t_us, ch, bytes(body[_HEAD.size :]))
            pos = stop


def is_capture(path: str | Path) -> bool:
    try:
        with open(path, "rb") as f:
            return f.read(len(MAGIC)) == MAGIC
    except OSError:
        return False
