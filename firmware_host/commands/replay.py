"""``fdi-bridge replay``: feed a capture or a plain NMEA log through a real pty into the pipeline.

The input is either the project's capture format (:mod:`drivers.capture`) or a plain NMEA
log (gpsd style: ``#`` comment lines skipped, every other byte sent as it is). A writer thread
writes it into the master side of a real pseudo-terminal pair (line settings from the capture's
header); the unmodified driver opens the slave side by its path, exactly as it opens
``/dev/ttyUSB0`` on the vehicle. ``--speed 0`` (the default) sends as fast as the pty takes
it; ``--speed 1`` paces the bytes at their recorded times (a plain log is paced by its fix
times), ``--speed 10`` ten times faster.

Outputs (the replay contract, see README): ``OUT/epochs.jsonl``, one object per receiver epoch,
and ``OUT/summary.json`` (written whole or not at all).

``^C``, ``SIGTERM`` and ``SIGHUP`` (a closed terminal, a ``timeout``, systemd) stop a replay the
same way: the epochs read so far are completed, ``summary.json`` is written marked ``partial``
(with the signal in ``interrupted_by``), every output is closed (a ``pty:PATH`` link removed,
so that nothing opens it later onto another program's pty) and the exit status is 128 + the
signal's number (130, 143, 129), as a shell reports a job a signal ended.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import json
import logging
import re
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, TextIO

from drivers.capture import CaptureReader, is_capture
from drivers.gps.link import LinkFit, WirePacer
from drivers.ptypair import PtyPair
from drivers.transport import SerialSettings, open_port, read_some
from fdi.errors import CaptureFormatError, FdiBridgeError, PortClosedError
from firmware_host.commands.port_checks import check_port_opens, output_urls
from firmware_host.commands.replay_args import add_arguments as add_arguments
from firmware_host.commands.summaries import (
    insgnss_replay_text,
    replay_problems,
    replay_text,
    rov_replay_text,
    wrote_text,
)
from firmware_host.rover.outputs import MavlinkGpsSink, NmeaSink
from firmware_host.rover.pipeline import EpochSink, RoverPipeline
from firmware_host.runtime.config import BridgeConfig, load_config
from firmware_host.runtime.replay import ReplayDriver, ReplayPort

log = logging.getLogger("fdi_bridge.replay")

# An ROV recording (firmware_host.rov.vehicle's TICK and LINK channels) goes to the ROV's
# replay, loaded only then (as the CLI loads a command): the rover's replay stays light.
ROV_TICK, ROV_LINK_RX, ROV_REPLAY = "rov tick", "rov link rx", "firmware_host.rov.replay"
ARDUSUB_TICK = "ardusub tick"  # firmware_host.rov.ardusub's TICK: the ArduSub ROV's replay
# A live INS/GNSS recording (both inputs of firmware_host.insgnss.vehicle) likewise.
INS_RX, INS_REPLAY = ("gps rx", "imu rx"), "firmware_host.insgnss.replay"
_TIME_RE = re.compile(rb"^\$..(?:GGA|RMC|GLL|ZDA|GST),(\d{6}(?:\.\d+)?)")
_LINE_END = re.compile(rb"[\r\n]")


Chunks = Iterable[tuple[float, bytes]]
_LINE_MAX = 1 << 20  # a plain log is read a line at a time, at most this many bytes at once
_READ = 1 << 16  # a plain log's blocks (ReplayInput.blocks) are read this many bytes at once
# _TIME_RE at the start of each line of a block but its first (the ``$`` after CR or LF; the
# address's two characters not a line end): the times of a block's lines in one scan (a
# look-behind after the ``$``, so that the scan looks for ``$`` alone).
_TIME_LINES_RE = re.compile(rb"\$(?<=[\r\n]\$)[^\r\n]{2}(?:GGA|RMC|GLL|ZDA|GST),"
                            rb"(\d{6}(?:\.\d+)?)")
_TIME_FIRST_RE = re.compile(rb"\$[^\r\n]{2}(?:GGA|RMC|GLL|ZDA|GST),(\d{6}(?:\.\d+)?)")


@dataclass
class ReplayInput:
    """Chunks of bytes with their times (seconds, from the first), and line settings.

    ``chunks`` streams from the file each time it is iterated (memory does not grow with the
    log's length); ``total_bytes``, ``truncated`` and the capture's ``notes`` are known once
    it has been iterated to the end (``total_bytes`` reads the file once more if asked for
    before). A list of chunks may be given instead of a file (tests, benchmarks).
    :meth:`blocks` streams the same bytes joined into blocks (a plain log's without a Python
    step a line: ``blocked``).
    """

    source: Callable[[ReplayInput], Iterator[tuple[float, bytes]]] | Chunks
    baudrate: int = 9600
    kind: str = "nmea"
    truncated: bool = False
    notes: list[str] = field(default_factory=list)
    _total: int | None = None
    # (size) -> what blocks(size) yields, made without the chunks (a plain log's)
    blocked: Callable[[int], Iterator[tuple[float, bytes]]] | None = None

    @property
    def chunks(self) -> Iterator[tuple[float, bytes]]:
        src = self.source
        total = 0
        for t, data in src(self) if callable(src) else src:
            total += len(data)
            yield t, data
        self._total = total

    def blocks(self, size: int) -> Iterator[tuple[float, bytes]]:
        """The chunks joined: each block ends with the chunk that brings it to ``size`` bytes
        or more, with that chunk's time; then the rest (perhaps empty) with the last chunk's
        time (0.0 without chunks). ``total_bytes`` is known at the end, as after ``chunks``."""
        if self.blocked is None:
            yield from _join(self.chunks, size)
            return
        total = 0
        for t, data in self.blocked(size):
            total += len(data)
            yield t, data
        self._total = total

    def data(self) -> bytes:
        """Every byte of the input, in one piece."""
        return b"".join(data for _, data in self.blocks(_LINE_MAX))

    @property
    def total_bytes(self) -> int:
        if self._total is None:
            for _ in self.blocks(_LINE_MAX):
                pass
        assert self._total is not None
        return self._total


def _join(chunks: Chunks, size: int) -> Iterator[tuple[float, bytes]]:
    """:meth:`ReplayInput.blocks` of any chunks."""
    block = bytearray()
    t = 0.0
    for t, data in chunks:
        block += data
        if len(block) >= size:
            yield t, bytes(block)
            block.clear()
    yield t, bytes(block)


def load_input(path: str | Path, channel: str | None = None) -> ReplayInput:
    """Open a capture (its first ``rx`` channel, or the one named) or a plain NMEA log.

    Nothing but the capture's header is read here: the bytes stream when ``chunks`` is
    iterated. Errors in the header (or a missing file) raise CaptureFormatError at once.
    """
    p = Path(path)
    if not p.exists():
        raise CaptureFormatError(f"{p}: no such file")
    if is_capture(p):
        reader = CaptureReader(p)
        idx = 0
        for i, ch in enumerate(reader.channels):
            if (channel is None and ch.direction == "rx") or ch.name == channel:
                idx = i
                break
        baud = reader.channels[idx].baudrate if reader.channels else 9600
        return ReplayInput(lambda inp: _capture_chunks(reader, idx, inp), baud, "capture")
    return ReplayInput(lambda inp: _nmea_chunks(p), 9600, "nmea",
                       blocked=lambda size: _nmea_blocks(p, size))


def _capture_chunks(reader: CaptureReader, idx: int, inp: ReplayInput
                    ) -> Iterator[tuple[float, bytes]]:
    t0: int | None = None
    for r in reader:
        if r.channel != idx:
            continue
        if t0 is None:
            t0 = r.t_us
        yield (r.t_us - t0) / 1e6, r.data
    inp.truncated = reader.truncated
    inp.notes = reader.all_notes()


class _FixClock:
    """A plain log's time (for pacing): its timed sentences' fix times from the first, a step
    back or a gap of a minute or more not counted."""

    __slots__ = ("_last_fix", "_last_text", "t")

    def __init__(self) -> None:
        self.t = 0.0
        self._last_fix: float | None = None
        self._last_text = b""

    def fix(self, s: bytes) -> None:
        """The next timed sentence's ``hhmmss[.ss]``."""
        if s == self._last_text:  # the same time as the sentence before: nothing moves
            return
        self._last_text = s
        fix = int(s[0:2]) * 3600 + int(s[2:4]) * 60 + float(s[4:])
        last = self._last_fix
        if last is not None and 0 < fix - last < 60:
            self.t += fix - last
        self._last_fix = fix

    def line(self, line: bytes) -> float:
        """The time at ``line`` (one line of the log)."""
        m = _TIME_RE.match(line)
        if m:
            self.fix(m.group(1))
        return self.t

    def lines(self, data: bytes) -> float:
        """The time at the last of ``data``'s lines (whole lines, no comment line)."""
        fix = self.fix
        m = _TIME_FIRST_RE.match(data)  # the first line
        if m:
            fix(m.group(1))
        for s in _TIME_LINES_RE.findall(data):  # the others
            fix(s)
        return self.t


def _lines(piece: bytes, clock: _FixClock) -> Iterator[tuple[float, bytes]]:
    """A piece's lines (``splitlines``, ends kept), comment lines skipped, with their times."""
    for line in piece.splitlines(keepends=True):
        if line.lstrip().startswith(b"#"):
            continue
        yield clock.line(line), line


def _nmea_chunks(path: Path) -> Iterator[tuple[float, bytes]]:
    """Plain log -> (time, line) with times from the fix times (for pacing only).

    The lines are exactly ``raw.splitlines(keepends=True)`` of the whole file (a line is cut
    after ``\n``, ``\r\n`` or a lone ``\r``), read a line at a time."""
    clock = _FixClock()
    with open(path, "rb") as f:
        for piece in iter(lambda: f.readline(_LINE_MAX), b""):
            yield from _lines(piece, clock)


def _readline_pieces(path: Path) -> Iterator[tuple[bytes, bool]]:
    """What ``readline(_LINE_MAX)`` returns of the file, one after the other, read in blocks:
    ``(data, True)`` for several whole pieces at once (each ending with ``\n``), else
    ``(piece, False)`` (a line longer than ``_LINE_MAX``, the file's unended last line)."""
    with open(path, "rb") as f:
        pending = b""  # what follows the last piece (no LF in it)
        for block in iter(lambda: f.read(_READ), b""):
            buf = pending + block if pending else block
            end = buf.rfind(b"\n") + 1
            if 0 < end <= _LINE_MAX:  # every line up to the last LF is one whole piece
                yield buf[:end], True
                pending = buf[end:]
                continue
            pos = 0
            while True:  # readline itself, on what is here
                i = buf.find(b"\n", pos, pos + _LINE_MAX)
                if i >= 0:
                    piece = buf[pos : i + 1]
                elif len(buf) - pos >= _LINE_MAX:
                    piece = buf[pos : pos + _LINE_MAX]
                else:
                    break
                yield piece, False
                pos += len(piece)
            pending = buf[pos:]
        for pos in range(0, len(pending), _LINE_MAX):
            yield pending[pos : pos + _LINE_MAX], False


def _nmea_blocks(path: Path, size: int) -> Iterator[tuple[float, bytes]]:
    """``_join(_nmea_chunks(path), size)``, the same blocks with the same times, without a
    Python step a line where whole lines without a comment come in one piece: the block is
    cut at the end of the line that brings it to ``size`` bytes, found by a search, and the
    times are taken in one scan of the lines (:data:`_TIME_LINES_RE`)."""
    clock = _FixClock()
    block = bytearray()
    t = 0.0
    for data, whole in _readline_pieces(path):
        if not whole or b"#" in data:  # line by line, as _nmea_chunks
            for t, line in _lines(data, clock):
                block += line
                if len(block) >= size:
                    yield t, bytes(block)
                    block.clear()
            continue
        pos, n = 0, len(data)
        while pos < n:
            need = pos + size - len(block)  # the block is full at a line end at or past this
            if need > n:
                block += data[pos:] if pos else data
                t = clock.lines(data[pos:] if pos else data)
                break
            j = _LINE_END.search(data, need - 1)
            assert j is not None  # data ends with LF
            end = j.end()
            if data[end - 1 : end + 1] == b"\r\n":
                end += 1
            part = data[pos:end]
            t = clock.lines(part)
            block += part
            yield t, bytes(block)
            block.clear()
            pos = end
    yield t, bytes(block)


class PtyFeeder(threading.Thread):
    """Writes the chunks into the pty's master side, paced by ``speed`` (0: no pacing), in
    writes of ``BATCH`` bytes or more (the last one perhaps less)."""

    BATCH = 4096

    def __init__(
        self,
        pty: PtyPair,
        chunks: Chunks,
        speed: float = 0.0,
        clock: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        super().__init__(name="pty-feeder", daemon=True)
        self.pty = pty
        self.chunks = chunks
        self.speed = speed
        self.clock = clock
        self.sleep = sleep
        self.bytes_written = 0
        self.t_written = 0.0  # the recorded time of the last chunk written (s)
        self.done = threading.Event()
        self.error: BaseException | None = None

    def run(self) -> None:
        try:
            start = self.clock()
            batch = bytearray()
            for t, data in self.chunks:
                if self.speed > 0:
                    due = start + t / self.speed
                    now = self.clock()
                    if due > now:
                        if batch:
                            self.bytes_written += self.pty.write(bytes(batch))
                            batch.clear()
                        self.sleep(due - now)
                batch += data
                self.t_written = t
                if len(batch) >= self.BATCH:
                    self.bytes_written += self.pty.write(bytes(batch))
                    batch.clear()
            if batch:
                self.bytes_written += self.pty.write(bytes(batch))
        except BaseException as err:  # reported by the reader side
            self.error = err
        finally:
            self.done.set()


class RoverFeed:
    """The rover's pipeline as a vehicle of the replay driver
    (:class:`~firmware_host.runtime.replay.ReplayDriver`): each step feeds it the bytes its
    port was given (a read of the pty, or a block of the file), and it finishes by completing
    the last epoch and closing its outputs. Nothing to start: the pipeline is built with its
    outputs."""

    name = "rover"
    pacing: Literal["data"] = "data"

    def __init__(self, pipeline: RoverPipeline, port: ReplayPort) -> None:
        self.pipeline = pipeline
        self.port = port

    def step(self, t: float) -> int:
        return self.pipeline.feed(self.port.read_some(len(self.port.pending)))

    def check(self, now: float) -> None:
        """Nothing: a replay's input does not go silent."""

    def finish(self) -> None:
        self.pipeline.finish()

    def summary(self) -> dict[str, Any]:
        return self.pipeline.summary()


def _pty_steps(inp: ReplayInput, port: ReplayPort, facts: dict[str, Any], speed: float,
               timeout_s: float, clock: Callable[[], float]) -> Iterator[float]:
    """The input written into a real pty by a :class:`PtyFeeder` and read back on its slave
    side by the unmodified driver (:func:`drivers.transport.open_port`): each read is one
    step's bytes (its time: the recorded time of the last chunk written). Ends when the writer
    is done and every byte it wrote has been read (no read timeout waited out);
    ``facts["bytes_written"]`` then says how many it wrote."""
    with PtyPair(baudrate=inp.baudrate) as pty:
        serial = open_port(SerialSettings(url=pty.url, baudrate=inp.baudrate, timeout_s=0.05))
        chunks: Chunks = inp.blocks(PtyFeeder.BATCH)  # unpaced: what the writer batches
        if speed > 0:
            chunks = (WirePacer(inp.chunks, inp.baudrate) if inp.kind == "capture"
                      else inp.chunks)  # the line's pace
        feeder = PtyFeeder(pty, chunks, speed)
        started = clock()
        feeder.start()
        read = 0
        try:
            while True:
                try:
                    data = read_some(serial, 65536)
                except PortClosedError:
                    break
                if data:
                    read += len(data)
                    port.load(data)
                    yield feeder.t_written
                if feeder.done.is_set() and read >= feeder.bytes_written:
                    break
                if clock() - started > timeout_s:
                    raise FdiBridgeError(f"replay did not finish within {timeout_s:.0f} s")
        finally:
            serial.close()
        feeder.join(timeout=5.0)
        if feeder.error is not None:
            raise FdiBridgeError(f"pty writer failed: {feeder.error}") from feeder.error
    facts["bytes_written"] = feeder.bytes_written


def _direct_steps(inp: ReplayInput, port: ReplayPort) -> Iterator[float]:
    """The input in blocks of about 64 KiB, as a port read would return them (no pty)."""
    for t, block in inp.blocks(65536):
        port.load(block)
        yield t


def _replay(driver: ReplayDriver, inp: ReplayInput, pipeline: RoverPipeline, *, use_pty: bool,
            speed: float = 0.0, timeout_s: float = 600.0,
            clock: Callable[[], float] = time.monotonic) -> dict[str, Any]:
    """``inp`` through ``pipeline`` on ``driver``; returns the transport facts."""
    port = ReplayPort()
    facts: dict[str, Any] = {}
    steps = (_pty_steps(inp, port, facts, speed, timeout_s, clock) if use_pty
             else _direct_steps(inp, port))
    driver.run(RoverFeed(pipeline, port), steps)
    if driver.interrupted_by:
        return {"bytes_total": inp.total_bytes, "pty": use_pty}
    if not use_pty:  # every byte loaded: the input was read to its end (once)
        facts["bytes_written"] = inp.total_bytes
    return {"bytes_total": inp.total_bytes, "bytes_written": facts["bytes_written"],
            "pty": use_pty}


def replay_through_pty(
    inp: ReplayInput,
    pipeline: RoverPipeline,
    *,
    speed: float = 0.0,
    timeout_s: float = 600.0,
    clock: Callable[[], float] = time.monotonic,
) -> dict[str, Any]:
    """Run ``pipeline`` on ``inp`` through a real pty; return transport facts for the summary
    (the pipeline writes its records to its own stream; a stop signal propagates)."""
    return _replay(ReplayDriver(None, partial_on_signal=False), inp, pipeline, use_pty=True,
                   speed=speed, timeout_s=timeout_s, clock=clock)


def replay_direct(inp: ReplayInput, pipeline: RoverPipeline) -> dict[str, Any]:
    """The same without a pty (for benchmarks and tests of the pipeline alone)."""
    return _replay(ReplayDriver(None, partial_on_signal=False), inp, pipeline, use_pty=False)


def build_sinks(
    cfg: BridgeConfig, nmea_url: str | None, mavlink_url: str | None
) -> list[EpochSink]:
    from dataclasses import replace


    sinks: list[EpochSink] = []
    out = cfg.rover.output
    nmea = nmea_url if nmea_url is not None else out.nmea_url
    mav = mavlink_url if mavlink_url is not None else out.mavlink_url
    if nmea:
        sinks.append(NmeaSink(nmea, out.nmea_baudrate))
    if mav:
        rover = replace(cfg.rover, output=replace(out, mavlink_url=mav))
        sinks.append(MavlinkGpsSink(rover))
    return sinks


def run_replay(
    cfg: BridgeConfig,
    capture: Path,
    out_dir: Path,
    *,
    speed: float = 0.0,
    use_pty: bool = True,
    sinks: list[EpochSink] | None = None,
    records: bool = True,
) -> dict[str, Any]:
    """Replay ``capture`` into the rover pipeline on the replay driver; write epochs.jsonl
    (``records=False``: none, and the pipeline builds no record) and summary.json."""
    inp = load_input(capture)
    driver = ReplayDriver(out_dir, records=records)
    # A capture's header says its line's baud rate; a plain log's is unknown (not judged).
    pipeline = RoverPipeline(cfg.rover, jsonl=driver.jsonl, sinks=sinks,
                             baudrate=inp.baudrate if inp.kind == "capture" else 0)
    transport = _replay(driver, inp, pipeline, use_pty=use_pty, speed=speed)
    return driver.write_summary(driver.summary(
        pipeline.summary(), config=cfg.name,
        input={"file": str(capture), "kind": inp.kind, "notes": inp.notes},
        facts=transport, facts_key="transport", count_records=False, add_to_input=True,
        throughput=True))


class Interrupted(KeyboardInterrupt):
    """A stop signal other than ^C (SIGTERM, SIGHUP): a replay stops as on ^C."""

    def __init__(self, signum: int) -> None:
        self.signum = signum
        self.signame = signal.Signals(signum).name
        super().__init__(self.signame)


@contextlib.contextmanager
def signals_interrupt(signums: tuple[int, ...] = (signal.SIGTERM, signal.SIGHUP)
                      ) -> Iterator[None]:
    """While the block runs, the first of ``signums`` raises :class:`Interrupted` in the main
    thread (as ^C raises KeyboardInterrupt); later ones are ignored, so that the partial
    summary is written and the outputs closed. The handlers are restored after the block.
    Outside the main thread (an embedding) nothing is installed."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    received: list[int] = []

    def handler(signum: int, frame: object) -> None:
        if received:
            log.warning("%s: already stopping", signal.Signals(signum).name)
            return
        received.append(signum)
        raise Interrupted(signum)

    previous = {s: signal.signal(s, handler) for s in signums}
    try:
        yield
    finally:
        for s, h in previous.items():
            signal.signal(s, h)


def link_warnings(summary: dict[str, Any]) -> list[str]:
    """The capture's receiver against its line's baud rate (its header's): a recording whose
    sentences at its rate do not fit could not have come from that line as recorded."""
    link = summary.get("link")
    if not isinstance(link, dict) or link.get("fits", True):
        return []
    fit = LinkFit(int(link["baudrate"]), float(link["bytes_per_epoch"]), float(link["rate_hz"]),
                  tuple(link["sentences"]))
    return [f"{summary['input'].get('file', 'input')}: {fit.message()}"]


def print_summary(s: dict[str, Any], stream: TextIO) -> None:
    stream.write(replay_text(s) + "\n")


# --------------------------------------------------------------------------- CLI


def _print(args: argparse.Namespace, summary: dict[str, Any], text: str) -> None:
    if args.json:
        print(json.dumps(summary))
    else:
        print(text)
        print(wrote_text(args.out, not args.no_records))


def _interrupted(summary: dict[str, Any]) -> int:
    """A replay a signal stopped: said on stderr; 128 + the signal's number (else 0)."""
    if not summary.get("partial"):
        return 0
    name = summary.get("interrupted_by", "SIGINT")
    print(f"fdi-bridge replay: interrupted ({name}) after {summary['epochs']} epochs: "
          "summary.json is partial", file=sys.stderr)
    return 128 + int(getattr(signal.Signals, name, signal.SIGINT))


def run(args: argparse.Namespace) -> int:
    with signals_interrupt():
        return _run(args)


def _run(args: argparse.Namespace) -> int:
    if is_capture(args.capture):
        names = {c.name for c in CaptureReader(args.capture).channels}
        if {ROV_TICK, ROV_LINK_RX} <= names or ARDUSUB_TICK in names:
            s = importlib.import_module(ROV_REPLAY).run(args)
            _print(args, s, rov_replay_text(s))
            return _interrupted(s)
        if set(INS_RX) <= names:
            s = importlib.import_module(INS_REPLAY).run(args)
            _print(args, s, insgnss_replay_text(s))
            return _interrupted(s)
        if ROV_LINK_RX in names:
            raise FdiBridgeError(f"{args.capture}: an ROV recording without step ticks (made "
                                 "before they were recorded): it cannot be replayed step by "
                                 "step")
    cfg = load_config(args.config)
    nmea_url, _mav_url = output_urls(cfg, args.nmea_out, args.mavlink)
    if nmea_url and not nmea_url.startswith("pty:"):  # a wrong port must not look like success
        check_port_opens(nmea_url, "--nmea-out", cfg.rover.output.nmea_baudrate)
    sinks = build_sinks(cfg, args.nmea_out, args.mavlink)
    try:
        summary = run_replay(cfg, args.capture, args.out, speed=args.speed,
                             use_pty=not args.no_pty, sinks=sinks,
                             records=not args.no_records)
    finally:  # closed by the pipeline's finish, unless a signal came before or after it
        for sink in sinks:
            sink.close()
    useless, warnings = replay_problems(summary)
    warnings += link_warnings(summary)
    for w in warnings:
        print(f"fdi-bridge replay: warning: {w}", file=sys.stderr)
    _print(args, summary, replay_text(summary))
    status = _interrupted(summary)
    if status:
        return status
    if useless is not None:
        print(f"fdi-bridge replay: {useless}", file=sys.stderr)
        return 1
    return 0
