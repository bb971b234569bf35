"""``fdi-bridge mavlink --config FILE``: the MAVLink router, with the file's vehicle if it has one.

A file with only ``[mavlink]`` (or no file) runs the router alone
(:func:`firmware_host.mavlink.router.run`, also ``--bench``). A file that also describes a
vehicle (``[rover]``, the ROV's keys) runs that vehicle on the one runtime with the router
attached, exactly as ``fdi-bridge run --config FILE`` does; ``--autopilot``, ``--gcs`` and
``--tlog-dir`` override the ``[mavlink]`` table and ``--seconds`` is the duration.
"""

from __future__ import annotations

import argparse
import json

from fdi.errors import ConfigError
from firmware_host.commands.launch import resolve_config_path, run_file, vehicle_of
from firmware_host.mavlink import router


def add_arguments(parser: argparse.ArgumentParser) -> None:
    router.add_arguments(parser)


def run(args: argparse.Namespace) -> int:
    if args.bench or not args.config:
        return router.run(args)
    path = resolve_config_path(args.config)
    try:
        vehicle_of(path)
    except ConfigError as err:
        if err.found == "neither":
            return router.run(args)  # the router alone
        raise
    args.config = str(path)
    summary = run_file(path, mavlink=router.config_from_args(args),
                       duration_s=args.seconds if args.seconds > 0 else None,
                       note=f"fdi-bridge mavlink --config {args.config}")
    print(json.dumps(summary))
    return 0
