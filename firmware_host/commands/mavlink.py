"""``fdi-bridge mavlink``: the MAVLink router as a command, with the file's vehicle if it has one,
and ``--bench``, a developer tool (:mod:`firmware_host.devtools.router_bench`, where the command
line sends it when the dev extra is installed: :data:`firmware_host.cli.DEV_OPTIONS`).

A file with only ``[mavlink]`` (or no file) runs the router alone. A file that also has a
vehicle (``[rover]``, ``[rov]``) runs that vehicle on the one runtime with the router attached,
exactly as ``fdi-bridge run --config FILE`` does (:func:`firmware_host.commands.launch.run_file`);
``--autopilot``, ``--gcs`` and ``--tlog-dir`` override the ``[mavlink]`` table and ``--seconds``
is the duration.

The command lives here, above the router, so that :mod:`firmware_host.mavlink.router` imports
neither the vehicles nor the benchmark (both import the router).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import sys
import time
from typing import Any

import firmware_host
from fdi.errors import UsageError
from firmware_host.commands.checks import (
    mavlink_url_arg,
    non_negative_float,
    output_dir_arg,
    positive_float,
    positive_int,
)
from firmware_host.commands.launch import run_file
from firmware_host.commands.live import console_status, router_table, run_summary_text
from firmware_host.commands.tables import fields
from firmware_host.mavlink.router import open_router
from firmware_host.runtime.config import BridgeFile, load_bridge_file, mavlink_config
from firmware_host.runtime.config_mavlink import EndpointConfig, MavlinkConfig

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
        "--bench", action="store_true",
        help="measure forwarding latency at 1 000 and 10 000 pkt/s (a developer tool: the dev "
             "extra)")
    parser.add_argument("--bench-rate", type=positive_int, action="append",
                        help="packets/s (repeatable)")
    parser.add_argument("--bench-seconds", type=positive_float, default=5.0,
                        help="seconds per run")
    parser.add_argument("--bench-runs", type=positive_int, default=1, help="runs per rate")
    parser.add_argument("--json", action="store_true",
                        help="print the end summary as JSON (default: a table)")


def config_from_args(args: argparse.Namespace, bf: BridgeFile) -> MavlinkConfig:
    """The file's ``[mavlink]`` (defaults without one) with the command line's overrides."""
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
    return dataclasses.replace(cfg, **changes)


def run(args: argparse.Namespace) -> int:
    if getattr(args, "bench", False):  # the CLI sends --bench to the developer tool
        raise UsageError("--bench is a developer tool: run it as fdi-bridge mavlink --bench "
                         "(pip install 'fdi-bridge[dev]')")
    bf: BridgeFile | None = getattr(args, "bridge_file", None)  # already read by `run`
    if bf is None and not (args.config or args.autopilot or args.gcs):
        raise UsageError("give --config FILE, or --autopilot URL and --gcs URL (the defaults "
                         "would route udpin:127.0.0.1:14555 <-> udpin:127.0.0.1:14550 silently)")
    as_json = bool(getattr(args, "json", False))
    if bf is None:
        bf = load_bridge_file(args.config) if args.config else BridgeFile()
    cfg = config_from_args(args, bf)
    if bf.rover is not None or bf.rov is not None:  # the vehicle, on the runtime
        view = console_status(args.config, bf)
        try:
            summary = run_file(bf, mavlink=cfg,
                               duration_s=args.seconds if args.seconds > 0 else None,
                               note=f"fdi-bridge mavlink --config {args.config}", status=view)
        finally:
            view.close()
        if as_json:
            print(json.dumps(summary))
        else:
            print(run_summary_text(summary), flush=True)
        return 0
    router = open_router(cfg)
    log.info("routing %s <-> %s", cfg.autopilot.url, ", ".join(g.url for g in cfg.gcs))
    quiet = logging.getLogger().getEffectiveLevel() > logging.WARNING
    if not quiet:
        gcs = ", ".join(g.url for g in cfg.gcs) or "no ground station"
        tlog = f", tlog in {cfg.tlog_dir}" if cfg.tlog_dir else ""
        until = f"for {args.seconds:g} s" if args.seconds > 0 else "until ^C"
        print(f"fdi-bridge {firmware_host.__version__}: routing {cfg.autopilot.url} <-> {gcs}"
              f"{tlog}, {until}", file=sys.stderr, flush=True)
    t0 = time.monotonic()
    deadline = t0 + args.seconds if args.seconds > 0 else None
    out: dict[str, Any] = {}
    stopped = "duration" if deadline is not None else "end"
    try:
        while deadline is None or time.monotonic() < deadline:
            router.poll(0.05)
    except KeyboardInterrupt:
        stopped = "SIGINT"
    finally:
        router.close()
        out["router"] = router.summary()
        out["runtime"] = {"stopped_by": stopped, "elapsed_s": round(time.monotonic() - t0, 3)}
        if as_json:
            print(json.dumps(out))
        else:
            print(fields([("stopped by", stopped, f"after {out['runtime']['elapsed_s']:.1f} s"),
                          ("tlog", out["router"].get("tlog_packets", "none"),
                           "packets" if "tlog_packets" in out["router"] else "")]))
            print("\n" + router_table(out["router"]), flush=True)
    return 0
