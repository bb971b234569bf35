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

import logging
import os
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

from drivers.capture import (
    MAX_RECORD,
    AppendFile,
    CaptureReader,
    Channel,
    Record,
    count_records,
    encode_header,
    encode_record,
)
from fdi.errors import FdiBridgeError
from firmware_host.runtime.disk_outage import DiskOutage

log = logging.getLogger("fdi_bridge.recorder")

SUFFIX = ".cap"


@dataclass(frozen=True)
class RecorderConfig:
    """The ``[recorder]`` table. An empty ``dir`` records nothing (``--record DIR`` overrides)."""

    dir: str = field(default="", metadata={
        "range": "a directory path, or \"\"",
        "doc": "where the flight recorder writes; empty: nothing recorded (--record DIR "
               "overrides)"})
    file_max_mb: float = field(default=64.0, metadata={
        "gt": 0.0, "unit": "MB", "doc": "a new file once the current one holds this much (10^6 "
                                        "bytes)"})
    dir_max_mb: float = field(default=4096.0, metadata={
        "gt": 0.0, "unit": "MB", "doc": "the oldest recordings are deleted beyond this total"})
    flush_interval_s: float = field(default=0.5, metadata={
        "gt": 0.0, "le": 1.0, "unit": "s", "doc": "flush and fsync at least this often"})
    buffer_max_kb: int = field(default=256, metadata={
        "ge": 1, "unit": "kB", "doc": "a buffer this full is written at once"})
    prefix: str = field(default="fdi", metadata={
        "range": "a file-name prefix", "doc": "recordings are named PREFIX-<time>-<seq>"})


class RecorderError(FdiBridgeError):
    """The recorder's directory cannot be written."""


class FlightRecorder(DiskOutage):
    """See the module docstring. Add channels first, then ``write``; ``poll`` every loop.

    A full or read-only disk never raises out of :meth:`write`, :meth:`poll` or :meth:`flush`:
    the recorder stops recording (logged once, ``lost_records``/``lost_bytes`` counted), the
    caller's loop goes on, and at each flush interval it tries again; when the disk takes the
    bytes again it says so once and records on. No file keeps a partial record in its middle
    (:class:`drivers.capture.AppendFile` cuts a failed write back to the last whole record).
    """

    _outage_log = log
    _outage_stopped = "recording stopped"
    _outage_unit = "records"

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
        self.note = note
        self.clock = clock
        self.wall_us = wall_us
        self.channels: list[Channel] = []
        self.file_max = int(self.cfg.file_max_mb * 1e6)
        self.dir_max = int(self.cfg.dir_max_mb * 1e6)
        self.buffer_max = self.cfg.buffer_max_kb * 1024
        self._buf = bytearray()
        self._file: AppendFile | None = None
        self._seq = 0
        self._last_sync = clock()
        self.path: Path | None = None
        # Counters.
        self.bytes_by_channel: list[int] = []
        self.records = 0
        self.files_opened = 0
        self.files_deleted = 0
        self.syncs = 0
        self.lost_records = 0  # records handed to write() that never reached a file
        self.lost_bytes = 0
        self.max_buffered = 0
        self.max_flush_s = 0.0  # the longest flush() the loop waited for (perf counter)
        self._init_outage()  # write_errors, outages, last_error (DiskOutage)
        # fsync in a helper thread: the loop hands the bytes to the kernel (all a SIGKILL
        # needs) and never waits for the disk; the thread makes them durable (power loss).
        self._sync_lock = threading.Lock()
        self._sync_wake = threading.Event()
        self._sync_fds: list[int] = []  # rotated-out files: fsync then close
        self._stopping = False
        self._syncer: threading.Thread | None = None
        try:
            self.dir.mkdir(parents=True, exist_ok=True)
        except OSError as err:  # a read-only or full disk: detection goes on without us
            self._failed(f"recorder directory {self.dir}: {err.strerror}")
        if background_sync:
            self._syncer = threading.Thread(target=self._sync_loop, name="recorder-fsync",
                                            daemon=True)
            self._syncer.start()

    # ------------------------------------------------------------------ channels

    def add_channel(self, channel: Channel) -> int:
        """Register a port direction; returns its channel id (a new file if one is open)."""
        self.channels.append(channel)
        self.bytes_by_channel.append(0)
        if self._file is not None:
            self._rotate()
        return len(self.channels) - 1

    def tap(self, channel: int) -> Callable[[bytes], None]:
        """A callable that records its bytes on ``channel`` (for ResilientPort's taps)."""
        return lambda data: self.write(channel, data)

    @property
    def recording(self) -> bool:
        """False while a disk error keeps the recorder from writing."""
        return self._writing

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
        if self._file is None:
            self._open()  # the file exists from the first flush on, data or not
        self._drain()
        if self._syncer is not None:
            self._sync_wake.set()
        elif self._file is not None:
            self._fsync(self._file.fd)
        if self._file is not None and (self._file.size >= self.file_max or self._file.broken):
            self._rotate()
        self.max_flush_s = max(self.max_flush_s, time.perf_counter() - t0)

    def _fsync(self, fd: int) -> None:
        try:
            os.fsync(fd)
            self.syncs += 1
        except OSError as err:
            self.write_errors += 1
            log.debug("recorder: fsync %s failed: %s", self.path, err.strerror)

    def _sync_loop(self) -> None:
        while True:
            self._sync_wake.wait()
            self._sync_wake.clear()
            with self._sync_lock:
                fds, self._sync_fds = self._sync_fds, []
                current = self._file.fd if self._file is not None else None
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
        if self._file is None:
            self._open()
        if self._file is None:  # no file could be created (the failure is logged and counted)
            self._hold("")
            return
        kept, err = self._file.append(self._buf)
        if err is None:
            self._buf.clear()
            self._recovered()
            return
        del self._buf[:kept]  # what the disk took is in the file, whole records only
        self._hold(f"recorder: write to {self.path} failed: {err.strerror}")

    def _hold(self, why: str) -> None:
        """Keep what the disk refused for the next try, up to the buffer's bound; past it,
        drop it (counted): memory stays bounded during a long outage."""
        if why:
            self._failed(why)
        if len(self._buf) >= self.buffer_max:
            self._lose(bytes(self._buf))
            self._buf.clear()

    def _lose(self, blob: bytes) -> None:
        n = count_records(blob)
        self.lost_records += n
        self.lost_bytes += len(blob)
        self._lost_now(n)

    def _outage_name(self) -> str:
        return f"recorder: writing again to {self.path}"

    def _outage_retry_s(self) -> float:
        return self.cfg.flush_interval_s

    # ------------------------------------------------------------------ files

    def _open(self) -> None:
        stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime(self.wall_us() / 1e6))
        self._seq += 1
        path = self.dir / f"{self.cfg.prefix}-{stamp}-{self._seq:05d}{SUFFIX}"
        created = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime(self.wall_us() / 1e6))
        header = encode_header(self.channels, self.note, created)
        try:
            self.dir.mkdir(parents=True, exist_ok=True)
            self._file = AppendFile.create(path, header)
        except OSError as err:
            self._failed(f"recorder: could not create {path}: {err.strerror}")
            return
        self.path = path
        self.files_opened += 1
        self._recovered()
        self._enforce_cap()

    def _rotate(self) -> None:
        self._close_file()
        self._open()

    def _close_file(self) -> None:
        self._drain()
        if self._file is None:
            return
        f, self._file = self._file, None
        if self._syncer is not None:
            with self._sync_lock:
                self._sync_fds.append(f.fd)
            self._sync_wake.set()
            return
        self._fsync(f.fd)
        f.close()

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
        if self._buf:  # the disk refused it to the end: lost, counted
            self._lose(bytes(self._buf))
            self._buf.clear()
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
            "lost_records": self.lost_records,
            "lost_bytes": self.lost_bytes,
            "outages": self.outages,
            "recording": self.recording,
            "last_error": self.last_error,
            "buffered_bytes": len(self._buf),
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
