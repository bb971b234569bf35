"""Deterministic replay of a recorded ROV session (``fdi-bridge replay`` of an ROV capture).

A ``fdi-bridge run`` of the Outland ROV with a flight recorder writes, at the start of every
step, one record on the ``rov tick`` channel (``{"k": step, "t": seconds since start}``, see
:mod:`firmware_host.rov.vehicle`); the recorder keeps its records in the order they were
written, so the ``rov link rx`` bytes between tick *k* and tick *k+1* are exactly what step *k*
read, and the ``rov link tx`` bytes there what it wrote.

:func:`replay_rov` runs the same :class:`~firmware_host.rov.vehicle.OutlandRovVehicle` on the
replay driver (:class:`~firmware_host.runtime.replay.ReplayDriver`: a
:class:`~firmware_host.runtime.loop.FakeClock` set to each recorded step time, ``epochs.jsonl``
and ``summary.json``), with a :class:`LinkReplayPort` that hands each step its recorded bytes and
keeps what the vehicle writes; ``epochs.jsonl`` has the same bytes as the live run's, and the
written commands are compared with the recorded ``tx`` bytes step by step.

An ArduSub ROV recording (:func:`replay_ardusub`: channels ``ardusub tick``, ``ardusub rx``,
``ardusub tx`` of :mod:`firmware_host.rov.ardusub`) is replayed the same way, step by step,
with the frames each live step took from the router (the vehicle's own time base is its step
count, so no clock is needed).

What a replay cannot reproduce exactly: the heading plausibility check of the link (the
protocol file's ``max_rate``) reads the clock when a message is decoded; live that is the
step time plus the read's latency (milliseconds), in the replay the step time itself, so a
jump judged at the very limit could be judged the other way.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, cast

from drivers.capture import CaptureReader
from drivers.resilient import ResilientPort
from fdi.errors import CaptureFormatError, FdiBridgeError
from firmware_host.rov.ardusub import RX as ARDUSUB_RX
from firmware_host.rov.ardusub import TICK as ARDUSUB_TICK
from firmware_host.rov.ardusub import TX as ARDUSUB_TX
from firmware_host.rov.ardusub import ArduSubRovVehicle
from firmware_host.rov.config import RovConfig
from firmware_host.rov.vehicle import LINK, TICK, OutlandRovVehicle, link_settings
from firmware_host.runtime.config import load_bridge_file, rov_config, vehicle_of
from firmware_host.runtime.loop import FakeClock
from firmware_host.runtime.replay import ReplayDriver, TxCheck
from firmware_host.runtime.vehicle import Context

RX = f"{LINK} rx"
TX = f"{LINK} tx"


def is_rov_capture(reader: CaptureReader) -> bool:
    """A recording of the Outland ROV: it has the ``rov tick`` and ``rov link rx`` channels."""
    names = {c.name for c in reader.channels}
    return TICK in names and RX in names


def has_rov_link(reader: CaptureReader) -> bool:
    """The ROV's link was recorded (with or without ticks)."""
    return any(c.name == RX for c in reader.channels)


@dataclass
class RecordedStep:
    """One live step: its time (seconds since start), what it read, what it wrote."""

    k: int
    t: float
    rx: list[bytes] = field(default_factory=list)
    tx: bytearray = field(default_factory=bytearray)


def recorded_steps(reader: CaptureReader, facts: dict[str, int],
                   channels: tuple[str, str, str] = (TICK, RX, TX)) -> Iterator[RecordedStep]:
    """The steps of the recording, in order (streamed: memory does not grow with its length).

    ``channels``: the names of the tick, rx and tx channels (the Outland ROV's by default).
    ``facts`` receives ``rx_before_first_step`` / ``tx_before_first_step`` (bytes no step
    read or wrote) and ``bad_ticks`` (a tick that does not decode: its bytes go to the step
    before)."""
    ids = {c.name: i for i, c in enumerate(reader.channels)}
    tick, rx, tx = ids[channels[0]], ids.get(channels[1], -1), ids.get(channels[2], -1)
    step: RecordedStep | None = None
    for rec in reader:
        if rec.channel == tick:
            try:
                mark = json.loads(rec.data)
                new = RecordedStep(int(mark["k"]), float(mark["t"]))
            except (ValueError, KeyError, TypeError):
                facts["bad_ticks"] = facts.get("bad_ticks", 0) + 1
                continue
            if step is not None:
                yield step
            step = new
        elif rec.channel == rx:
            if step is None:
                facts["rx_before_first_step"] = facts.get("rx_before_first_step", 0) + len(
                    rec.data)
            else:
                step.rx.append(rec.data)
        elif rec.channel == tx:
            if step is None:
                facts["tx_before_first_step"] = facts.get("tx_before_first_step", 0) + len(
                    rec.data)
            else:
                step.tx += rec.data
    if step is not None:
        yield step


class LinkReplayPort:
    """The Outland link's port in a replay: each step reads exactly its recorded bytes.

    ``read`` returns the step's bytes not read yet (at most ``size``); with nothing left it
    returns ``b""`` and, like a port's read timeout, advances the fake clock by ``timeout_s``
    (an RS-485 poll that got no reply waits out its deadline). ``write`` keeps the bytes for
    the comparison with the recorded ``tx``.
    """

    def __init__(self, clock: FakeClock, timeout_s: float) -> None:
        self.clock = clock
        self.timeout_s = timeout_s
        self.pending = bytearray()
        self.written = bytearray()
        self.bytes_rx = 0
        self.bytes_tx = 0

    @property
    def port(self) -> str | None:
        return "replay"

    def load(self, chunks: list[bytes]) -> None:
        self.pending = bytearray(b"".join(chunks))
        self.written.clear()

    @property
    def in_waiting(self) -> int:
        return len(self.pending)

    def read(self, size: int = 1) -> bytes:
        if not self.pending:
            self.clock.advance(self.timeout_s)
            return b""
        data = bytes(self.pending[:size])
        del self.pending[:size]
        self.bytes_rx += len(data)
        return data

    def write(self, data: bytes, /) -> int | None:
        self.written += data
        self.bytes_tx += len(data)
        return len(data)

    def reset_input_buffer(self) -> None:
        """Nothing: what the live step dropped unread was never recorded."""

    def leftover(self) -> int:
        return len(self.pending)


def replay_rov(cfg: RovConfig, base_dir: Path, capture: Path, out_dir: Path,
               *, config_name: str = "", records: bool = True) -> dict[str, Any]:
    """Replay the ROV recording ``capture`` on the replay driver; write
    ``out_dir/epochs.jsonl`` (not with ``records=False``) and ``summary.json``; return the
    summary."""
    reader = CaptureReader(capture)
    if not is_rov_capture(reader):
        raise CaptureFormatError(f"{capture}: not an ROV recording with step ticks "
                                 f"(channels {TICK!r} and {RX!r})")
    driver = ReplayDriver(out_dir, records=records)
    port = LinkReplayPort(driver.clock, link_settings(cfg).timeout_s)
    vehicle = OutlandRovVehicle(cfg, base_dir)
    facts: dict[str, int] = {}
    tx = TxCheck()
    leftover = 0

    def steps() -> Iterator[float]:
        nonlocal leftover
        for st in recorded_steps(reader, facts):
            port.load(st.rx)
            yield st.t
            leftover += port.leftover()
            tx.compare(st.k, bytes(port.written), bytes(st.tx))

    # The vehicle uses only read/write/in_waiting/reset_input_buffer of its port.
    ctx = Context(clock=driver.clock, ports={LINK: cast(ResilientPort, port)},
                  epochs=driver.epochs)
    driver.run(vehicle, steps(), start=lambda: vehicle.start(ctx))
    return driver.write_summary(driver.summary(
        vehicle.summary(), vehicle="rov", config=config_name,
        input={"file": str(capture), "kind": "rov capture", "notes": reader.all_notes()},
        facts={"steps": driver.steps, "bytes_rx": port.bytes_rx, "bytes_tx": port.bytes_tx,
               "rx_unread": leftover, **tx.facts(), **facts}))


def is_ardusub_capture(reader: CaptureReader) -> bool:
    """A recording of the ArduSub ROV (:mod:`firmware_host.rov.ardusub`): its tick channel."""
    return any(c.name == ARDUSUB_TICK for c in reader.channels)


def replay_ardusub(cfg: RovConfig, capture: Path, out_dir: Path, *,
                   config_name: str = "", records: bool = True) -> dict[str, Any]:
    """Replay the ArduSub ROV recording ``capture`` on the replay driver: each recorded step's
    frames (the ``ardusub rx`` records after its tick, as the live step took them from the
    router) into the inbox of the same :class:`~firmware_host.rov.ardusub.ArduSubRovVehicle`,
    with no router; write ``out_dir/epochs.jsonl`` (the live run's bytes; not with
    ``records=False``) and ``summary.json``, and compare each step's commands with the
    recorded ``ardusub tx`` lines."""
    reader = CaptureReader(capture)
    if not is_ardusub_capture(reader):
        raise CaptureFormatError(f"{capture}: not an ArduSub ROV recording (no "
                                 f"{ARDUSUB_TICK!r} channel)")
    if cfg.heading_source != "mavlink":
        raise FdiBridgeError(f"{capture} is an ArduSub ROV recording: its config has "
                             '[rov] heading_source = "mavlink"')
    driver = ReplayDriver(out_dir, records=records)
    vehicle = ArduSubRovVehicle(cfg)
    facts: dict[str, int] = {}
    tx = TxCheck()
    frames = 0

    def steps() -> Iterator[float]:
        nonlocal frames
        loop = vehicle.loop
        assert loop is not None  # started by the driver before the first step
        for st in recorded_steps(reader, facts, (ARDUSUB_TICK, ARDUSUB_RX, ARDUSUB_TX)):
            for raw in st.rx:  # what the router's thread had queued for this step
                loop.inbox.push(raw)
            frames += len(st.rx)
            yield st.t
            tx.compare(st.k, b"".join(loop.tx), bytes(st.tx))

    driver.run(vehicle, steps(), start=lambda: vehicle.start_replay(driver.epochs))
    return driver.write_summary(driver.summary(
        vehicle.summary(), vehicle="rov-ardusub", config=config_name,
        input={"file": str(capture), "kind": "rov-ardusub capture",
               "notes": reader.all_notes()},
        facts={"steps": driver.steps, "frames": frames, **tx.facts(), **facts}))


def run(args: argparse.Namespace) -> dict[str, Any]:
    """``fdi-bridge replay`` of an ROV recording (from :mod:`firmware_host.commands.replay`,
    which prints): its steps re-run with the ``[rov]`` file of ``--config`` (the one it was
    recorded with); returns the summary."""
    if args.config is None:
        raise FdiBridgeError(f"{args.capture} is an ROV recording: give --config with the "
                             "[rov] file it was recorded with")
    bf = load_bridge_file(args.config)
    if vehicle_of(bf) != "rov":
        raise FdiBridgeError(f"{args.capture} is an ROV recording, but {args.config} has no "
                             "[rov] table")
    rcfg, base = rov_config(bf)
    records = not getattr(args, "no_records", False)
    if is_ardusub_capture(CaptureReader(args.capture)):
        return replay_ardusub(rcfg, args.capture, args.out, config_name=str(args.config),
                              records=records)
    return replay_rov(rcfg, base, args.capture, args.out, config_name=str(args.config),
                      records=records)
