"""The one replay driver: a recording re-run through a vehicle on a fake clock, one summary.

Every ``fdi-bridge replay`` -- the rover's NMEA log or capture
(:mod:`firmware_host.commands.replay`), the Outland ROV's and the ArduSub ROV's flight
recordings (:mod:`firmware_host.rov.replay`), a live INS/GNSS recording
(:mod:`firmware_host.insgnss.replay`) -- is the same loop, written once here as the live loop is
written once in :class:`~firmware_host.runtime.runner.Runner`:

* **time**: a :class:`~firmware_host.runtime.loop.FakeClock` set to each step's recorded time,
  by the vehicle's pacing as the runner paces it live: a ``"period"`` vehicle steps at its
  deadline (the clock set to the recorded step time), a ``"data"`` vehicle at the clock, which
  never goes back;
* **the steps**: the recording is an iterator of step times; before yielding a time it loads
  the step's recorded bytes into the vehicle's ports (or inbox), and when resumed it may
  compare what the step wrote with what was recorded (:class:`TxCheck`). Each step is the
  vehicle's ``step`` then its ``check``, as live; ``finish`` after the last;
* **signals**: ^C, SIGTERM and SIGHUP (raised as ``KeyboardInterrupt`` by
  :func:`firmware_host.commands.replay.signals_interrupt`) end the steps; the vehicle still
  finishes and the summary is written marked ``partial`` with ``interrupted_by``;
* **files**: ``OUT/epochs.jsonl`` (:class:`~firmware_host.runtime.records.EpochLog`; a disk
  error raises) and ``OUT/summary.json``, whole or not at all, by :meth:`ReplayDriver.summary`
  and :meth:`ReplayDriver.write_summary`, the one summary writer. ``records=False``
  (``replay --no-records``): no ``epochs.jsonl`` (one left from an earlier run in ``OUT`` is
  removed), the records counted but not encoded, and a vehicle that builds its records only
  for the file (the rover) builds none: the summary is the same.

A vehicle supplies only what is its own: its ports' contents per step, what its summary says of
the input, and its replay facts (``replay`` in the summary; ``transport`` for the rover).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any, Literal, Protocol, TextIO

from firmware_host.runtime.loop import FakeClock
from firmware_host.runtime.records import EPOCHS, EpochLog

Pacing = Literal["period", "data"]


class ReplayVehicle(Protocol):
    """What the driver needs of a vehicle (a part of :class:`~firmware_host.runtime.vehicle.
    Vehicle`: a replay opens no port, so ``ports``, ``mavlink`` and ``idle_s`` are not used;
    the caller starts it, see :meth:`ReplayDriver.run`)."""

    @property
    def pacing(self) -> Pacing: ...

    def step(self, t: float) -> int: ...

    def check(self, now: float) -> None: ...

    def finish(self) -> None: ...

    def summary(self) -> dict[str, Any]: ...


class ReplayPort:
    """A port in a replay: a read returns the bytes loaded for this step (then nothing).

    Enough of :class:`~drivers.resilient.ResilientPort` for a vehicle that reads with
    ``read_some`` (the rover's receiver, the INS/GNSS vehicle's two inputs)."""

    up = True

    def __init__(self) -> None:
        self.pending = b""
        self.bytes_rx = 0

    def load(self, data: bytes) -> None:
        self.pending = data

    def read_some(self, size: int) -> bytes:
        data, self.pending = self.pending[:size], self.pending[size:]
        self.bytes_rx += len(data)
        return data

    def wait_s(self) -> float:
        return 0.0


class RecordCount(EpochLog):
    """``--no-records``: the records counted (``lines``), not encoded or written; only
    ``OUT/summary.json`` is written, and an ``epochs.jsonl`` left in ``OUT`` by an earlier run
    is removed (it would pass for this run's)."""

    def __init__(self, directory: Path) -> None:
        super().__init__(None)
        directory.mkdir(parents=True, exist_ok=True)
        (directory / EPOCHS).unlink(missing_ok=True)
        self.dir = directory

    def write(self, record: dict[str, Any]) -> None:
        self.lines += 1


class TxCheck:
    """Each step's written bytes against the recorded ones (the ROV replays' ``tx_*``)."""

    def __init__(self) -> None:
        self.same = 0
        self.differ = 0
        self.first_differ: int | None = None

    def compare(self, k: int, written: bytes, recorded: bytes) -> None:
        if written == recorded:
            self.same += 1
        else:
            self.differ += 1
            if self.first_differ is None:
                self.first_differ = k

    def facts(self) -> dict[str, Any]:
        return {"tx_steps_same": self.same, "tx_steps_differ": self.differ,
                "tx_first_differ_step": self.first_differ, "tx_match": self.differ == 0}


class ReplayDriver:
    """One replay into ``out_dir`` (None: no files, for a pipeline that writes to a caller's
    stream). ``partial_on_signal=False``: a stop signal propagates, nothing finished (a
    caller's loop, a benchmark). See the module docstring."""

    def __init__(self, out_dir: Path | None, *, records: bool = True,
                 partial_on_signal: bool = True) -> None:
        self.out_dir = out_dir
        self.records = records
        self.partial_on_signal = partial_on_signal
        self.clock = FakeClock(0.0)
        self.epochs: EpochLog = (RecordCount(out_dir) if out_dir is not None and not records
                                 else EpochLog(out_dir))
        self.steps = 0
        self.interrupted_by = ""
        self.wall_s = 0.0

    @property
    def jsonl(self) -> TextIO | None:
        """The open ``epochs.jsonl`` for a vehicle that writes its records itself (the rover's
        pipeline); None with ``records=False`` (then it builds none)."""
        return self.epochs.stream

    def run(self, vehicle: ReplayVehicle, steps: Iterable[float], *,
            start: Callable[[], None] | None = None) -> None:
        """``start()`` the vehicle (its ``start`` with a
        :class:`~firmware_host.runtime.vehicle.Context` of the driver's ``clock`` and
        ``epochs`` and the replay's ports; this module does not build one, so that a rover
        replay never imports the MAVLink router), step it at each time of ``steps``, finish it;
        ``epochs.jsonl`` is closed whatever happens. A stop signal ends the steps
        (``interrupted_by``); any other error propagates, with nothing finished."""
        clock = self.clock
        t0 = time.perf_counter()
        try:
            if start is not None:
                start()
            by_deadline = vehicle.pacing == "period"
            it = iter(steps)
            try:
                try:
                    for t in it:
                        if by_deadline:  # a deadline-paced step runs at its recorded time
                            clock.now = t
                        else:  # a data-paced step at the clock, which never goes back
                            clock.now = t = max(clock.now, t)
                        vehicle.step(t)
                        vehicle.check(clock.now)
                        self.steps += 1
                finally:  # the recording's inputs (a pty) closed before the vehicle finishes
                    close = getattr(it, "close", None)
                    if close is not None:
                        close()
            except KeyboardInterrupt as err:  # ^C, SIGTERM, SIGHUP: keep what was read
                if not self.partial_on_signal:
                    raise
                self.interrupted_by = getattr(err, "signame", "SIGINT")
            vehicle.finish()
        finally:
            self.epochs.close()
            self.wall_s = time.perf_counter() - t0

    def summary(self, vehicle_summary: Mapping[str, Any], *, config: str,
                input: Mapping[str, Any], facts: Mapping[str, Any],
                vehicle: str | None = None, facts_key: str = "replay",
                count_records: bool = True, add_to_input: bool = False,
                throughput: bool = False) -> dict[str, Any]:
        """The replay's summary: the vehicle's, then, in this order, ``partial`` and
        ``interrupted_by`` (when a signal stopped it), ``vehicle``, ``config``, ``epochs``
        (the records written; ``count_records=False`` when the vehicle's summary counts
        them), ``input`` (``add_to_input``: added to the vehicle's own ``input``), the facts
        under ``facts_key``, and with ``throughput`` ``wall_s`` and ``epochs_per_s``."""
        s = dict(vehicle_summary)
        if self.interrupted_by:
            s["partial"] = True
            s["interrupted_by"] = self.interrupted_by
        if vehicle is not None:
            s["vehicle"] = vehicle
        s["config"] = config
        if count_records:
            s["epochs"] = self.epochs.lines
        if add_to_input:
            s["input"].update(input)
        else:
            s["input"] = dict(input)
        s[facts_key] = dict(facts)
        if throughput:
            wall = self.wall_s
            s["wall_s"] = round(wall, 4)
            s["epochs_per_s"] = round(s["epochs"] / wall, 1) if wall > 0 else None
        return s

    def write_summary(self, summary: dict[str, Any]) -> dict[str, Any]:
        """``OUT/summary.json``, whole or not at all; returns ``summary``."""
        self.epochs.write_summary(summary)
        return summary

