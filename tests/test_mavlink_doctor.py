"""``doctor`` with a MAVLink output: a 1 Hz receiver is flagged (ArduPilot's GPS health check
wants a fix every ~215 ms), and the tlog / parameter file directories are checked."""

from __future__ import annotations

import os
import threading
import time
from pathlib import Path

import pytest

from drivers.gps.nmea import format_lat, format_lon, format_time, with_checksum
from drivers.ptypair import PtyPair
from firmware_host.commands.doctor import Report, check_gps_rate, check_mavlink_disk
from firmware_host.runtime.config import load_bridge_file, mavlink_config


def _feed(pty: PtyPair, rate_hz: float, seconds: float, stop: threading.Event) -> None:
    la, ns = format_lat(32.02)
    lo, ew = format_lon(118.85)
    t0 = time.monotonic()
    i = 0
    while not stop.is_set() and time.monotonic() - t0 < seconds:
        t = 36000.0 + i / rate_hz
        line = with_checksum(f"GPGGA,{format_time(t)},{la},{ns},{lo},{ew},1,10,0.9,10.0,M,0.0,M,,")
        os.write(pty.master_fd, line)
        i += 1
        stop.wait(max(0.0, t0 + i / rate_hz - time.monotonic()))


@pytest.mark.parametrize(("rate_hz", "warns"), [(1.0, True), (10.0, False)])
def test_gps_rate_warning(rate_hz: float, warns: bool) -> None:
    pty = PtyPair()
    stop = threading.Event()
    feeder = threading.Thread(target=_feed, args=(pty, rate_hz, 4.0, stop), daemon=True)
    try:
        feeder.start()
        rep = Report()
        check_gps_rate(rep, pty.url, 9600, 3.2)
    finally:
        stop.set()
        feeder.join(timeout=2.0)
        pty.close()
    text = " ".join(rep.warnings)
    assert ("215 ms" in text) is warns, rep
    if not warns:
        assert any("GPS rate: 10.0 Hz" in m for m in rep.ok), rep


def test_mavlink_disk_checks(tmp_path: Path) -> None:
    cfg = tmp_path / "v.toml"
    ro = tmp_path / "ro"
    cfg.write_text(f'[mavlink]\ntlog_dir = "{tmp_path / "tlog"}"\ntlog_min_free_bytes = 0\n'
                   f'param_file = "{ro / "p.toml"}"\n[rover.port]\nurl = "loop://"\n'
                   f'[rover.output]\nmavlink_url = "udpout:127.0.0.1:14550"\n')
    rep = Report()  # diagnose() calls it for a file with [mavlink]
    check_mavlink_disk(rep, mavlink_config(load_bridge_file(cfg)))
    assert any("mavlink tlog" in m and "writable" in m for m in rep.ok), rep.lines()
    assert any("mavlink parameter file" in m for m in rep.ok), rep.lines()
    cfg.write_text(cfg.read_text().replace("tlog_min_free_bytes = 0",
                                           "tlog_min_free_bytes = 1099511627776000"))
    rep = Report()
    check_mavlink_disk(rep, mavlink_config(load_bridge_file(cfg)))
    assert any("pauses until space returns" in m for m in rep.warnings), rep.lines()
