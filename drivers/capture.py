"""The fdi-bridge capture format: raw serial bytes with timestamps, per channel.

Version 2 (written; all integers big-endian, full description in ``docs/capture-format.md``)::

    magic      8 bytes   b"FDICAP02"
    hlen       u32       length of the header
    header     hlen      UTF-8 JSON: {"version": 2, "created_utc", "note", "channels": [...]}
    hcrc       u32       CRC-32 of magic, hlen and header
    records    ...       each: sync 0xC5 0xA3 | t_us u64 | channel u8 | length u16 | data
                         | crc32 u32 (of sync .. data)

The first record is a copy of the header on channel 255 (:data:`HEADER_CHANNEL`), so a file
whose header is damaged is read with the copy (and the other way round). A damaged record is
skipped: the reader looks for the next sync marker whose record passes its CRC, and counts the
bytes it skipped (``skipped_bytes``, ``damaged_regions``); a record cut short at the end of the
file (the writer was killed) is ``truncated``. Version 1 (``FDICAP01``: no sync marker, no
header checksum, a bad record ends the read) is still read.

Both writers (:class:`CaptureWriter` here, ``firmware_host.runtime.recorder.FlightRecorder``)
append through :class:`AppendFile`, which never leaves a partial record in a file: a write that
fails half-way (disk full) is cut back to the last whole record.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import struct
import time
import zlib
from collections.abc import Generator, Iterator
from dataclasses import asdict, dataclass, fields
from io import BytesIO
from pathlib import Path
from types import TracebackType
from typing import Any, BinaryIO, Literal

from fdi.errors import CaptureFormatError

log = logging.getLogger("fdi_bridge.capture")

MAGIC_V1 = b"FDICAP01"
MAGIC = b"FDICAP02"
VERSION = 2
RECORD_SYNC = b"\xc5\xa3"
HEADER_CHANNEL = 0xFF  # the header's copy; data channels are 0..254
MAX_RECORD = 0xFFFF
MAX_HEADER = 1 << 20
_HEAD_V1 = struct.Struct(">QBH")  # t_us, channel, length
_HEAD = struct.Struct(">2sQBH")  # sync, t_us, channel, length
_CRC = struct.Struct(">I")
_U32 = struct.Struct(">I")
RECORD_OVERHEAD = _HEAD.size + _CRC.size  # 17 bytes
_BLOCK = 1 << 20  # bytes read at a time: memory does not grow with the file
_write = os.write  # the one write call of the writers (a test injects a full disk here)


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


# --------------------------------------------------------------------------- encoding


def encode_record(t_us: int, channel: int, data: bytes) -> bytes:
    """One or more version-2 records for ``data`` (split at 65 535 bytes, same time)."""
    out = bytearray()
    for i in range(0, len(data), MAX_RECORD) if data else [0]:
        chunk = data[i : i + MAX_RECORD]
        body = _HEAD.pack(RECORD_SYNC, t_us, channel, len(chunk)) + chunk
        out += body + _CRC.pack(zlib.crc32(body))
    return bytes(out)


def header_dict(channels: list[Channel], note: str, created_utc: str) -> dict[str, Any]:
    return {
        "version": VERSION,
        "created_utc": created_utc,
        "note": note,
        "channels": [dict(id=i, **asdict(c)) for i, c in enumerate(channels)],
    }


def encode_header(channels: list[Channel], note: str, created_utc: str) -> bytes:
    """The file's start: magic, header, its CRC, and the header's copy as the first record."""
    if len(channels) > HEADER_CHANNEL:
        raise ValueError(f"at most {HEADER_CHANNEL} channels")
    blob = json.dumps(header_dict(channels, note, created_utc)).encode("utf-8")
    head = MAGIC + _U32.pack(len(blob)) + blob
    return head + _CRC.pack(zlib.crc32(head)) + encode_record(0, HEADER_CHANNEL, blob)


def complete_prefix(blob: bytes | bytearray | memoryview, n: int) -> int:
    """Length of the longest run of whole version-2 records at the start of ``blob[:n]``."""
    pos = 0
    while pos + _HEAD.size <= n:
        (length,) = struct.unpack_from(">H", blob, pos + _HEAD.size - 2)
        end = pos + RECORD_OVERHEAD + length
        if end > n:
            break
        pos = end
    return pos


# --------------------------------------------------------------------------- safe appending


class AppendFile:
    """An append-only file that never keeps a partial record.

    :meth:`append` writes whole records; if the write fails part-way (``ENOSPC``, ``EIO``) the
    file is cut back (``ftruncate``) to the last whole record written, and the error returned,
    not raised: the caller counts what was lost and tries again later. If even the cut fails
    the file is ``broken`` (the caller should start a new file; a reader would resynchronise
    on the next record anyway). A failed :meth:`open` (the header did not fit) removes the file.
    """

    def __init__(self, path: Path, fd: int, size: int) -> None:
        self.path = path
        self.fd = fd
        self.size = size
        self.broken = False

    @classmethod
    def create(cls, path: Path, header: bytes) -> AppendFile:
        """Create ``path`` with ``header``; OSError (nothing left behind) if that fails."""
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_APPEND, 0o644)
        f = cls(path, fd, 0)
        err = f._write_all(header, whole=False)
        if err is not None:
            f.close()
            with contextlib.suppress(OSError):
                path.unlink()
            raise err
        return f

    def append(self, blob: bytes | bytearray) -> tuple[int, OSError | None]:
        """Write ``blob`` (whole records); return (bytes kept, the error if any)."""
        start = self.size
        err = self._write_all(blob, whole=True)
        return self.size - start, err

    def _write_all(self, blob: bytes | bytearray, *, whole: bool) -> OSError | None:
        written = 0
        try:
            while written < len(blob):
                # No memoryview of the caller's buffer survives this call (it may be resized).
                written += _write(self.fd, blob if written == 0 else bytes(blob[written:]))
        except OSError as err:
            keep = complete_prefix(blob, written) if whole else 0
            if keep != written:
                try:
                    os.ftruncate(self.fd, self.size + keep)
                except OSError:
                    self.broken = True
                    keep = written  # what is there stays; the reader skips the partial record
            self.size += keep
            return err.with_traceback(None)
        self.size += written
        return None

    def close(self) -> None:
        if self.fd >= 0:
            fd, self.fd = self.fd, -1
            os.close(fd)


# --------------------------------------------------------------------------- writer


class CaptureWriter:
    """Append timestamped records (buffered; :meth:`flush` writes them). One thread per file.

    A disk that fills up (or goes read-only) does not raise: the records that could not be
    written are counted (``lost_records``, ``lost_bytes``, ``write_errors``), logged once per
    outage, and writing resumes by itself at the next :meth:`flush` that succeeds. The file
    never holds a partial record in its middle.
    """

    def __init__(self, path: str | Path, channels: list[Channel], note: str = "",
                 buffer_max: int = 1 << 16) -> None:
        self.path = Path(path)
        self.channels = channels
        created = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
        try:
            self._file: AppendFile | None = AppendFile.create(
                self.path, encode_header(channels, note, created))
        except OSError as err:
            raise CaptureFormatError(f"{self.path}: cannot create: {err.strerror}") from err
        self.buffer_max = buffer_max
        self._buf = bytearray()
        self.bytes_written = 0  # data bytes handed to write()
        self.records = 0
        self.write_errors = 0
        self.lost_records = 0
        self.lost_bytes = 0
        self.failing = False

    def write(self, channel: int, data: bytes, t_us: int | None = None) -> None:
        if t_us is None:
            t_us = time.time_ns() // 1000
        self._buf += encode_record(t_us, channel, data)
        n = 1 + (len(data) - 1) // MAX_RECORD if data else 1
        self.records += n
        self.bytes_written += len(data)
        if len(self._buf) >= self.buffer_max:
            self.flush()

    def flush(self) -> None:
        """Write the buffer. What a full disk refuses is kept for the next flush, up to
        ``buffer_max``; past that it is dropped and counted."""
        if not self._buf or self._file is None:
            return
        kept, err = self._file.append(self._buf)
        del self._buf[:kept]
        if err is None:
            if self.failing:
                log.warning("capture %s: writing again (%d records lost)", self.path,
                            self.lost_records)
                self.failing = False
            return
        self.write_errors += 1
        if not self.failing:
            log.warning("capture %s: write failed (%s); recording paused, retried at each "
                        "flush", self.path, err.strerror)
            self.failing = True
        if len(self._buf) >= self.buffer_max:
            self.lost_records += count_records(self._buf)
            self.lost_bytes += len(self._buf)
            self._buf.clear()

    def close(self) -> None:
        if self._file is not None:
            self.flush()
            self._file.close()
            self._file = None

    def __enter__(self) -> CaptureWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


def count_records(blob: bytes | bytearray | memoryview) -> int:
    """Records in ``blob``, a run of whole version-2 records (a writer's buffer)."""
    pos = n = 0
    while pos + _HEAD.size <= len(blob):
        (length,) = struct.unpack_from(">H", blob, pos + _HEAD.size - 2)
        pos += RECORD_OVERHEAD + length
        n += 1
    return n


# --------------------------------------------------------------------------- reader


_CHANNEL_TYPES: dict[str, tuple[type, ...]] = {
    "name": (str,), "url": (str,), "baudrate": (int,), "bytesize": (int,), "parity": (str,),
    "stopbits": (int, float), "direction": (str,),
}


def _channels(header: Any, where: str) -> list[Channel]:
    """The header's channels, validated: every problem is a CaptureFormatError, not a crash."""
    if not isinstance(header, dict):
        raise CaptureFormatError(f"{where}: damaged header: not a JSON object")
    chans = header.get("channels", [])
    if not isinstance(chans, list):
        raise CaptureFormatError(f"{where}: damaged header: channels is not a list")
    known = {f.name for f in fields(Channel)}
    out = []
    for i, c in enumerate(chans):
        if not isinstance(c, dict):
            raise CaptureFormatError(f"{where}: damaged header: channel {i} is not an object")
        extra = sorted(set(c) - known - {"id"})
        if extra:
            raise CaptureFormatError(f"{where}: damaged header: channel {i} has unknown "
                                     f"key(s) {', '.join(map(repr, extra))}")
        if "name" not in c:
            raise CaptureFormatError(f"{where}: damaged header: channel {i} has no name")
        for k, v in c.items():
            if k in _CHANNEL_TYPES and (isinstance(v, bool)
                                        or not isinstance(v, _CHANNEL_TYPES[k])):
                raise CaptureFormatError(f"{where}: damaged header: channel {i} {k} = {v!r}")
        if c.get("direction", "rx") not in ("rx", "tx"):
            raise CaptureFormatError(f"{where}: damaged header: channel {i} direction "
                                     f"{c['direction']!r}")
        out.append(Channel(**{k: v for k, v in c.items() if k != "id"}))
    return out


def _near_magic(b: bytes) -> bool:
    """Within 4 flipped bits of the version-2 magic (a damaged magic is still this format)."""
    return len(b) == len(MAGIC) and sum(bin(x ^ y).count("1") for x, y in zip(b, MAGIC,
                                                                             strict=True)) <= 4


class CaptureReader:
    """Read a capture: ``header``, ``channels``, ``version`` and an iterator of :class:`Record`.

    The file is read in blocks as it is iterated (memory does not grow with its length); each
    iteration reads it again and sets ``truncated``, ``corrupt`` (damaged bytes were skipped),
    ``skipped_bytes`` and ``damaged_regions``. ``notes`` says what was recovered.
    """

    def __init__(self, path: str | Path, data: bytes | None = None, block: int = _BLOCK) -> None:
        self.path = Path(path)
        self._data = data  # read these bytes instead of the file (tests, the fuzzer)
        self._block = block
        self.truncated = False
        self.good_bytes = 0  # bytes in intact records (the header's copy included)
        self.corrupt = False
        self.skipped_bytes = 0
        self.damaged_regions = 0
        self.notes: list[str] = []
        try:
            with self._open() as f:
                start = f.read(len(MAGIC) + 4 + 65536)
        except OSError as err:
            raise CaptureFormatError(f"{self.path}: {err.strerror}") from err
        magic = start[: len(MAGIC)]
        if len(start) < len(MAGIC) + 4 or not (magic in (MAGIC, MAGIC_V1) or _near_magic(magic)):
            raise CaptureFormatError(f"{self.path}: not an fdi-bridge capture (bad magic)")
        if magic == MAGIC_V1:
            self.version = 1
            self._read_header_v1(start)
        else:
            self.version = 2
            if magic != MAGIC:
                self.notes.append("magic damaged")
            self._read_header_v2(start)

    @property
    def records_start(self) -> int:
        """File offset where the records read by iteration begin (after the header used)."""
        return self._start

    def _open(self) -> BinaryIO:
        if self._data is not None:
            return BytesIO(self._data)
        return open(self.path, "rb")

    # ---------------------------------------------------------------- headers

    def _read_header_v1(self, start: bytes) -> None:
        (hlen,) = _U32.unpack_from(start, len(MAGIC))
        pos = len(MAGIC) + 4
        blob = start[pos : pos + hlen] if pos + hlen <= len(start) else self._slice(pos, hlen)
        try:
            self.header = json.loads(blob.decode("utf-8"))
        except (UnicodeDecodeError, json.JSONDecodeError) as err:
            raise CaptureFormatError(f"{self.path}: damaged header: {err}") from err
        if not isinstance(self.header, dict) or self.header.get("version") != 1:
            raise CaptureFormatError(f"{self.path}: unsupported capture version")
        self.channels = _channels(self.header, str(self.path))
        self._start = pos + hlen

    def _slice(self, pos: int, n: int) -> bytes:
        with self._open() as f:
            f.seek(pos)
            return f.read(n)

    def _parse_v2(self, blob: bytes) -> tuple[dict[str, Any], list[Channel]] | None:
        try:
            header = json.loads(blob.decode("utf-8"))
            if not isinstance(header, dict) or header.get("version") != VERSION:
                return None
            return header, _channels(header, str(self.path))
        except (UnicodeDecodeError, json.JSONDecodeError, CaptureFormatError):
            return None

    def _read_header_v2(self, start: bytes) -> None:
        (hlen,) = _U32.unpack_from(start, len(MAGIC))
        pos = len(MAGIC) + 4
        primary = None
        if hlen <= MAX_HEADER:
            need = pos + hlen + _CRC.size
            head = start[:need] if need <= len(start) else self._slice(0, need)
            if len(head) == need:
                (crc,) = _CRC.unpack_from(head, pos + hlen)
                if zlib.crc32(head[: pos + hlen]) == crc:
                    primary = self._parse_v2(head[pos : pos + hlen])
                    if primary is None:  # a valid CRC over a header we cannot use
                        raise CaptureFormatError(f"{self.path}: unsupported capture header")
        if primary is not None:
            self.header, self.channels = primary
            self._start = pos + hlen + _CRC.size
            return
        # The header is damaged: use its copy, the first intact record on HEADER_CHANNEL.
        with contextlib.closing(self._scan(pos)) as scan:
            first = next(scan, None)  # the first good record must be the copy
        if first is not None and first[0].channel == HEADER_CHANNEL:
            copy = self._parse_v2(first[0].data)
            if copy is not None:
                self.header, self.channels = copy
                self._start = first[1]
                self.notes.append("header damaged; read from its copy")
                return
        raise CaptureFormatError(f"{self.path}: damaged header (checksum mismatch) and no "
                                 "intact copy of it")

    # ---------------------------------------------------------------- records

    def all_notes(self) -> list[str]:
        """The header's notes and, after an iteration, what was skipped (for a summary)."""
        notes = list(self.notes)
        if self.truncated:
            notes.append("last record truncated (skipped)")
        if self.corrupt:
            notes.append(f"{self.skipped_bytes} damaged bytes in {self.damaged_regions} "
                         "place(s) skipped; the records around them were replayed"
                         if self.version >= 2 else
                         "a record failed its CRC; the rest was not replayed (capture format "
                         "version 1)")
        return notes

    def __iter__(self) -> Iterator[Record]:
        self.truncated = self.corrupt = False
        self.skipped_bytes = self.damaged_regions = self.good_bytes = 0
        if self.version == 1:
            yield from self._iter_v1()
            return
        for rec, _ in self._scan(self._start):
            if rec.channel != HEADER_CHANNEL:
                yield rec

    def _iter_v1(self) -> Iterator[Record]:
        with self._open() as f:
            f.seek(self._start)
            buf = b""
            pos = 0
            eof = False
            while True:
                if not eof and len(buf) - pos < _HEAD_V1.size + _CRC.size + MAX_RECORD:
                    more = f.read(self._block)
                    eof = not more
                    buf = buf[pos:] + more
                    pos = 0
                if pos == len(buf):
                    return
                if len(buf) - pos < _HEAD_V1.size:
                    self.truncated = True
                    return
                t_us, ch, length = _HEAD_V1.unpack_from(buf, pos)
                total = _HEAD_V1.size + length + _CRC.size
                if len(buf) - pos < total:
                    self.truncated = True
                    return
                body = buf[pos : pos + _HEAD_V1.size + length]
                (crc,) = _CRC.unpack_from(buf, pos + _HEAD_V1.size + length)
                if zlib.crc32(body) != crc:
                    self.corrupt = True  # version 1 has no sync marker: the read ends here
                    return
                yield Record(t_us, ch, body[_HEAD_V1.size :])
                pos += total
                self.good_bytes += total

    def _scan(self, start: int) -> Generator[tuple[Record, int], None, None]:
        """Good version-2 records from ``start`` with their end offsets; damage is skipped."""
        head, crc_s = _HEAD.size, _CRC.size
        block = self._block
        with self._open() as f:
            f.seek(start)
            buf = bytearray()
            base = start  # the file offset of buf[0]
            pos = 0
            eof = False
            skip_from: int | None = None  # file offset where the damaged region began
            skip_tail = False  # it began with a record that runs past the end of the file

            def fill(n: int) -> bool:
                """At least ``n`` bytes from ``pos`` in ``buf`` (False at the end of the file)."""
                nonlocal buf, base, pos, eof
                while len(buf) - pos < n and not eof:
                    if pos >= block:
                        del buf[:pos]
                        base += pos
                        pos = 0
                    more = f.read(max(block, n))
                    if not more:
                        eof = True
                    buf += more
                return len(buf) - pos >= n

            while True:
                past_end = False
                if not fill(head):
                    if pos < len(buf) and skip_from is None:
                        skip_from, skip_tail = base + pos, True
                    break
                if buf[pos : pos + 2] == RECORD_SYNC:
                    _, t_us, ch, length = _HEAD.unpack_from(buf, pos)
                    total = head + length + crc_s
                    if fill(total):
                        body = bytes(buf[pos : pos + head + length])
                        (crc,) = _CRC.unpack_from(buf, pos + head + length)
                        if zlib.crc32(body) == crc:
                            if skip_from is not None:
                                self._skipped(base + pos - skip_from)
                                skip_from = None
                            pos += total
                            self.good_bytes += total
                            yield Record(t_us, ch, body[head:]), base + pos
                            continue
                    else:
                        past_end = True
                if skip_from is None:
                    skip_from, skip_tail = base + pos, past_end
                # Resynchronise on the next sync marker after this position.
                while True:
                    j = buf.find(RECORD_SYNC, pos + 1)
                    if j >= 0:
                        pos = j
                        break
                    if eof:
                        pos = len(buf)
                        break
                    pos = max(pos, len(buf) - 2)  # a marker may straddle the block boundary
                    fill(len(buf) - pos + 1)
            if skip_from is not None:
                n = base + len(buf) - skip_from
                if skip_tail:
                    self.truncated = True
                    self.skipped_bytes += n
                else:
                    self._skipped(n)

    def _skipped(self, n: int) -> None:
        self.corrupt = True
        self.skipped_bytes += n
        self.damaged_regions += 1


def is_capture(path: str | Path) -> bool:
    try:
        with open(path, "rb") as f:
            magic = f.read(len(MAGIC))
    except OSError:
        return False
    return magic in (MAGIC, MAGIC_V1) or _near_magic(magic)
