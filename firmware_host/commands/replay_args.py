"""The arguments of ``fdi-bridge replay``, apart from the command so that ``--help`` is light.

:mod:`firmware_host.commands.replay` imports the pipeline and its outputs (pymavlink among them);
this module imports nothing of the project, so building the parser costs nothing.
"""

from __future__ import annotations

import argparse
from pathlib import Path


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("capture", type=Path, help="a capture file or a plain NMEA log")
    parser.add_argument("--config", help="config file or preset name (default: built-in)")
    parser.add_argument("--out", type=Path, required=True, help="output directory")
    parser.add_argument("--speed", type=float, default=0.0,
                        help="0 = as fast as possible (default); 1 = recorded pace; N = N× faster")
    parser.add_argument("--no-pty", action="store_true", help="feed the pipeline directly")
    parser.add_argument("--nmea-out", default=None,
                        help="corrected NMEA to this pyserial URL, or pty:LINKPATH")
    parser.add_argument("--mavlink", default=None,
                        help="GPS_INPUT to this MAVLink URL, e.g. udpout:127.0.0.1:14550")
