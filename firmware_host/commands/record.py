"""``fdi-bridge record``: capture a serial port's raw bytes, timestamped, in the capture format.

The port is any pyserial URL. Every read is one record (t_us = wall-clock microseconds at the
read). The line settings go in the capture's header, so a replay sets up its pty the same way.
A port that goes away is reported once and reopened with capped backoff until it is back.
A full disk pauses the recording (logged once, the lost records counted and printed at the end)
without ending it; the file never holds a partial record in its middle.

On a terminal a progress line counts the bytes and their rate while it records (on
standard error, :mod:`firmware_host.commands.byte_rate`: nothing in a pipe, under systemd or with
``-q``); ^C ends it with what was recorded, said as such.
"""

from __future__ import annotations

import argparse
import logging
import time
from collections.abc import Callable
from pathlib import Path

from drivers.capture import CaptureWriter, Channel
from drivers.transport import SerialSettings, open_port, read_some
from fdi.errors import PortError
from firmware_host.commands.byte_rate import ByteRate
from firmware_host.commands.checks import (
    output_file_arg,
    positive_float,
    positive_int,
    serial_url_arg,
)
from firmware_host.commands.port_checks import check_port_opens

log = logging.getLogger("fdi_bridge.record")


def record(
    settings: SerialSettings,
    path: Path,
    *,
    duration_s: float | None = None,
    max_bytes: int | None = None,
    clock: Callable[[], float] = time.monotonic,
    sleep: Callable[[float], None] = time.sleep,
    stop: Callable[[], bool] = lambda: False,
    backoff_max_s: float = 5.0,
    on_open: Callable[[], None] | None = None,
    on_data: Callable[[int], None] | None = None,
) -> dict[str, int]:
    """Record until ``duration_s``, ``max_bytes``, ``stop()`` or ^C; return counters
    (``interrupted`` 1 after ^C: the file holds everything read until then). ``on_data(n)``:
    ``n`` bytes were just recorded (the progress line)."""
    channel = Channel(name="port", url=settings.url, baudrate=settings.baudrate,
                      bytesize=settings.bytesize, parity=settings.parity,
                      stopbits=settings.stopbits, direction="rx")
    start = clock()
    reopen = 0
    backoff = 0.1
    port = None
    interrupted = 0
    with CaptureWriter(path, [channel], note=f"fdi-bridge record {settings.url}") as cap:
        last_flush = clock()
        try:
            while not stop():
                if duration_s is not None and clock() - start >= duration_s:
                    break
                if max_bytes is not None and cap.bytes_written >= max_bytes:
                    break
                if port is None:
                    try:
                        port = open_port(settings)  # pyserial flushes the input on open
                        backoff = 0.1
                        if on_open is not None:
                            on_open()
                    except PortError as err:
                        if reopen == 0:
                            log.warning("%s", err)
                        reopen += 1
                        sleep(backoff)
                        backoff = min(backoff * 2, backoff_max_s)
                        continue
                try:
                    data = read_some(port, 65536)
                except PortError as err:
                    log.warning("%s; reopening", err)
                    port.close()
                    port = None
                    continue
                if data:
                    cap.write(0, data)
                    if on_data is not None:
                        on_data(len(data))
                if clock() - last_flush >= 1.0:
                    cap.flush()
                    last_flush = clock()
        except KeyboardInterrupt:  # ^C: the records so far are whole; the caller says so
            interrupted = 1
        if port is not None:
            port.close()
        cap.flush()
        return {"bytes": cap.bytes_written, "records": cap.records, "reopen_attempts": reopen,
                "lost_records": cap.lost_records, "lost_bytes": cap.lost_bytes,
                "write_errors": cap.write_errors, "interrupted": interrupted}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("url", type=serial_url_arg,
                        help="port URL: /dev/ttyUSB0, a pty path, socket://host:port ...")
    parser.add_argument("--baud", type=positive_int, default=9600, help="baud rate")
    parser.add_argument("--bytesize", type=int, choices=(5, 6, 7, 8), default=8,
                        help="data bits")
    parser.add_argument("--parity", choices=("N", "E", "O", "M", "S"), default="N",
                        help="parity: None, Even, Odd, Mark, Space")
    parser.add_argument("--stopbits", type=float, choices=(1.0, 1.5, 2.0), default=1.0,
                        help="stop bits")
    parser.add_argument("--out", type=output_file_arg, required=True,
                        help="capture file to write (its directory must exist)")
    parser.add_argument("--duration", type=positive_float, default=None,
                        help="seconds to record (default: until ^C)")
    parser.add_argument("--max-bytes", type=positive_int, default=None,
                        help="stop after this many bytes (default: no limit)")
    parser.add_argument("--wait", action="store_true",
                        help="wait for a missing port to appear (default: fail at once)")


def run(args: argparse.Namespace) -> int:
    settings = SerialSettings(url=args.url, baudrate=args.baud, bytesize=args.bytesize,
                              parity=args.parity, stopbits=args.stopbits, timeout_s=0.1)
    if not args.wait:  # a missing or forbidden port must not give an empty capture and exit 0
        check_port_opens(args.url, "port", args.baud, bytesize=args.bytesize,
                         parity=args.parity, stopbits=args.stopbits)
    with ByteRate(f"recording {args.url}") as bar:
        counts = record(settings, args.out, duration_s=args.duration,
                        max_bytes=args.max_bytes, on_data=bar.step)
    how = "stopped by ^C: " if counts["interrupted"] else ""
    print(f"{how}recorded {counts['bytes']} bytes in {counts['records']} records to {args.out}")
    if counts["lost_records"]:
        print(f"lost {counts['lost_records']} records ({counts['lost_bytes']} bytes) to disk "
              f"errors; the file holds whole records only")
    return 0
