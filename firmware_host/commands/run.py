"""``fdi-bridge run --config FILE``: the bridge on the vehicle, with the configured ports.

The config file (a path, or a preset name: :func:`firmware_host.runtime.config.resolve_config_path`)
says which vehicle: a file with a ``[rover]`` table runs the rover (GPS fault isolation,
:class:`~firmware_host.rover.vehicle.RoverVehicle`); a file with an ``[rov]`` table (as
``config/rov.toml``) runs the ROV heading hold on the Outland link
(:class:`~firmware_host.rov.vehicle.OutlandRovVehicle`). A file with both or neither vehicle is
a configuration error (a file with only ``[mavlink]`` runs the router alone, as ``fdi-bridge
mavlink``). A ``[mavlink]`` table attaches the MAVLink router to the vehicle: one process, the
deployment systemd runs.

Every vehicle runs on the one runtime, :class:`~firmware_host.runtime.runner.Runner`
(``docs/architecture.md``). Reliability (``docs/reliability.md``):

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
* files never stop the bridge: ``--out DIR``, ``--record DIR`` and ``[recorder] dir`` on a disk
  that is full, read-only or not writable at start or later are said once (the path and the
  error), counted in the summary and retried; detection and the outputs go on (a field laptop's
  SD card remounted read-only must not take the GPS corrections with it; ``fdi-bridge doctor``
  is the check before a mission that refuses such a directory);
* ``SIGTERM`` (systemd's stop) and ``^C`` end the loop cleanly (exit 0): nothing stale is
  sent, the recorder, the ``.tlog`` and ``epochs.jsonl`` are flushed and ``summary.json`` written.
"""

from __future__ import annotations

import argparse
import json
import logging
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, TextIO

from drivers.resilient import Opener, ResilientPort
from firmware_host.commands import mavlink as mavlink_cmd
from firmware_host.commands.checks import (
    mavlink_url_arg,
    output_url_arg,
    positive_float,
)
from firmware_host.commands.launch import run_file
from firmware_host.commands.live import console_status, run_summary_text
from firmware_host.rov.vehicle import OutlandRovVehicle
from firmware_host.rover.failsafe import RoverFailsafe
from firmware_host.rover.pipeline import RoverPipeline
from firmware_host.rover.vehicle import RoverVehicle
from firmware_host.runtime.config import (
    BridgeConfig,
    BridgeFile,
    load_bridge_file,
    rov_config,
)
from firmware_host.runtime.config import Vehicle as Vehicle
from firmware_host.runtime.config import resolve_config_path as resolve_config_path
from firmware_host.runtime.config import vehicle_of as vehicle_of
from firmware_host.runtime.mavout import EncoderOutput, MavlinkOutput
from firmware_host.runtime.recorder import FlightRecorder
from firmware_host.runtime.runner import Runner

log = logging.getLogger("fdi_bridge.run")

# --------------------------------------------------------------------------- embedding


class RoverBridge:
    """The rover on the :class:`Runner`, started, for embedding and tests.

    ``step()`` is one iteration of the runtime's loop, ``run(stop)`` loops until ``stop()``
    (in any thread), ``close()`` finishes (see :meth:`RoverVehicle.finish`). ``endpoint``
    replaces the MAVLink output (tests, the soak); ``jsonl`` receives the records.
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
        opener: Opener | None = None,
        endpoint: MavlinkOutput | None = None,
    ) -> None:
        self.vehicle = RoverVehicle(cfg, nmea_url=nmea_url, mavlink_url=mavlink_url)
        self.runner = Runner(self.vehicle, jsonl=jsonl, recorder=recorder,
                             mavlink_output=endpoint, clock=clock, opener=opener,
                             handle_signals=False)
        self.runner.start()

    @property
    def pipeline(self) -> RoverPipeline:
        assert self.vehicle.pipeline is not None
        return self.vehicle.pipeline

    @property
    def port(self) -> ResilientPort:
        return self.runner.ports["gps"]

    @property
    def failsafe(self) -> RoverFailsafe:
        assert self.vehicle.failsafe is not None
        return self.vehicle.failsafe

    @property
    def mav_out(self) -> EncoderOutput | None:
        """The serial MAVLink output (its ``port`` reopens a lost autopilot line), or None."""
        out = self.runner.mavlink_output
        return out if isinstance(out, EncoderOutput) and out.port is not None else None

    def step(self) -> int:
        return self.runner.step()

    def run(self, stop: Callable[[], bool], sleep: Callable[[float], None] | None = None
            ) -> None:
        if sleep is not None:
            self.runner.sleep = sleep
        self.runner.run(until=stop)

    def close(self) -> None:
        self.runner.close()

    def summary(self) -> dict[str, Any]:
        return self.runner.summary()


def run_rov_bridge(
    path: str | Path | BridgeFile,
    *,
    jsonl: TextIO | None = None,
    clock: Callable[[], float] = time.monotonic,
    sleep: Callable[[float], None] | None = None,
    stop_event: threading.Event | None = None,
    recorder: FlightRecorder | None = None,
    opener: Opener | None = None,
    max_steps: int | None = None,
    ft: bool = True,
    on_epoch: Callable[[dict[str, Any]], None] | None = None,
) -> dict[str, Any]:
    """The Outland ROV of the config at ``path`` on the :class:`Runner` (tests, embedding)."""
    bf = path if isinstance(path, BridgeFile) else load_bridge_file(path)
    cfg, base = rov_config(bf)
    vehicle = OutlandRovVehicle(cfg, base, ft=ft, on_epoch=on_epoch)
    runner = Runner(vehicle, jsonl=jsonl, recorder=recorder, clock=clock, sleep=sleep,
                    opener=opener, handle_signals=False)
    return runner.run(max_steps=max_steps,
                      until=stop_event.is_set if stop_event is not None else None)


# --------------------------------------------------------------------------- CLI


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--config", required=True,
                        help="config file or preset name; [rover] -> rover, [rov] -> ROV; "
                             "[mavlink] attaches the router")
    parser.add_argument("--out", type=Path, default=None,
                        help="write epochs.jsonl/summary.json here (default: none); a disk "
                             "that is full, read-only or not writable is said once and "
                             "retried, the bridge runs on")
    parser.add_argument("--nmea-out", type=output_url_arg, default=None,
                        help="rover: corrected NMEA to this URL or pty:PATH "
                             "(default: the config's)")
    parser.add_argument("--mavlink", type=mavlink_url_arg, default=None,
                        help="rover: GPS_INPUT to this MAVLink URL (default: the config's)")
    parser.add_argument("--record", type=Path, default=None,
                        help="flight recorder directory (overrides [recorder] dir; as it, a "
                             "disk that cannot be written is said once and retried)")
    parser.add_argument("--duration", type=positive_float, default=None,
                        help="stop after this many seconds (default: until SIGTERM or ^C)")
    parser.add_argument("--json", action="store_true",
                        help="print the end summary as JSON (default: a table)")


def run(args: argparse.Namespace) -> int:
    bf = load_bridge_file(args.config)  # the one read of the file
    if bf.rover is None and bf.rov is None and bf.mavlink is not None:
        rparser = argparse.ArgumentParser(prog="fdi-bridge mavlink")  # the router alone
        mavlink_cmd.add_arguments(rparser)
        extra = ["--seconds", str(args.duration)] if args.duration else []
        margs = rparser.parse_args(["--config", str(bf.path), *extra])
        margs.bridge_file = bf  # read once
        margs.json = bool(getattr(args, "json", False))
        return int(mavlink_cmd.run(margs))
    view = console_status(args.config, bf)
    try:
        summary = run_file(bf, mavlink=bf.mavlink, out=args.out, record=args.record,
                           duration_s=args.duration, nmea_url=args.nmea_out,
                           mavlink_url=args.mavlink, status=view,
                           note=f"fdi-bridge run --config {args.config}")
    finally:
        view.close()
    print_run_summary(summary, as_json=bool(getattr(args, "json", False)))
    return 0


def print_run_summary(summary: dict[str, Any], *, as_json: bool) -> None:
    """The end summary on stdout: a table, or the summary as JSON with ``--json``."""
    if as_json:
        print(json.dumps(summary))
    else:
        print(run_summary_text(summary), flush=True)
