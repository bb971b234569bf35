"""``fdi-bridge run --config FILE``: the bridge on the vehicle, with the configured ports.

The config file (a path, or a preset name: :func:`firmware_host.runtime.config.resolve_config_path`)
says which vehicle: a file with a ``[rover]`` table runs the rover (GPS fault isolation,
:class:`RoverBridge`); a file with an ``[rov]`` table (as ``config/rov.toml``) runs the ROV heading
hold (:func:`firmware_host.rov.app.run_rov`). A file with both or neither is a configuration
error; a file with ``[mavlink]`` runs the router (``fdi-bridge mavlink``).

Reliability (``docs/reliability.md``):

* every port is a :class:`~drivers.resilient.ResilientPort`: a port that errors or
  vanishes is reported once, the loop keeps running, and the same URL is reopened with backoff
  capped at ``rover.reconnect_max_s`` / ``link.reconnect_max_s``; data resumes without a restart
  (the rover pipeline and the ROV controller keep their state);
* silence: the rover sends a no-fix GPS_INPUT and a STATUSTEXT after ``rover.silence_s``
  without a valid fix, and says when data is back
  (:class:`~firmware_host.runtime.failsafe.RoverFailsafe`);
  the ROV holds its last command for ``dropout_hold_s``, then neutral thrust, and says when
  telemetry is back;
* the flight recorder (``[recorder] dir`` or ``--record DIR``) keeps every byte read and sent on
  every port (:mod:`firmware_host.runtime.recorder`);
* ``SIGTERM`` (systemd's stop) and ``^C`` end the loop cleanly: the recorder is flushed and
  ``summary.json`` written.
"""

from __future__ import annotations

import argparse
import json
import logging
import signal
import threading
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any, Literal, TextIO

from drivers.capture import Channel
from drivers.mavlink.io import MavEndpoint, PortEndpoint
from drivers.mavlink.links import is_network_url
from drivers.resilient import Opener, ResilientPort
from drivers.transport import SerialSettings, open_port, open_port_nonblocking
from firmware_host.commands import mavlink as mavlink_cmd
from firmware_host.commands.checks import (
    mavlink_url_arg,
    output_dir_arg,
    output_url_arg,
    positive_float,
)
from firmware_host.rov.app import run_rov
from firmware_host.rover.outputs import MavlinkGpsSink, NmeaSink
from firmware_host.rover.pipeline import EpochSink, RoverPipeline
from firmware_host.runtime.config import (
    BridgeConfig,
    BridgeFile,
    bridge_config,
    load_bridge_file,
    rov_config,
)
from firmware_host.runtime.config import Vehicle as Vehicle
from firmware_host.runtime.config import resolve_config_path as resolve_config_path
from firmware_host.runtime.config import vehicle_of as vehicle_of
from firmware_host.runtime.failsafe import RoverFailsafe, RovFailsafeMonitor
from firmware_host.runtime.recorder import FlightRecorder, RecorderConfig

log = logging.getLogger("fdi_bridge.run")


# --------------------------------------------------------------------------- outputs


class TappedEndpoint:
    """A MAVLink endpoint whose ``send_*``/``request_*`` bytes also go to a recorder tap."""

    def __init__(self, endpoint: Any, tap: Callable[[bytes], None]) -> None:
        self._endpoint = endpoint
        self._tap = tap

    def __getattr__(self, name: str) -> Any:
        attr = getattr(self._endpoint, name)
        if not callable(attr) or not name.startswith(("send_", "request_")):
            return attr

        def sent(*args: Any, **kwargs: Any) -> Any:
            data = attr(*args, **kwargs)
            if isinstance(data, bytes | bytearray) and data:
                self._tap(bytes(data))
            return data

        return sent


def _channel(name: str, s: SerialSettings, direction: Literal["rx", "tx"]) -> Channel:
    return Channel(name=name, url=s.url, baudrate=s.baudrate, bytesize=s.bytesize,
                   parity=s.parity, stopbits=s.stopbits, direction=direction)


# --------------------------------------------------------------------------- the rover


class RoverBridge:
    """The rover on the vehicle: one resilient GPS port, the pipeline, outputs, failsafe.

    ``step()`` is one loop iteration (read what is waiting, up to the port's timeout; process
    the epochs it completes; run the silence check; let the recorder flush); ``run(stop)``
    repeats it. ``endpoint`` replaces the MAVLink endpoint (tests, the soak).
    """

    def __init__(
        self,
        cfg: BridgeConfig,
        *,
        jsonl: TextIO | None = None,
        nmea_url: str | None = None,
        mavlink_url: str | None = None,
        clock: Callable[[], float] = time.monotonic,
        recorder: FlightRecorder | None = None,
        opener: Opener = open_port_nonblocking,
        endpoint: Any | None = None,
    ) -> None:
        rc = cfg.rover
        self.cfg = cfg
        self.clock = clock
        self.recorder = recorder
        rx_tap = None
        if recorder is not None:
            rx_tap = recorder.tap(recorder.add_channel(_channel("gps rx", rc.port, "rx")))
        self.port = ResilientPort(rc.port, name="gps", backoff_max_s=rc.reconnect_max_s,
                                  clock=clock, opener=opener, on_rx=rx_tap)
        sinks: list[EpochSink] = []
        out = rc.output
        nmea = nmea_url if nmea_url is not None else out.nmea_url
        mav = mavlink_url if mavlink_url is not None else out.mavlink_url
        self.nmea: NmeaSink | None = None
        self.mav_out: Any = None  # drivers.mavlink.io.PortEndpoint on a serial mavlink_url
        if nmea:
            tap = None
            if recorder is not None:
                s = SerialSettings(url=nmea, baudrate=out.nmea_baudrate)
                tap = recorder.tap(recorder.add_channel(_channel("nmea tx", s, "tx")))
            self.nmea = NmeaSink(nmea, out.nmea_baudrate, clock=clock,
                                 backoff_max_s=rc.reconnect_max_s,
                                 opener=opener, tap=tap)
            sinks.append(self.nmea)
        if endpoint is None and mav:
            if is_network_url(mav):
                endpoint = MavEndpoint(mav, source_system=out.mavlink_system,
                                       source_component=out.mavlink_component)
            else:  # a serial line to the autopilot: reopened when it goes and comes back
                port = ResilientPort(
                    SerialSettings(url=mav, baudrate=out.mavlink_baudrate, timeout_s=0.0),
                    name="mavlink out", backoff_max_s=rc.reconnect_max_s, clock=clock,
                    opener=opener)
                endpoint = self.mav_out = PortEndpoint(
                    port, source_system=out.mavlink_system, source_component=out.mavlink_component)
        if endpoint is not None:
            if recorder is not None:
                ch = recorder.add_channel(Channel(name="mavlink tx", url=mav or "endpoint",
                                                  direction="tx"))
                endpoint = TappedEndpoint(endpoint, recorder.tap(ch))
            rover = replace(rc, output=replace(out, mavlink_url=mav or "endpoint"))
            sinks.append(MavlinkGpsSink(rover, endpoint=endpoint))
        self.failsafe = RoverFailsafe(rc, endpoint, clock=clock)
        sinks.append(self.failsafe)
        self.pipeline = RoverPipeline(rc, jsonl=jsonl, sinks=sinks)

    def step(self) -> int:
        data = self.port.read_some(65536)
        n = self.pipeline.feed(data) if data else 0
        self.failsafe.check()
        if self.recorder is not None:
            self.recorder.poll()
        return n

    def run(self, stop: Callable[[], bool], sleep: Callable[[float], None] = time.sleep) -> None:
        while not stop():
            self.step()
            if not self.port.up:  # nothing blocks in read while the port is down
                sleep(min(max(self.port.wait_s(), 0.01), 0.05))

    def close(self) -> None:
        self.port.close()
        self.pipeline.finish()
        if self.recorder is not None:
            self.recorder.close()

    def summary(self) -> dict[str, Any]:
        s = self.pipeline.summary()
        s["port"] = self.port.counters()
        s["failsafe"] = {"silences": self.failsafe.watchdog.episodes,
                         "no_fix_sent": self.failsafe.no_fix_sent,
                         "statustexts": self.failsafe.statustexts}
        if self.nmea is not None:
            w = self.nmea.writer
            s["nmea_out"] = w.port.counters() if w.port is not None else {
                "dropped": w.dropped_bytes}
        if self.mav_out is not None:
            s["mavlink_out"] = dict(self.mav_out.port.counters(),
                                    partial_bytes=self.mav_out.partial_bytes)
        if self.recorder is not None:
            s["recorder"] = self.recorder.counters()
        return s


def run_rover(
    cfg: BridgeConfig,
    *,
    jsonl: TextIO | None = None,
    nmea_url: str | None = None,
    mavlink_url: str | None = None,
    clock: Callable[[], float] = time.monotonic,
    sleep: Callable[[float], None] = time.sleep,
    stop: Callable[[], bool] = lambda: False,
    recorder: FlightRecorder | None = None,
    opener: Opener = open_port_nonblocking,
    endpoint: Any | None = None,
) -> RoverBridge:
    """Run the rover until ``stop()``; returns the (closed) bridge for its counters."""
    bridge = RoverBridge(cfg, jsonl=jsonl, nmea_url=nmea_url, mavlink_url=mavlink_url,
                         clock=clock, recorder=recorder, opener=opener, endpoint=endpoint)
    try:
        bridge.run(stop, sleep)
    finally:
        bridge.close()
    return bridge


# --------------------------------------------------------------------------- the ROV


def run_rov_bridge(
    path: str | Path | BridgeFile,
    *,
    jsonl: TextIO | None = None,
    clock: Callable[[], float] = time.monotonic,
    sleep: Callable[[float], None] = time.sleep,
    stop_event: threading.Event | None = None,
    recorder: FlightRecorder | None = None,
    opener: Opener = open_port,
    max_steps: int | None = None,
    ft: bool = True,
    on_epoch: Callable[[dict[str, Any]], None] | None = None,
) -> dict[str, Any]:
    """The ROV config at ``path`` through :func:`run_rov`, with a resilient, recorded link."""

    bf = path if isinstance(path, BridgeFile) else load_bridge_file(path)
    cfg, base = rov_config(bf)
    rx_tap = tx_tap = None
    if recorder is not None:
        s = cfg.link.port
        rx_tap = recorder.tap(recorder.add_channel(_channel("rov link rx", s, "rx")))
        tx_tap = recorder.tap(recorder.add_channel(_channel("rov link tx", s, "tx")))
    ports: list[ResilientPort] = []

    def resilient(settings: SerialSettings) -> ResilientPort:
        port = ResilientPort(settings, name="rov link", backoff_max_s=cfg.link.reconnect_max_s,
                             clock=clock, opener=opener, on_rx=rx_tap, on_tx=tx_tap)
        ports.append(port)
        return port

    monitor = RovFailsafeMonitor(cfg.period_s)

    def each_epoch(rec: dict[str, Any]) -> None:
        monitor.observe(rec)
        if on_epoch is not None:
            on_epoch(rec)
        if jsonl is not None:
            jsonl.write(json.dumps(rec, separators=(",", ":")) + "\n")
        if recorder is not None:
            recorder.poll()

    try:
        out = run_rov(cfg, clock, sleep, stop_event, base_dir=base, ft=ft, max_steps=max_steps,
                      on_epoch=each_epoch, opener=resilient)
    finally:
        for p in ports:
            p.close()
        if recorder is not None:
            recorder.close()
    out["port"] = ports[0].counters() if ports else {}
    out["failsafe"] = {"episodes": monitor.episodes, "neutral": monitor.neutral_episodes}
    if recorder is not None:
        out["recorder"] = recorder.counters()
    return out


# --------------------------------------------------------------------------- CLI


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--config", required=True,
                        help="config file or preset name; [rover] -> rover, [rov] -> ROV, "
                             "[mavlink] -> the router (with [rover])")
    parser.add_argument("--out", type=output_dir_arg, default=None,
                        help="write epochs.jsonl/summary.json here (default: none)")
    parser.add_argument("--nmea-out", type=output_url_arg, default=None,
                        help="rover: corrected NMEA to this URL or pty:PATH "
                             "(default: the config's)")
    parser.add_argument("--mavlink", type=mavlink_url_arg, default=None,
                        help="rover: GPS_INPUT to this MAVLink URL (default: the config's)")
    parser.add_argument("--record", type=output_dir_arg, default=None,
                        help="flight recorder directory (overrides [recorder] dir)")
    parser.add_argument("--duration", type=positive_float, default=None,
                        help="stop after this many seconds (default: until SIGTERM or ^C)")


def _recorder(cfg: RecorderConfig, override: Path | None, note: str) -> FlightRecorder | None:
    directory = str(override) if override is not None else cfg.dir
    if not directory:
        return None
    return FlightRecorder(directory, cfg, note=note, background_sync=True)


def run(args: argparse.Namespace) -> int:
    bf = load_bridge_file(args.config)  # the one read of the file
    if bf.mavlink is not None:
        # A vehicle with an autopilot: one process, the MAVLink router running the pipeline.
        rparser = argparse.ArgumentParser(prog="fdi-bridge mavlink")
        mavlink_cmd.add_arguments(rparser)
        path = str(bf.path)
        log.warning("%s has a [mavlink] table: running it as `fdi-bridge mavlink`", path)
        extra = ["--seconds", str(args.duration)] if args.duration else []
        margs = rparser.parse_args(["--config", path, *extra])
        margs.bridge_file = bf  # read once
        return int(mavlink_cmd.run(margs))
    vehicle = vehicle_of(bf)
    stop_event = threading.Event()
    t0 = time.monotonic()

    def on_signal(signum: int, frame: object) -> None:
        log.warning("signal %d: stopping", signum)
        stop_event.set()

    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, on_signal)
        signal.signal(signal.SIGINT, on_signal)

    def stop() -> bool:
        if args.duration is not None and time.monotonic() - t0 >= args.duration:
            stop_event.set()
        return stop_event.is_set()

    jsonl = None
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        jsonl = open(args.out / "epochs.jsonl", "w", encoding="utf-8")  # noqa: SIM115
    try:
        if vehicle == "rover":
            cfg = bridge_config(bf)
            rec = _recorder(cfg.recorder, args.record, f"fdi-bridge run --config {args.config}")
            bridge = run_rover(cfg, jsonl=jsonl, nmea_url=args.nmea_out,
                               mavlink_url=args.mavlink, stop=stop, recorder=rec)
            summary = bridge.summary()
        else:
            rcfg, _ = rov_config(bf)
            rec = _recorder(rcfg.recorder, args.record, f"fdi-bridge run --config {args.config}")
            if args.duration is not None:
                timer = threading.Timer(args.duration, stop_event.set)
                timer.daemon = True
                timer.start()
            summary = run_rov_bridge(bf, jsonl=jsonl, stop_event=stop_event,
                                     recorder=rec)
    finally:
        if jsonl is not None:
            jsonl.close()
    summary["vehicle"] = vehicle
    if args.out is not None:
        (args.out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    return 0
