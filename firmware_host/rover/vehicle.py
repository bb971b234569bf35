"""The rover as a vehicle of the runtime: one GPS port, the pipeline, its outputs, its failsafe.

Paced by its receiver's epochs (``"data"``): each step reads what the GPS port has (blocking
at most the port's timeout) and processes the epochs it completes
(:class:`~firmware_host.rover.pipeline.RoverPipeline`: ``epochs.jsonl``, corrected NMEA,
GPS_INPUT). Outputs: corrected NMEA (``nmea_url``), and MAVLink either through the router
(a ``[mavlink]`` table: :func:`~firmware_host.mavlink.rover.attach_rover`, live detector
parameters, NAMED_VALUE_FLOAT statistics) or to ``mavlink_url``. Failsafe
(:class:`~firmware_host.runtime.failsafe.RoverFailsafe`): a no-fix GPS_INPUT and a STATUSTEXT
after ``silence_s`` without a valid fix, "data back" when a valid fix really comes back.

Shutdown (:meth:`RoverVehicle.finish`): the epoch still pending in the driver (its end not
seen yet) is completed into ``epochs.jsonl`` and the counters, exactly as a replay of the
recording completes it, but it is **not sent**: it is older than what the failsafe may have
sent since (a no-fix), and it would say "data back" for a fix that did not come back.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import replace
from typing import Any, Literal

from drivers.resilient import ResilientPort
from drivers.transport import open_port_nonblocking
from firmware_host.mavlink.rover import attach_rover
from firmware_host.rover.outputs import MavlinkGpsSink, NmeaSink
from firmware_host.rover.pipeline import EpochSink, RoverPipeline
from firmware_host.runtime.config import BridgeConfig
from firmware_host.runtime.failsafe import RoverFailsafe
from firmware_host.runtime.vehicle import Context, MavlinkSpec, PortSpec

log = logging.getLogger("fdi_bridge.rover")


def rover_mavlink_spec(cfg: BridgeConfig, url: str | None) -> MavlinkSpec | None:
    """The MAVLink output of a vehicle on the rover's receiver (the rover, the live INS/GNSS):
    ``url`` (none when empty) with ``[rover.output]``'s ids and baud rate and the rover's
    reopen backoff."""
    if not url:
        return None
    o, rc = cfg.rover.output, cfg.rover
    return MavlinkSpec(url, o.mavlink_baudrate, o.mavlink_system, o.mavlink_component,
                       rc.reconnect_max_s)


class RoverVehicle:
    """See the module docstring. ``nmea_url``/``mavlink_url`` override the config's."""

    name = "rover"
    pacing: Literal["data"] = "data"
    period_s = 0.05  # the longest wait while the GPS port is down

    def __init__(self, cfg: BridgeConfig, *, nmea_url: str | None = None,
                 mavlink_url: str | None = None) -> None:
        self.cfg = cfg
        out = cfg.rover.output
        self.nmea_url = nmea_url if nmea_url is not None else out.nmea_url
        self.mavlink_url = mavlink_url if mavlink_url is not None else out.mavlink_url
        self.port: ResilientPort | None = None
        self.pipeline: RoverPipeline | None = None
        self.failsafe: RoverFailsafe | None = None
        self.nmea: NmeaSink | None = None
        self.pending_not_sent = 0  # epochs completed at shutdown and kept out of the outputs
        self.clock: Callable[[], float] = time.monotonic
        self._idle_s = 0.0

    # ------------------------------------------------------------------ what it needs

    def ports(self) -> list[PortSpec]:
        rc = self.cfg.rover
        return [PortSpec("gps", rc.port, rc.reconnect_max_s, opener=open_port_nonblocking)]

    def mavlink(self) -> MavlinkSpec | None:
        return rover_mavlink_spec(self.cfg, self.mavlink_url)

    def start(self, ctx: Context) -> None:
        rc = self.cfg.rover
        out = rc.output
        self.port = ctx.ports["gps"]
        self.clock = ctx.clock
        sinks: list[EpochSink] = []
        if self.nmea_url:
            tap = ctx.tap("nmea tx", self.nmea_url, out.nmea_baudrate, "tx")
            self.nmea = NmeaSink(self.nmea_url, out.nmea_baudrate, clock=ctx.clock,
                                 backoff_max_s=rc.reconnect_max_s,
                                 opener=open_port_nonblocking, tap=tap)
            sinks.append(self.nmea)
        # The receiver's sentences at its rate against the line's baud rate: said once in the
        # log and shown on the status line (a network URL has no baud rate: not judged).
        baud = 0 if "://" in rc.port.url and not rc.port.url.startswith("rfc2217://") else None
        pipeline = self.pipeline = RoverPipeline(rc, jsonl=ctx.epochs.stream, sinks=sinks,
                                                 baudrate=baud, warn_link=True)
        if ctx.router is not None:
            attach_rover(pipeline, ctx.router)  # GPS_INPUT, statistics, live parameters
        elif ctx.mavlink is not None:
            rover = replace(rc, output=replace(out, mavlink_url=self.mavlink_url or "output"))
            pipeline.sinks.append(MavlinkGpsSink(rover, endpoint=ctx.mavlink))
        self.failsafe = RoverFailsafe(rc, ctx.mavlink, clock=ctx.clock)
        pipeline.sinks.append(self.failsafe)

    # ------------------------------------------------------------------ the loop's hooks

    def step(self, t: float) -> int:
        assert self.port is not None and self.pipeline is not None
        t0 = self.clock()
        data = self.port.read_some(65536)
        if data:
            self._idle_s = 0.0
            return self.pipeline.feed(data)
        # Nothing came: the read should have waited the port's timeout. If it returned at once
        # (timeout_s = 0, a simulated device on a fake clock), the runner waits the rest.
        wait = max(self.cfg.rover.port.timeout_s, 0.01)
        self._idle_s = max(0.0, wait - (self.clock() - t0))
        return 0

    def status_fields(self) -> dict[str, Any]:
        """What the status line adds for the rover (the runner's Snapshot ``extra``)."""
        out: dict[str, Any] = {}
        fit = self.pipeline.link.result if self.pipeline is not None else None
        if fit is not None and not fit.fits:
            out["LINK"] = f"{fit.load:.1f}x {fit.baudrate} baud, max {fit.max_rate_hz:.2f} Hz"
        return out

    def check(self, now: float) -> None:
        if self.failsafe is not None:
            self.failsafe.check()

    def idle_s(self) -> float:
        if self.port is None:
            return 0.0
        if self.port.up:
            return self._idle_s  # 0 when the read waited for the receiver itself
        return max(self.port.wait_s(), 0.01)

    def finish(self) -> None:
        pipeline = self.pipeline
        if pipeline is None:
            return
        sinks, pipeline.sinks = pipeline.sinks, []
        try:
            self.pending_not_sent = pipeline.finish()  # recorded, not sent (module docstring)
        finally:
            pipeline.sinks = sinks
            for sink in sinks:
                sink.close()
        if self.pending_not_sent:
            log.info("shutdown: %d pending epoch(s) recorded, not sent", self.pending_not_sent)

    def summary(self) -> dict[str, Any]:
        if self.pipeline is None:
            return {}
        s = self.pipeline.summary()
        s["shutdown"] = {"pending_not_sent": self.pending_not_sent}
        if self.failsafe is not None:
            s["failsafe"] = {"silences": self.failsafe.watchdog.episodes,
                             "no_fix_sent": self.failsafe.no_fix_sent,
                             "statustexts": self.failsafe.statustexts}
        if self.nmea is not None:
            w = self.nmea.writer
            s["nmea_out"] = w.port.counters() if w.port is not None else {
                "dropped": w.dropped_bytes}
        return s
