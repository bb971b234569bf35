"""Deterministic replay of a recorded live INS/GNSS session (``fdi-bridge replay`` of its
capture).

A ``fdi-bridge run`` of :class:`~firmware_host.insgnss.vehicle.InsGnssVehicle` with a flight
recorder keeps both of its inputs: the receiver's bytes on ``gps rx`` and the autopilot's
MAVLink bytes on ``imu rx``, each read written as one record, in the order the vehicle read
them (a step reads ``imu`` then ``gps``). :func:`replay_insgnss` runs the same vehicle logic on
those records in that order: each record is handed to the vehicle as the only bytes of one
step, on a :class:`~firmware_host.runtime.loop.FakeClock` at the record's time, and the
vehicle's pending epochs are drained after it, as live. The epochs the vehicle passes depend on
its data (the IMU samples' own stamps, the GNSS epochs), not on when they were read, so
``epochs.jsonl`` is the live run's, byte for byte.

What a replay cannot reproduce exactly: an epoch that live waited ``max_wait_s`` of wall
clock for its IMU samples (a stalled IMU link) is let go at the recorded time of the read
after the wait, within one read of the live decision. Outputs (GPS_INPUT, corrected NMEA)
are not sent again.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any, cast

from drivers.capture import CaptureReader
from drivers.resilient import ResilientPort
from fdi.errors import CaptureFormatError, FdiBridgeError
from firmware_host.insgnss.vehicle import InsGnssVehicle
from firmware_host.runtime.config import BridgeConfig, bridge_config, load_bridge_file, vehicle_of
from firmware_host.runtime.config_insgnss import InsGnssSetup
from firmware_host.runtime.loop import FakeClock
from firmware_host.runtime.records import EpochLog
from firmware_host.runtime.vehicle import Context

GPS_RX, IMU_RX = "gps rx", "imu rx"


def is_insgnss_capture(reader: CaptureReader) -> bool:
    """A recording of the live INS/GNSS vehicle: it has the ``gps rx`` and ``imu rx``
    channels."""
    names = {c.name for c in reader.channels}
    return GPS_RX in names and IMU_RX in names


class ReplayPort:
    """A port in the replay: a read returns the bytes loaded for this step (then nothing)."""

    up = True

    def __init__(self) -> None:
        self.pending = b""
        self.bytes_rx = 0

    def load(self, data: bytes) -> None:
        self.pending = data

    def read_some(self, size: int) -> bytes:
        data, self.pending = self.pending[:size], self.pending[size:]
        self.bytes_rx += len(data)
        return data

    def wait_s(self) -> float:
        return 0.0


def replay_insgnss(cfg_file: Path, capture: Path, out_dir: Path) -> dict[str, Any]:
    """Replay the INS/GNSS recording ``capture`` with the vehicle of ``cfg_file`` (the file
    it was recorded with); write ``out_dir/epochs.jsonl`` and ``summary.json``; return the
    summary."""
    reader = CaptureReader(capture)
    if not is_insgnss_capture(reader):
        raise CaptureFormatError(f"{capture}: not a live INS/GNSS recording (channels "
                                 f"{GPS_RX!r} and {IMU_RX!r})")
    bf = load_bridge_file(cfg_file)
    if vehicle_of(bf) != "rover" or bf.insgnss is None:
        raise FdiBridgeError(f"{capture} is a live INS/GNSS recording, but {cfg_file} is not "
                             "a live INS/GNSS file ([rover] and [insgnss])")
    return replay_with(bridge_config(bf), bf.insgnss, reader, out_dir,
                       config_name=str(cfg_file))


def replay_with(cfg: BridgeConfig, setup: InsGnssSetup, reader: CaptureReader, out_dir: Path, *,
                config_name: str = "") -> dict[str, Any]:
    """The replay of :func:`replay_insgnss` with the configuration already loaded."""
    ids = {c.name: i for i, c in enumerate(reader.channels)}
    gps_id, imu_id = ids[GPS_RX], ids[IMU_RX]
    clock = FakeClock(0.0)
    gps, imu = ReplayPort(), ReplayPort()
    # no outputs: the replay writes the records, it does not send again
    vehicle = InsGnssVehicle(cfg, setup, nmea_url="", mavlink_url="")
    if not vehicle.live.imu_url:
        raise FdiBridgeError(f"{config_name}: [insgnss.live] imu_url is empty, but the "
                             "recording has the IMU")
    epochs = EpochLog(out_dir)
    ports = {"gps": cast(ResilientPort, gps), "imu": cast(ResilientPort, imu)}
    records = 0
    t0: int | None = None
    try:
        vehicle.start(Context(clock=clock, ports=ports, epochs=epochs))
        for rec in reader:
            if rec.channel not in (gps_id, imu_id):
                continue
            if t0 is None:
                t0 = rec.t_us
            t = (rec.t_us - t0) / 1e6
            clock.now = max(clock.now, t)
            (gps if rec.channel == gps_id else imu).load(rec.data)
            vehicle.step(clock.now)
            vehicle.check(clock.now)
            records += 1
        vehicle.finish()
    finally:
        epochs.close()
    notes = reader.all_notes()
    summary = dict(vehicle.summary())
    summary["vehicle"] = "insgnss"
    summary["config"] = config_name
    summary["epochs"] = epochs.lines
    summary["input"] = {"kind": "insgnss capture", "notes": notes}
    summary["replay"] = {"records": records, "bytes_gps": gps.bytes_rx,
                         "bytes_imu": imu.bytes_rx}
    epochs.write_summary(summary)
    return summary


def result_text(summary: dict[str, Any], out_dir: Path) -> str:
    """The replay's result for a human."""
    ins = summary.get("ins", {})
    modes = ins.get("epochs", {})
    r = summary["replay"]
    return (f"INS/GNSS replay: {r['records']} records ({r['bytes_imu']} IMU bytes, "
            f"{r['bytes_gps']} GNSS bytes), {summary['epochs']} epochs: "
            f"{modes.get('ins', 0)} by the INS, {modes.get('rover', 0)} by the rover detector"
            f"\nwrote {out_dir / 'epochs.jsonl'} and {out_dir / 'summary.json'}")


def run(args: argparse.Namespace) -> dict[str, Any]:
    """``fdi-bridge replay`` of a live INS/GNSS recording (from
    :mod:`firmware_host.commands.replay`, which prints): needs ``--config``, the file it was
    recorded with; returns the summary."""
    if args.config is None:
        raise FdiBridgeError(f"{args.capture} is a live INS/GNSS recording: give --config with "
                             "the [rover] + [insgnss] file it was recorded with")
    if getattr(args, "nmea_out", None) or getattr(args, "mavlink", None):
        raise FdiBridgeError("--nmea-out / --mavlink: an INS/GNSS replay writes the records "
                             "only")
    return replay_insgnss(Path(args.config), Path(args.capture), Path(args.out))
