"""The flight recorder: every byte in and out of every port, in the capture format, kill-safe.

:class:`FlightRecorder` writes files of the project's capture format
(``docs/capture-format.md``, read by :class:`drivers.capture.CaptureReader` and
``fdi-bridge replay``) into one directory, one channel per port direction (``gps rx``,
``nmea tx``, ``mavlink tx``, ``rov link rx`` ...):

* **bounded buffering**: records are encoded into an in-memory buffer of at most
  ``buffer_max_kb``; a full buffer is written to the file at once;
* **flush + fsync** at least every ``flush_interval_s`` (at most 1 s) of the injected clock,
  checked on every write and on every :meth:`poll` (the run loops poll every iteration, at
  least every 50 ms): a ``SIGKILL`` loses at most what arrived since the last flush; a power
  cut at most what arrived since the last fsync. With ``background_sync`` (what ``run`` uses)
  the loop only hands the bytes to the kernel and a helper thread does the fsync, so a slow
  disk (an SD card, a USB stick under load) never stalls the loop on an fsync.
  A record cut short by the kill is skipped by the reader (``truncated``);
* **rotation** by size (``file_max_mb``): a new file, with the same header, once the current
  one is that large;
* **a cap for the whole directory** (``dir_max_mb``): the oldest recordings (by name, which
  starts with the UTC time the file was opened) are deleted until the directory fits.

Timestamps are wall-clock microseconds (``wall_us``, injected) as the format says; the flush
schedule runs on the monotonic ``clock`` (injected), so tests drive both.
"""

from __future__ import annotations

import json
import logging
import os
import struct
import threading
import time
import zlib
from collections.abc import Callable, Iterator
from dataclasses import asdict, dataclass, field
from pathlib import Path

from drivers.capture import MAGIC, CaptureReader, Channel, Record
from fdi.errors import FdiBridgeError

log = logging.getLogger("fdi_bridge.recorder")

_HEAD = struct.Struct(">QBH")  # the capture format's record head: t_us, channel, length
_CRC = struct.Struct(">I")
MAX_RECORD = 0xFFFF
SUFFIX = ".cap"


@dataclass(frozen=True)
class RecorderConfig:
    """The ``[recorder]`` table. An empty ``dir`` records nothing (``--record DIR`` overrides)."""

    dir: str = ""
    file_max_mb: float = field(default=64.0, metadata={"gt": 0.0})
    dir_max_mb: float = field(default=4096.0, metadata={"gt": 0.0})
    flush_interval_s: float = field(default=0.5, metadata={"gt": 0.0, "le": 1.0})
    buffer_max_kb: int = field(default=256, metadata={"ge": 1})
    prefix: str = "fdi"


def encode_record(t_us: int, channel: int, data: bytes) -> bytes:
    """One or more capture records for ``data`` (split at 65 535 bytes, same time)."""
    out = bytearray()
    for i in range(0, len(data), MAX_RECORD) if data else [0]:
        chunk = data[i : i + MAX_RECORD]
        head = _HEAD.pack(t_us, channel, len(chunk))
        out += head + chunk + _CRC.pack(zlib.crc32(head + chunk))
    return bytes(out)


def encode_header(channels: list[Channel], note: str, created_utc: str) -> bytes:
    header = {
        "version": 1,
        "created_utc": created_utc,
        "note": note,
        "channels": [dict(id=i, **asdict(c)) for i, c in enumerate(channels)],
    }
    blob = json.dumps(header).encode("utf-8")
    return MAGIC + struct.pack(">I", len(blob)) + blob


class RecorderError(FdiBridgeError):
    """The recorder's directory cannot be written."""


class FlightRecorder:
    """See the module docstring. Add channels first, then ``write``; ``poll`` every loop."""

    def __init__(
        self,
        directory: str | Path,
        cfg: RecorderConfig | None = None,
        *,
        note: str = "fdi-bridge flight recorder",
        clock: Callable[[], float] = time.monotonic,
        wall_us: Callable[[], int] = lambda: time.time_ns() // 1000,
        background_sync: bool = False,
    ) -> None:
        self.cfg = cfg or RecorderConfig()
        self.dir = Path(directory)
        try:
            self.dir.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise RecorderError(f"recorder directory {self.dir}: {err.strerror}") from err
        self.note = note
        self.clock = clock
        self.wall_us = wall_us
        self.channels: list[Channel] = []
        self.file_max = int(self.cfg.file_max_mb * 1e6)
        self.dir_max = int(self.cfg.dir_max_mb * 1e6)
        self.buffer_max = self.cfg.buffer_max_kb * 1024
        self._buf = bytearray()
        self._fd: int | None = None
        self._file_size = 0
        self._seq = 0
        self._last_sync = clock()
        self.path: Path | None = None
        # Counters.
        self.bytes_by_channel: list[int] = []
        self.records = 0
        self.files_opened = 0
        self.files_deleted = 0
        self.syncs = 0
        self.write_errors = 0
        self.max_buffered = 0
        self.max_flush_s = 0.0  # the longest flush() the loop waited for (perf counter)
        # fsync in a helper thread: the loop hands the bytes to the kernel (all a SIGKILL
        # needs) and never waits for the disk; the thread makes them durable (power loss).
        self._sync_lock = threading.Lock()
        self._sync_wake = threading.Event()
        self._sync_fds: list[int] = []  # rotated-out files: fsync then close
        self._stopping = False
        self._syncer: threading.Thread | None = None
        if background_sync:
            self._syncer = threading.Thread(target=self._sync_loop, name="recorder-fsync",
                                            daemon=True)
            self._syncer.start()

    # ------------------------------------------------------------------ channels

    def add_channel(self, channel: Channel) -> int:
        """Register a port direction; returns its channel id (a new file if one is open)."""
        self.channels.append(channel)
        self.bytes_by_channel.append(0)
        if self._fd is not None:
            self._rotate()
        return len(self.channels) - 1

    def tap(self, channel: int) -> Callable[[bytes], None]:
        """A callable that records its bytes on ``channel`` (for ResilientPort's taps)."""
        return lambda data: self.write(channel, data)

    # ------------------------------------------------------------------ writing

    def write(self, channel: int, data: bytes, t_us: int | None = None) -> None:
        if not data:
            return
        rec = encode_record(self.wall_us() if t_us is None else t_us, channel, data)
        self._buf += rec
        self.records += 1 + (len(data) - 1) // MAX_RECORD
        self.bytes_by_channel[channel] += len(data)
        self.max_buffered = max(self.max_buffered, len(self._buf))
        if len(self._buf) >= self.buffer_max:
            self._drain()
        self.poll()

    def poll(self) -> None:
        """Flush and fsync when ``flush_interval_s`` has passed since the last time."""
        if self.clock() - self._last_sync >= self.cfg.flush_interval_s:
            self.flush()

    def flush(self) -> None:
        """Write the buffer, fsync the file (or have the helper thread do it), rotate."""
        t0 = time.perf_counter()
        self._last_sync = self.clock()
        if self._fd is None:
            self._open()  # the file exists from the first flush on, data or not
        self._drain()
        if self._syncer is not None:
            self._sync_wake.set()
        elif self._fd is not None:
            self._fsync(self._fd)
        if self._file_size >= self.file_max:
            self._rotate()
        self.max_flush_s = max(self.max_flush_s, time.perf_counter() - t0)

    def _fsync(self, fd: int) -> None:
        try:
            os.fsync(fd)
            self.syncs += 1
        except OSError as err:
            self.write_errors += 1
            log.warning("recorder: fsync %s failed: %s", self.path, err.strerror)

    def _sync_loop(self) -> None:
        while True:
            self._sync_wake.wait()
            self._sync_wake.clear()
            with self._sync_lock:
                fds, self._sync_fds = self._sync_fds, []
                current = self._fd
                stopping = self._stopping
            for fd in fds:
                self._fsync(fd)
                os.close(fd)
            if current is not None and current not in fds:
                try:
                    os.fsync(current)
                    self.syncs += 1
                except OSError:
                    pass  # closed by a rotation meanwhile: its own fsync is queued
            if stopping:
                return

    def _drain(self) -> None:
        if not self._buf:
            return
        if self._fd is None:
            self._open()
        assert self._fd is not None
        view = memoryview(self._buf)
        try:
            while view:
                n = os.write(self._fd, view)
                view = view[n:]
                self._file_size += n
        except OSError as err:  # disk full, removed: count, keep running, drop the buffer
            self.write_errors += 1
            log.warning("recorder: write to %s failed: %s", self.path, err.strerror)
        finally:
            view.release()
            self._buf.clear()

    # ------------------------------------------------------------------ files

    def _open(self) -> None:
        stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime(self.wall_us() / 1e6))
        self._seq += 1
        self.path = self.dir / f"{self.cfg.prefix}-{stamp}-{self._seq:05d}{SUFFIX}"
        created = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime(self.wall_us() / 1e6))
        header = encode_header(self.channels, self.note, created)
        try:
            self._fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_APPEND,
                               0o644)
            os.write(self._fd, header)
        except OSError as err:
            raise RecorderError(f"could not create {self.path}: {err.strerror}") from err
        self._file_size = len(header)
        self.files_opened += 1
        self._enforce_cap()

    def _rotate(self) -> None:
        self._close_file()
        self._open()

    def _close_file(self) -> None:
        self._drain()
        if self._fd is None:
            return
        fd, self._fd = self._fd, None
        if self._syncer is not None:
            with self._sync_lock:
                self._sync_fds.append(fd)
            self._sync_wake.set()
            return
        self._fsync(fd)
        os.close(fd)

    def recordings(self) -> list[Path]:
        """This recorder's files in the directory, oldest first."""
        return sorted(self.dir.glob(f"{self.cfg.prefix}-*{SUFFIX}"))

    def _enforce_cap(self) -> None:
        files = self.recordings()
        sizes = {}
        for p in files:
            try:
                sizes[p] = p.stat().st_size
            except OSError:
                sizes[p] = 0
        total = sum(sizes.values())
        for p in files:
            if total <= self.dir_max:
                break
            if p == self.path:
                continue
            try:
                p.unlink()
                self.files_deleted += 1
                log.info("recorder: deleted %s (directory over %.0f MB)", p.name,
                         self.cfg.dir_max_mb)
            except OSError as err:
                log.warning("recorder: could not delete %s: %s", p, err.strerror)
                continue
            total -= sizes[p]

    def close(self) -> None:
        self._close_file()
        if self._syncer is not None:
            with self._sync_lock:
                self._stopping = True
            self._sync_wake.set()
            self._syncer.join(10.0)

    def counters(self) -> dict[str, object]:
        return {
            "bytes_by_channel": {c.name: n for c, n in zip(self.channels, self.bytes_by_channel,
                                                           strict=True)},
            "records": self.records,
            "files_opened": self.files_opened,
            "files_deleted": self.files_deleted,
            "syncs": self.syncs,
            "write_errors": self.write_errors,
            "max_buffered_bytes": self.max_buffered,
            "max_flush_ms": round(self.max_flush_s * 1e3, 3),
        }

    def __enter__(self) -> FlightRecorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def read_session(files: list[Path]) -> Iterator[tuple[Channel, Record]]:
    """Records of several recorder files in order, with their channel (truncation tolerated)."""
    for path in files:
        reader = CaptureReader(path)
        for rec in reader:
            if rec.channel < len(reader.channels):
                yield reader.channels[rec.channel], rec
