"""The run's two files: ``epochs.jsonl`` (one JSON object a line) and ``summary.json``.

:class:`EpochLog` is the one JSON Lines writer of the runtime: the ROV's records go through
:meth:`EpochLog.write`; the rover pipeline writes its records (the replay contract, in the same
compact encoding) to :attr:`EpochLog.stream`. Without a directory both are no-ops, so a vehicle
never asks whether there is an output.

The live bridge's files (``EpochLog(dir, keep_going=True)``, what the runner opens for
``run --out DIR``) are written as the flight recorder writes (issue C.3): a full, read-only or
missing disk never stops detection or the outputs. ``epochs.jsonl`` is a :class:`JsonlFile`
(handed to the kernel every 0.25 s, a failure logged once, counted, retried, never a cut line);
``summary.json`` is written whole or not at all (:func:`write_json_atomic`), into space
reserved when the run started, and a summary that cannot be written is said on stderr (the
log) without changing the exit status. The replays' files (``keep_going=False``) stop the
replay with the error instead: an offline job's output is its product.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import time
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any, TextIO, cast

from firmware_host.runtime.disk_outage import DiskOutage

try:  # the ``fast`` extra: a compiled encoder (no wheel on every platform, so optional)
    import orjson as _orjson
except ImportError:  # pragma: no cover - exercised by the tests with the encoder disabled
    _orjson = None  # type: ignore[assignment]

log = logging.getLogger("fdi_bridge.records")

# y + 1.5 * 2**52 - 1.5 * 2**52 is y rounded to an integer (to even on a tie) for
# |y| < 2**51: the sum's unit in the last place is 1 there (round4, round4_all).
_RINT = 6755399441055744.0
EPOCHS = "epochs.jsonl"
SUMMARY = "summary.json"
# Space kept for summary.json from the start of a run (a run's summary is 2-10 kB; a router
# with many links more): the bridge's own files filling the disk cannot keep it from its end.
SUMMARY_RESERVE = ".summary.json.reserve"
SUMMARY_RESERVE_BYTES = 64 * 1024
_write = os.write  # the one write call of JsonlFile (tests inject a failing disk here)


def encode_line_stdlib(record: dict[str, Any]) -> str:
    """One line of ``epochs.jsonl`` with the standard library (compact separators, as the
    replay contract has them): the reference encoding."""
    return json.dumps(record, separators=(",", ":")) + "\n"


def _same_in_orjson(value: Any) -> bool:
    """Does orjson write ``value`` byte for byte as :func:`json.dumps` does? True for the
    plain JSON types only (exact types: no subclasses, no numpy scalars), floats that are 0 or
    finite with ``1e-4 <= |x| < 1e16`` (outside that, ``repr`` uses an exponent that orjson
    spells differently, and NaN/Infinity become ``null``), strings of printable ASCII (else
    ``json.dumps`` escapes what orjson writes raw), and dicts with such string keys. Integers
    beyond 64 bits make orjson raise, which falls back too. Checked on generated runs, the
    corpus and random values by tests/test_json_encoding.py."""
    t = type(value)
    if t is float:
        return 1e-4 <= abs(value) < 1e16 or value == 0.0
    if t is str:
        return value.isascii() and value.isprintable()
    if value is None or t is int or t is bool:
        return True
    if t is dict:
        return all(type(k) is str and k.isascii() and k.isprintable() and _same_in_orjson(v)
                   for k, v in value.items())
    if t is list or t is tuple:
        return all(_same_in_orjson(v) for v in value)
    return False


def _flat_same_in_orjson(record: dict[str, Any]) -> bool:
    """:func:`_same_in_orjson` of a record, its scalar values checked inline (the hot path:
    once an epoch); a non-string key makes ``join`` raise TypeError (the caller falls back)."""
    for v in record.values():
        t = type(v)
        if t is float:  # the same test as _same_in_orjson's, without the call to abs
            if not (1e-4 <= v < 1e16 or -1e16 < v <= -1e-4 or v == 0.0):
                return False
        elif t is str:
            if not (v.isascii() and v.isprintable()):
                return False
        elif not (v is None or t is bool or t is int or _same_in_orjson(v)):
            return False
    keys = "".join(record)
    return keys.isascii() and keys.isprintable()


def encode_line(record: dict[str, Any]) -> str:
    """One line of ``epochs.jsonl``, byte-identical to :func:`encode_line_stdlib`: orjson
    (about ten times faster) when it is installed and writes this record the same way, else
    the standard library."""
    if _orjson is not None:
        try:
            if _flat_same_in_orjson(record):
                return _orjson.dumps(record, option=_orjson.OPT_APPEND_NEWLINE).decode()
        except TypeError:  # a non-string key, an integer beyond 64 bits
            pass
    return encode_line_stdlib(record)


def round4(x: float) -> float:
    """``round(x, 4)``, the same float (sign of zero included), in about half its time.

    For ``|y| < 2**31`` with ``y = x * 1e4`` the product is within ``2**-22`` of the exact
    ``x * 10**4``; when the guard accepts ``r``, ``y`` rounded to an integer (``_RINT``), as
    within ``0.4999`` of ``y`` (exact subtraction), the exact value is within
    ``0.4999 + 2**-22 < 1/2`` of ``r``, so ``r`` is the integer :func:`round` rounds it to
    (near-ties go to :func:`round` itself); ``r / 1e4`` is
    correctly rounded by the division, as :func:`round`'s decimal string is by its
    conversion back. Zero (its sign), NaN,
    infinities, large values and anything but a float (an int stays an int) go to
    :func:`round`. Tested against :func:`round` on millions of values
    (tests/test_json_encoding.py). The rover's records round about fifteen values an epoch."""
    y = x * 10000.0
    if -2147483648.0 < y < 2147483648.0 and type(x) is float:  # (round keeps an int an int)
        r = (y + _RINT) - _RINT
        if r and -0.4999 < y - r < 0.4999:
            return r / 10000.0
    return round(x, 4)


def round2(x: float) -> float:
    """``round(x, 2)``, the same float: :func:`round4` with 100 for 10 000."""
    y = x * 100.0
    if -2147483648.0 < y < 2147483648.0 and type(x) is float:
        r = (y + _RINT) - _RINT
        if r and -0.4999 < y - r < 0.4999:
            return r / 100.0
    return round(x, 2)


def round4_all(values: Iterable[float | None]) -> tuple[list[float | None], bool]:
    """``[None if x is None else round4(x) for x in values]`` in one call, and whether every
    result is a number :func:`numbers_spelled_alike` passes (``(rounded, plain)``).

    A record rounds a score of values an epoch: one loop here costs less than a call each.
    The fast path's result ``r / 1e4`` (``r`` a non-zero integer under ``2**31``) is at least
    ``1e-4`` and under ``1e16`` in magnitude, so it passes that test as it is made; only what
    :func:`round` itself rounds (zero, large values, NaN, infinities, integers) is tested.
    The same values as :func:`round4` (tested against it and :func:`numbers_spelled_alike`)."""
    out: list[float | None] = []
    add = out.append
    plain = True
    for x in values:
        if type(x) is float:  # round4's fast path, its guards in the cheapest order
            y = x * 10000.0
            r = (y + _RINT) - _RINT
            if -0.4999 < y - r < 0.4999 and r and -2147483648.0 < y < 2147483648.0:
                add(r / 10000.0)
                continue
        elif x is None:
            add(None)
            continue
        v = round(x, 4)
        add(v)
        if plain and not (1e-4 <= v < 1e16 or -1e16 < v <= -1e-4 or v == 0.0):
            plain = False
    return out, plain


def numbers_spelled_alike(values: Iterable[float | int | None]) -> bool:
    """Does orjson write each of these numbers (or None) as :func:`json.dumps` does? The
    number part of :func:`_same_in_orjson` for a caller that knows its values are numbers:
    0, or finite with ``1e-4 <= |x| < 1e16`` (an integer that large falls back too)."""
    for v in values:
        if v is not None and not (1e-4 <= v < 1e16 or -1e16 < v <= -1e-4 or v == 0.0):
            return False
    return True


def encode_plain_line(record: dict[str, Any]) -> str:
    """:func:`encode_line` for a record whose maker has checked what :func:`_same_in_orjson`
    checks (the rover's records, :meth:`RoverPipeline._record
    <firmware_host.rover.pipeline.RoverPipeline._record>`): flat, its keys and strings
    printable ASCII, its numbers passed by :func:`numbers_spelled_alike`, the rest None,
    booleans and integers. orjson when installed, else the standard library: the same bytes."""
    if _orjson is not None:
        try:
            return _orjson.dumps(record, option=_orjson.OPT_APPEND_NEWLINE).decode()
        except TypeError:  # an integer beyond 64 bits
            pass
    return encode_line_stdlib(record)




# --------------------------------------------------------------------------- files


def write_json_atomic(path: Path, obj: Any) -> None:
    """``path`` holds ``obj`` (``json.dumps(obj, indent=2)`` and a newline) whole, or is left
    as it was: a temporary file in the same directory, written, fsynced and renamed over
    ``path`` (then the directory fsynced), as editors and package managers replace a file.
    Raises OSError, the temporary file removed."""
    data = (json.dumps(obj, indent=2) + "\n").encode("utf-8")
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        try:
            written = 0
            while written < len(data):
                written += os.write(fd, data[written:])
            os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(tmp, path)
    except OSError:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise
    with contextlib.suppress(OSError):  # the rename itself durable (not all systems allow it)
        dfd = os.open(path.parent, os.O_RDONLY)
        try:
            os.fsync(dfd)
        finally:
            os.close(dfd)


class JsonlFile(DiskOutage):
    """A JSON Lines file that a full or read-only disk never stops, kill-safe to 0.25 s.

    :meth:`write` takes whole lines (a ``TextIO``'s ``write``, for the rover pipeline) and keeps
    them in memory; they are handed to the kernel in one ``os.write`` at least every
    ``flush_interval_s`` of the injected ``clock`` (the runner's monotonic clock: wall time,
    not the epochs' times; :meth:`poll`, called by the runner after every iteration, every 50 ms
    or sooner with the rover's default port timeout) and whenever ``buffer_max`` bytes wait.
    A ``SIGKILL`` loses at most the lines of the last interval and one iteration
    (tests/test_epochs_kill.py); there is no fsync (a power cut may lose what the kernel had not
    written yet; the flight recorder is the file that is fsynced).

    A write the disk refuses (``ENOSPC``, ``EROFS``, ``EIO``) never raises: the file is cut back
    to its last whole line (never a partial line in it), the outage is logged once and counted
    (``outages``, ``write_errors`` for every failed try), and what the disk refused is kept for
    the next try up to ``buffer_max`` bytes, past it dropped and counted (``lost_lines``,
    ``lost_bytes``): memory stays bounded during a long outage. Every interval the writer tries
    again; when the disk takes the lines again it says so once and goes on (the flight
    recorder's policy, :class:`~firmware_host.runtime.recorder.FlightRecorder`). A file that
    cannot be created (a read-only or missing directory, no permission) is the same outage: it
    is created (empty, then appended to) as soon as it can be.
    """

    _outage_log = log
    _outage_stopped = "records are not written"
    _outage_unit = "lines"
    _outage_retry_fmt = "%.2f"

    def __init__(self, path: Path, *, clock: Callable[[], float] = time.monotonic,
                 flush_interval_s: float = 0.25, buffer_max: int = 256 * 1024) -> None:
        self.path = path
        self.clock = clock
        self.flush_interval_s = flush_interval_s
        self.buffer_max = buffer_max
        self._lines: list[str] = []  # written, not yet encoded
        self._pending = 0  # characters in _lines
        self._held = bytearray()  # encoded whole lines not yet taken by the disk
        self._partial = False  # _held starts inside a line the file holds the start of
        self._fd: int | None = None
        self._size = 0
        self._last_flush = clock()
        self.closed = False
        # Counters.
        self.lines_written = 0  # lines the file holds
        self.lost_lines = 0
        self.lost_bytes = 0
        self._init_outage()  # write_errors, outages, last_error (DiskOutage)
        self._open()

    @property
    def writing(self) -> bool:
        """False while a disk error keeps the lines out of the file."""
        return self._writing

    # ------------------------------------------------------------------ TextIO's part

    def write(self, text: str) -> int:
        """Keep ``text`` (whole lines) for the next flush; flush when ``buffer_max`` waits."""
        if self.closed:
            self.lost_lines += text.count("\n")
            self.lost_bytes += len(text)
            return len(text)
        self._lines.append(text)
        self._pending += len(text)
        if self._pending >= self.buffer_max:
            self.flush()
        return len(text)

    def poll(self, now: float | None = None) -> None:
        """Flush when ``flush_interval_s`` has passed since the last flush."""
        if (self.clock() if now is None else now) - self._last_flush >= self.flush_interval_s:
            self.flush()

    def flush(self) -> None:
        """Hand what waits to the kernel (or keep it for the next try, see the class)."""
        self._last_flush = self.clock()
        if self._lines:
            self._held += "".join(self._lines).encode("utf-8")
            self._lines.clear()
            self._pending = 0
        if not self._held:
            return
        if self._fd is None and not self._open():
            self._bound()
            return
        err = self._append()
        if err is None:
            self._recovered()
            return
        self._failed(f"{self.path}: write failed: {err.strerror}")
        self._bound()

    def close(self) -> None:
        """A last flush; what the disk still refuses is lost (counted)."""
        if self.closed:
            return
        self.flush()
        self.closed = True
        if self._held:
            self._lose()
            self._held.clear()
            log.warning("%s: %d lines lost in all (the disk refused them to the end)",
                        self.path, self.lost_lines)
        if self._fd is not None:
            fd, self._fd = self._fd, None
            with contextlib.suppress(OSError):
                os.close(fd)

    # ------------------------------------------------------------------ the disk

    def _open(self) -> bool:
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_APPEND,
                               0o644)
        except FileExistsError:  # mkdir: a file where the directory should be
            self._failed(f"could not create {self.path}: {self.path.parent} exists and is not "
                         "a directory")
            return False
        except OSError as err:
            self._failed(f"could not create {self.path}: {err.strerror}")
            return False
        self._size = 0
        return True

    def _append(self) -> OSError | None:
        """Write ``_held``; on an error cut the file back to its last whole line."""
        assert self._fd is not None
        data = self._held
        written = 0
        try:
            while written < len(data):
                written += _write(self._fd, data if written == 0 else bytes(data[written:]))
        except OSError as err:
            keep = data.rfind(b"\n", 0, written) + 1
            cut = False
            if keep != written:
                try:
                    os.ftruncate(self._fd, self._size + keep)
                except OSError:  # the cut line stays; the rest of it is the next write's start
                    keep, cut = written, True
            self._took(keep)
            self._partial = self._partial or cut
            return err
        self._took(written)
        return None

    def _took(self, n: int) -> None:
        """The file took the first ``n`` bytes of ``_held``."""
        if n:
            ended = self._held.count(b"\n", 0, n)
            self.lines_written += ended
            self._size += n
            del self._held[:n]
            if ended:
                self._partial = False

    def _bound(self) -> None:
        """Past ``buffer_max`` what the disk refused is dropped (counted)."""
        if len(self._held) >= self.buffer_max:
            self._lose()
            # A cut line in the file is ended, so that the next line starts a line of its own.
            self._held = bytearray(b"\n") if self._partial else bytearray()
            self._partial = False

    def _lose(self) -> None:
        n = self._held.count(b"\n")
        self.lost_lines += n
        self.lost_bytes += len(self._held)
        self._lost_now(n)

    def _outage_name(self) -> str:
        return f"{self.path}: writing again"

    def _outage_retry_s(self) -> float:
        return self.flush_interval_s

    def counters(self) -> dict[str, Any]:
        return {
            "path": str(self.path),
            "lines_written": self.lines_written,
            "lost_lines": self.lost_lines,
            "lost_bytes": self.lost_bytes,
            "write_errors": self.write_errors,
            "outages": self.outages,
            "writing": self.writing,
            "last_error": self.last_error,
            "buffered_bytes": len(self._held) + self._pending,
        }


class EpochLog:
    """``DIR/epochs.jsonl`` and ``DIR/summary.json`` (or nothing, with ``directory=None``); or
    a caller's open ``stream`` (an embedding, a test), which is flushed but not closed.

    ``keep_going=True`` (the live bridge, :class:`~firmware_host.runtime.runner.Runner`): the
    disk never stops the run (see the module docstring; :meth:`poll` every iteration). A
    ``summary.json`` left from an earlier run in ``DIR`` is removed at the start (it would
    otherwise pass for this run's if this one's cannot be written), and
    ``SUMMARY_RESERVE_BYTES`` are reserved for this run's (released just before it is
    written). ``keep_going=False`` (the replays): a disk error raises ``OSError``.
    """

    def __init__(self, directory: Path | None, stream: TextIO | None = None, *,
                 keep_going: bool = False, clock: Callable[[], float] = time.monotonic) -> None:
        self.dir = directory
        self.stream: TextIO | None = stream
        self._borrowed = stream is not None
        self.keep_going = keep_going
        self.file: JsonlFile | None = None
        self.lines = 0
        self.summary_error = ""
        if directory is not None and stream is None:
            if keep_going:
                self.file = JsonlFile(directory / EPOCHS, clock=clock)
                self.stream = cast(TextIO, self.file)
                with contextlib.suppress(OSError):
                    (directory / SUMMARY).unlink(missing_ok=True)
                self._reserve(directory / SUMMARY_RESERVE)
            else:
                directory.mkdir(parents=True, exist_ok=True)
                self.stream = open(directory / EPOCHS, "w", encoding="utf-8")  # noqa: SIM115

    @staticmethod
    def _reserve(path: Path) -> None:
        try:
            fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        except OSError:
            return  # no directory yet or a read-only disk: nothing to reserve
        try:
            os.write(fd, bytes(SUMMARY_RESERVE_BYTES))
        except OSError:  # a disk already full: the summary may not fit at the end (said then)
            with contextlib.suppress(OSError):
                path.unlink()
        finally:
            os.close(fd)

    def write(self, record: dict[str, Any]) -> None:
        if self.stream is not None:
            self.stream.write(encode_line(record))
            self.lines += 1

    def poll(self, now: float) -> None:
        """The live file's flush when due (``keep_going``); nothing otherwise."""
        if self.file is not None:
            self.file.poll(now)

    def flush(self) -> None:
        if self.stream is not None:
            self.stream.flush()

    def close(self) -> None:
        if self.stream is not None:
            if self._borrowed:
                self.stream.flush()
            else:
                self.stream.close()
            self.stream = None

    def counters(self) -> dict[str, Any] | None:
        """The live file's counters (``keep_going``), else None."""
        return None if self.file is None else self.file.counters()

    def write_summary(self, summary: dict[str, Any]) -> Path | None:
        """``DIR/summary.json``, whole or not at all (None without a directory). With
        ``keep_going`` a failure is logged (ERROR, on stderr) and None returned: the run's
        exit status is the run's."""
        if self.dir is None:
            return None
        path = self.dir / SUMMARY
        with contextlib.suppress(OSError):
            (self.dir / SUMMARY_RESERVE).unlink(missing_ok=True)
        try:
            write_json_atomic(path, summary)
        except OSError as err:
            if not self.keep_going:
                raise
            self.summary_error = f"could not write {path}: {err.strerror}"
            log.error("%s; the run's result is unchanged", self.summary_error)
            return None
        return path
