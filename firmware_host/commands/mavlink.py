"""``fdi-bridge mavlink``: the MAVLink router as a command, with the rover pipeline when the file
has a ``[rover]`` table (:mod:`firmware_host.mavlink.rover`) and ``--bench``
(:mod:`firmware_host.devtools.router_bench`).

The command lives here, above the router, so that :mod:`firmware_host.mavlink.router` imports
neither the rover wiring nor the benchmark (both import the router).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import threading
import time
from collections.abc import Callable
from typing import Any

from fdi.errors import UsageError
from firmware_host.commands.checks import (
    mavlink_url_arg,
    non_negative_float,
    output_dir_arg,
    positive_float,
    positive_int,
)
from firmware_host.devtools.router_bench import bench_forwarding
from firmware_host.mavlink.params import ParamStore
from firmware_host.mavlink.router import Router
from firmware_host.mavlink.rover import attach_rover, run_rover_reader
from firmware_host.rover.pipeline import RoverPipeline
from firmware_host.runtime.config import BridgeFile, load_bridge_file, mavlink_config
from firmware_host.runtime.config_mavlink import EndpointConfig

log = logging.getLogger("fdi_bridge.router")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--config", help="vehicle TOML file or preset with a [mavlink] table")
    parser.add_argument("--autopilot", type=mavlink_url_arg,
                        help="override [mavlink].autopilot.url, e.g. udpin:127.0.0.1:14555")
    parser.add_argument("--baud", type=positive_int, help="override the autopilot's baud rate")
    parser.add_argument("--gcs", type=mavlink_url_arg, action="append",
                        help="GCS endpoint URL, e.g. udpout:127.0.0.1:14550 (repeatable)")
    parser.add_argument("--tlog-dir", type=output_dir_arg, help="record a .tlog here")
    parser.add_argument("--seconds", type=non_negative_float, default=0.0,
                        help="stop after this long, s (0: until ^C)")
    parser.add_argument(
        "--bench", action="store_true", help="measure forwarding latency at 1 000 and 10 000 pkt/s"
    )
    parser.add_argument("--bench-rate", type=positive_int, action="append",
                        help="packets/s (repeatable)")
    parser.add_argument("--bench-seconds", type=positive_float, default=5.0,
                        help="seconds per run")
    parser.add_argument("--bench-runs", type=positive_int, default=1, help="runs per rate")


def run(args: argparse.Namespace) -> int:
    if args.bench:
        for rate in args.bench_rate or (1000, 10000):
            for _ in range(max(1, args.bench_runs)):
                print(json.dumps(bench_forwarding(rate, args.bench_seconds)), flush=True)
        return 0
    bf: BridgeFile | None = getattr(args, "bridge_file", None)  # already read by `run`
    if bf is None and not (args.config or args.autopilot or args.gcs):
        raise UsageError("give --config FILE, or --autopilot URL and --gcs URL (the defaults "
                         "would route udpin:127.0.0.1:14555 <-> udpin:127.0.0.1:14550 silently)")
    if bf is None:
        bf = load_bridge_file(args.config) if args.config else BridgeFile()
    cfg = mavlink_config(bf)
    changes: dict[str, Any] = {}
    if args.autopilot or args.baud:
        changes["autopilot"] = dataclasses.replace(
            cfg.autopilot,
            url=args.autopilot or cfg.autopilot.url,
            baud=args.baud or cfg.autopilot.baud,
        )
    if args.gcs:
        changes["gcs"] = tuple(EndpointConfig(u) for u in args.gcs)
    if args.tlog_dir:
        changes["tlog_dir"] = args.tlog_dir
    cfg = dataclasses.replace(cfg, **changes)
    params = ParamStore(cfg.param_file or None)
    router = Router(cfg, params=params)
    log.info("routing %s <-> %s", cfg.autopilot.url, ", ".join(g.url for g in cfg.gcs))
    rover = _start_rover(bf, router)
    deadline = time.monotonic() + args.seconds if args.seconds > 0 else None
    summary: dict[str, Any] = {}
    try:
        while deadline is None or time.monotonic() < deadline:
            router.poll(0.05)
    except KeyboardInterrupt:
        pass
    finally:
        if rover is not None:
            summary["rover"] = rover()
        router.close()
        summary["router"] = router.summary()
        print(json.dumps(summary))
    return 0


def _start_rover(bf: BridgeFile, router: Router) -> Callable[[], dict[str, Any]] | None:
    """With a ``[rover]`` table in the config, run the rover pipeline on its receiver port.

    Returns a function that stops it and gives its summary; None without a ``[rover]`` table.
    """
    if bf.rover is None:
        return None
    pipeline = RoverPipeline(bf.rover)
    attach_rover(pipeline, router)
    stop = threading.Event()
    thread = threading.Thread(
        target=run_rover_reader, args=(pipeline, stop), name="rover", daemon=True
    )
    thread.start()
    log.info("rover pipeline on %s, corrected fixes to the autopilot", bf.rover.port.url)

    def finish() -> dict[str, Any]:
        stop.set()
        thread.join(timeout=2.0)
        pipeline.finish()
        return pipeline.summary()

    return finish
