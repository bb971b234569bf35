"""Deterministic replay of a recorded live INS/GNSS session (``fdi-bridge replay`` of its
capture).

A ``fdi-bridge run`` of :class:`~firmware_host.insgnss.vehicle.InsGnssVehicle` with a flight
recorder keeps both of its inputs: the receiver's bytes on ``gps rx`` and the autopilot's
MAVLink bytes on ``imu rx``, each read written as one record, in the order the vehicle read
them (a step reads ``imu`` then ``gps``). :func:`replay_insgnss` runs the same vehicle logic on
those records in that order: each record is handed to the vehicle as the only bytes of one
step of the replay driver (:class:`~firmware_host.runtime.replay.ReplayDriver`), its fake
clock at the record's time, and the vehicle's pending epochs are drained after it (its
``check``), as live. The epochs the vehicle passes depend on
its data (the IMU samples' own stamps, the GNSS epochs), not on when they were read, so
``epochs.jsonl`` is the live run's, byte for byte.

What a replay cannot reproduce exactly: an epoch that live waited ``max_wait_s`` of wall
clock for its IMU samples (a stalled IMU link) is let go at the recorded time of the read
after the wait, within one read of the live decision. Outputs (GPS_INPUT, corrected NMEA)
are not sent again.
"""

from __future__ import annotations

import argparse
from collections.abc import Iterator
from pathlib import Path
from typing import Any, cast

from drivers.capture import CaptureReader
from drivers.resilient import ResilientPort
from fdi.errors import CaptureFormatError, FdiBridgeError
from firmware_host.insgnss.vehicle import InsGnssVehicle
from firmware_host.runtime.config import BridgeConfig, bridge_config, load_bridge_file, vehicle_of
from firmware_host.runtime.config_insgnss import InsGnssSetup
from firmware_host.runtime.replay import ReplayDriver, ReplayPort
from firmware_host.runtime.vehicle import Context

GPS_RX, IMU_RX = "gps rx", "imu rx"


def is_insgnss_capture(reader: CaptureReader) -> bool:
    """A recording of the live INS/GNSS vehicle: it has the ``gps rx`` and ``imu rx``
    channels."""
    names = {c.name for c in reader.channels}
    return GPS_RX in names and IMU_RX in names


def replay_insgnss(cfg_file: Path, capture: Path, out_dir: Path, *,
                   records: bool = True) -> dict[str, Any]:
    """Replay the INS/GNSS recording ``capture`` with the vehicle of ``cfg_file`` (the file
    it was recorded with); write ``out_dir/epochs.jsonl`` (not with ``records=False``) and
    ``summary.json``; return the summary."""
    reader = CaptureReader(capture)
    if not is_insgnss_capture(reader):
        raise CaptureFormatError(f"{capture}: not a live INS/GNSS recording (channels "
                                 f"{GPS_RX!r} and {IMU_RX!r})")
    bf = load_bridge_file(cfg_file)
    if vehicle_of(bf) != "rover" or bf.insgnss is None:
        raise FdiBridgeError(f"{capture} is a live INS/GNSS recording, but {cfg_file} is not "
                             "a live INS/GNSS file ([rover] and [insgnss])")
    return replay_with(bridge_config(bf), bf.insgnss, reader, out_dir,
                       config_name=str(cfg_file), records=records)


def replay_with(cfg: BridgeConfig, setup: InsGnssSetup, reader: CaptureReader, out_dir: Path, *,
                config_name: str = "", records: bool = True) -> dict[str, Any]:
    """The replay of :func:`replay_insgnss` with the configuration already loaded, on the
    replay driver (:class:`~firmware_host.runtime.replay.ReplayDriver`: data-paced, the fake
    clock at each record's time, never going back)."""
    ids = {c.name: i for i, c in enumerate(reader.channels)}
    gps_id, imu_id = ids[GPS_RX], ids[IMU_RX]
    gps, imu = ReplayPort(), ReplayPort()
    # no outputs: the replay writes the records, it does not send again
    vehicle = InsGnssVehicle(cfg, setup, nmea_url="", mavlink_url="")
    if not vehicle.live.imu_url:
        raise FdiBridgeError(f"{config_name}: [insgnss.live] imu_url is empty, but the "
                             "recording has the IMU")
    driver = ReplayDriver(out_dir, records=records)

    def steps() -> Iterator[float]:
        t0: int | None = None
        for rec in reader:  # each record the only bytes of one step, in the order read
            if rec.channel not in (gps_id, imu_id):
                continue
            if t0 is None:
                t0 = rec.t_us
            (gps if rec.channel == gps_id else imu).load(rec.data)
            yield (rec.t_us - t0) / 1e6

    ports = {"gps": cast(ResilientPort, gps), "imu": cast(ResilientPort, imu)}
    ctx = Context(clock=driver.clock, ports=ports, epochs=driver.epochs)
    driver.run(vehicle, steps(), start=lambda: vehicle.start(ctx))
    return driver.write_summary(driver.summary(
        vehicle.summary(), vehicle="insgnss", config=config_name,
        input={"kind": "insgnss capture", "notes": reader.all_notes()},
        facts={"records": driver.steps, "bytes_gps": gps.bytes_rx,
               "bytes_imu": imu.bytes_rx}))


def run(args: argparse.Namespace) -> dict[str, Any]:
    """``fdi-bridge replay`` of a live INS/GNSS recording (from
    :mod:`firmware_host.commands.replay`, which prints
    :func:`~firmware_host.commands.summaries.insgnss_replay_text`): needs ``--config``, the
    file it was recorded with; returns the summary."""
    if args.config is None:
        raise FdiBridgeError(f"{args.capture} is a live INS/GNSS recording: give --config with "
                             "the [rover] + [insgnss] file it was recorded with")
    if getattr(args, "nmea_out", None) or getattr(args, "mavlink", None):
        raise FdiBridgeError("--nmea-out / --mavlink: an INS/GNSS replay writes the records "
                             "only")
    return replay_insgnss(Path(args.config), Path(args.capture), Path(args.out),
                          records=not getattr(args, "no_records", False))
