"""``fdi-bridge run``: the bridge on the vehicle, with the configured ports.

For the rover: read the receiver's port, run the pipeline on every epoch, send the corrected
fixes on (NMEA port, MAVLink GPS_INPUT), and write ``epochs.jsonl`` when ``--out`` is given.
A port that errors or disappears is reported once and reopened with capped backoff; the
pipeline keeps its state, so data resumes without a restart. No valid epoch for
``rover.silence_s`` is reported as silence (once) and again when data returns.
"""

from __future__ import annotations

import argparse
import json
import logging
import time
from collections.abc import Callable
from pathlib import Path
from typing import TextIO

from drivers.transport import open_port, read_some
from fdi.errors import PortError
from firmware_host.config import BridgeConfig, load_config
from firmware_host.replay import build_sinks
from firmware_host.rover_pipeline import RoverPipeline

log = logging.getLogger("fdi_bridge.run")


def run_rover(
    cfg: BridgeConfig,
    *,
    jsonl: TextIO | None = None,
    nmea_url: str | None = None,
    mavlink_url: str | None = None,
    clock: Callable[[], float] = time.monotonic,
    sleep: Callable[[float], None] = time.sleep,
    stop: Callable[[], bool] = lambda: False,
    backoff_max_s: float = 5.0,
) -> RoverPipeline:
    sinks = build_sinks(cfg, nmea_url, mavlink_url)
    pipeline = RoverPipeline(cfg.rover, jsonl=jsonl, sinks=sinks)
    port = None
    backoff = 0.1
    reported_down = False
    last_epoch_t = clock()
    silent = False
    while not stop():
        if port is None:
            try:
                port = open_port(cfg.rover.port)
                if reported_down:
                    log.warning("%s is back", cfg.rover.port.url)
                reported_down = False
                backoff = 0.1
            except PortError as err:
                if not reported_down:
                    log.warning("%s; retrying with backoff up to %.0f s", err, backoff_max_s)
                    reported_down = True
                sleep(backoff)
                backoff = min(2 * backoff, backoff_max_s)
                continue
        try:
            data = read_some(port, 65536)
        except PortError as err:
            log.warning("%s; reopening", err)
            reported_down = True
            port.close()
            port = None
            continue
        if data and pipeline.feed(data):
            last_epoch_t = clock()
            if silent:
                log.warning("receiver data is back")
                silent = False
        elif not silent and clock() - last_epoch_t > cfg.rover.silence_s:
            log.warning("no valid epoch from the receiver for %.1f s", cfg.rover.silence_s)
            silent = True
    if port is not None:
        port.close()
    pipeline.finish()
    return pipeline


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--config", required=True, help="config file or preset name")
    parser.add_argument("--out", type=Path, default=None, help="write epochs.jsonl/summary.json")
    parser.add_argument("--nmea-out", default=None)
    parser.add_argument("--mavlink", default=None)


def run(args: argparse.Namespace) -> int:
    cfg = load_config(args.config)
    jsonl = None
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        jsonl = open(args.out / "epochs.jsonl", "w", encoding="utf-8")  # noqa: SIM115
    try:
        pipeline = run_rover(cfg, jsonl=jsonl, nmea_url=args.nmea_out, mavlink_url=args.mavlink)
    except KeyboardInterrupt:
        return 0
    finally:
        if jsonl is not None:
            jsonl.close()
    if args.out is not None:
        (args.out / "summary.json").write_text(json.dumps(pipeline.summary(), indent=2) + "\n")
    return 0
