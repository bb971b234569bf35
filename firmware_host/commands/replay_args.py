"""The arguments of ``fdi-bridge replay``, apart from the command so that ``--help`` is light.

:mod:`firmware_host.commands.replay` imports the pipeline and its outputs (pymavlink among them);
this module imports only the argument checks (:mod:`firmware_host.commands.checks`, standard
library only), so building the parser costs nothing.
"""

from __future__ import annotations

import argparse

from firmware_host.commands.checks import (
    input_file_arg,
    mavlink_url_arg,
    non_negative_float,
    output_dir_arg,
    output_url_arg,
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("capture", type=input_file_arg,
                        help="a capture file (fdi-bridge record) or a plain NMEA log")
    parser.add_argument("--config", help="config file or preset name (default: built-in)")
    parser.add_argument("--out", type=output_dir_arg, required=True,
                        help="output directory for epochs.jsonl and summary.json "
                             "(created if missing; --no-records: summary.json only)")
    parser.add_argument("--speed", type=non_negative_float, default=0.0,
                        help="0 = as fast as possible; 1 = recorded pace; N = N times faster")
    parser.add_argument("--no-pty", action="store_true",
                        help="feed the pipeline directly instead of through a pty")
    parser.add_argument("--nmea-out", type=output_url_arg, default=None,
                        help="corrected NMEA to this pyserial URL, or pty:LINKPATH")
    parser.add_argument("--mavlink", type=mavlink_url_arg, default=None,
                        help="GPS_INPUT to this MAVLink URL, e.g. udpout:127.0.0.1:14550")
    parser.add_argument("--no-records", action="store_true",
                        help="summary only: no epochs.jsonl, and no per-epoch record built "
                             "where the vehicle does not need it (the rover); summary.json "
                             "is the same as with the records")
    parser.add_argument("--json", action="store_true",
                        help="print the summary as one JSON object instead of a table")
