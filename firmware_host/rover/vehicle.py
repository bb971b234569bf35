"""The rover as a vehicle of the runtime: one GPS port, the pipeline, its outputs, its failsafe.

Paced by its receiver's epochs (``"data"``): each step reads what the GPS port has (blocking
at most the port's timeout) and processes the epochs it completes
(:class:`~firmware_host.rover.pipeline.RoverPipeline`: ``epochs.jsonl``, corrected NMEA,
GPS_INPUT). Outputs: corrected NMEA (``nmea_url``), and MAVLink either through the router
(a ``[mavlink]`` table: :func:`~firmware_host.rover.mavlink.attach_rover`, live detector
parameters, NAMED_VALUE_FLOAT statistics) or to ``mavlink_url``. Failsafe
(:class:`~firmware_host.rover.failsafe.RoverFailsafe`): a no-fix GPS_INPUT and a STATUSTEXT
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
from firmware_host.rover.failsafe import RoverFailsafe
from firmware_host.rover.mavlink import attach_rover
from firmware_host.rover.outputs import MavlinkGpsSink, NmeaSink
from firmware_host.rover.pipeline import EpochSink, RoverPipeline
from firmware_host.runtime.config import BridgeConfig
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


GGA_QUALITY = {0: "no fix", 1: "GPS", 2: "DGPS", 3: "PPS", 4: "RTK", 5: "RTK float",
               6: "DR", 7: "manual", 8: "sim", 9: "SBAS"}
"""GGA quality indicator -> a short name (NMEA 0183 4.x), as the status line shows it."""
FIX_TYPE_NAMES = {0: "none", 1: "no fix", 2: "2D", 3: "3D", 4: "DGPS", 5: "RTK float",
                  6: "RTK"}
"""GPS_FIX_TYPE of the GPS_INPUT sent -> a short name."""


def _last_gps_input(pipeline: RoverPipeline) -> Any | None:
    """The last GPS_INPUT the pipeline's MAVLink output sent (direct or through the router)."""
    for sink in pipeline.sinks:
        gps = sink if isinstance(sink, MavlinkGpsSink) else getattr(sink, "gps", None)
        if isinstance(gps, MavlinkGpsSink):
            return gps.last_fix
    return None


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

    def outputs(self) -> tuple[str, ...]:
        """The corrected NMEA output, when there is one (the start banner)."""
        return (f"NMEA {self.nmea_url}",) if self.nmea_url else ()

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
        """Counters the status line adds after the rover's (the runner's Snapshot ``extra``):
        ``LINK`` when the receiver's sentences at its rate do not fit the port's baud rate."""
        fit = self.pipeline.link.result if self.pipeline is not None else None
        if fit is not None and not fit.fits:
            return {"LINK": f"{fit.load:.1f}x {fit.baudrate} baud, max {fit.max_rate_hz:.2f} Hz"}
        return {}

    def status_detail(self) -> tuple[str, ...]:
        """The fix, compact as cgps shows it, after the ports on the status line (Snapshot
        ``detail``): the receiver's last fix and the output's position from the first fix
        with the speed (``DGPS 9sv HDOP 0.8 +0.3E +13.3N m 2.0 m/s``), what was sent and its
        accuracy (``out replace 3D 1.49 m``: the decision, GPS_INPUT's fix type and
        horizontal accuracy, when a MAVLink output is up), and the sentences the receiver
        sends (``GGA+RMC+VTG``)."""
        pipeline = self.pipeline
        last = pipeline.last_outcome if pipeline is not None else None
        if pipeline is None or last is None:
            return ()
        e, d = last.epoch, last.decision
        if e.valid:
            sats = "" if e.num_sats is None else f" {e.num_sats}sv"
            hdop = "" if e.hdop is None else f" HDOP {e.hdop:.1f}"
            fix_text = f"{GGA_QUALITY.get(e.quality, str(e.quality))}{sats}{hdop}"
        else:
            fix_text = "no fix"
        if d.out_enu is not None:
            speed = "" if e.speed_mps is None else f" {e.speed_mps:.1f} m/s"
            fix_text += f" {d.out_enu[0]:+.1f}E {d.out_enu[1]:+.1f}N m{speed}"
        sent = ""
        fix = _last_gps_input(pipeline)
        if fix is not None:
            kind = FIX_TYPE_NAMES.get(int(fix.fix_type), str(fix.fix_type))
            sent = f" {kind} {fix.horiz_accuracy_m:.2f} m" if fix.fix_type >= 2 else f" {kind}"
        parts = [fix_text, f"out {d.action}{sent}"]
        if e.sentences:
            parts.append("+".join(dict.fromkeys(e.sentences)))
        return tuple(parts)

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
