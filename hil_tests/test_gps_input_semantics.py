"""What the autopilot fuses: GPS_INPUT field semantics over real UDP to a pymavlink autopilot.

Checked against ArduPilot's ``AP_GPS_MAV.cpp`` (``alt`` is used unless the ALT ignore flag is
set; an ignored velocity keeps the previous one; ``time_week = 0`` is accepted) and
``AP_GPS_NMEA.cpp`` (GGA quality 6 is no fix). Each test drives the real rover pipeline with
NMEA a receiver would send and reads the GPS_INPUT the autopilot stand-in receives.
"""

from __future__ import annotations

import calendar
import math
import threading
import time
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from drivers.configload import load_file
from drivers.gps.nmea import format_date, format_lat, format_lon, format_time, with_checksum
from drivers.mavlink import io as mio
from fdi.errors import ConfigError
from firmware_host.rover.outputs import MavlinkGpsSink, gps_week_ms, unix_time
from firmware_host.rover.pipeline import RoverPipeline
from firmware_host.runtime.config import BridgeConfig, RoverConfig, RoverOutputs

LAT0, LON0, ALT0 = 32.02, 118.85, 545.0
DATE = (2024, 6, 3)
KNOT = 1852.0 / 3600.0


def _gga(t: float, lat: float, lon: float, alt: float | None, quality: int = 2,
         bad: bool = False) -> bytes:
    la, ns = format_lat(lat)
    lo, ew = format_lon(lon)
    a = "" if alt is None else f"{alt:.3f}"
    line = with_checksum(f"GPGGA,{format_time(t)},{la},{ns},{lo},{ew},{quality},12,0.8,{a},M,"
                         f"0.000,M,1.0,0001")
    if bad:  # one flipped character: the checksum no longer matches
        line = line.replace(b",12,", b",13,", 1)
    return line


def _rmc(t: float, lat: float, lon: float, speed: float, course: float,
         date: tuple[int, int, int] | None = DATE) -> bytes:
    la, ns = format_lat(lat)
    lo, ew = format_lon(lon)
    d = format_date(date) if date else ""
    return with_checksum(f"GPRMC,{format_time(t)},A,{la},{ns},{lo},{ew},{speed / KNOT:.3f},"
                         f"{course:.1f},{d},,,D")


def _vtg(speed: float, course: float) -> bytes:
    return with_checksum(f"GPVTG,{course:.1f},T,,M,{speed / KNOT:.3f},N,{speed * 3.6:.3f},K,D")


def _track(n: int, rate_hz: float, speed: float = 2.0, course: float = 45.0,
           seed: int = 0, noise_m: float = 0.02) -> Iterator[tuple[float, float, float, float]]:
    """(utc s, lat, lon, alt) of a straight track, with a little seeded position noise."""
    rng = np.random.default_rng(seed)
    c = math.radians(course)
    for i in range(n):
        t = 36000.0 + i / rate_hz
        dn = speed * (i / rate_hz) * math.cos(c) + rng.normal(0, noise_m)
        de = speed * (i / rate_hz) * math.sin(c) + rng.normal(0, noise_m)
        lat = LAT0 + math.degrees(dn / 6378137.0)
        lon = LON0 + math.degrees(de / (6378137.0 * math.cos(math.radians(LAT0))))
        yield t, lat, lon, ALT0 + rng.normal(0, noise_m)


class _Autopilot(threading.Thread):
    """A pymavlink autopilot stand-in on 127.0.0.1 collecting what it receives."""

    def __init__(self) -> None:
        super().__init__(daemon=True)
        self.ep = mio.MavEndpoint("udpin:127.0.0.1:0", source_system=1, source_component=1)
        self.msgs: list[Any] = []
        self.halt = threading.Event()
        self.start()

    @property
    def url(self) -> str:
        addr = self.ep.local_address
        assert addr is not None
        return f"udpout:127.0.0.1:{addr[1]}"

    def run(self) -> None:
        while not self.halt.is_set():
            msg = self.ep.recv(0.05)
            if msg is not None:
                self.msgs.append(msg)

    def gps(self, n: int, deadline_s: float = 10.0) -> list[Any]:
        end = time.monotonic() + deadline_s
        while time.monotonic() < end and self._count() < n:
            time.sleep(0.01)  # the receiving thread collects; bounded by the deadline
        self.halt.set()
        self.join(timeout=2.0)
        self.ep.close()
        return [m for m in self.msgs if m.get_type() == "GPS_INPUT"]

    def _count(self) -> int:
        return sum(m.get_type() == "GPS_INPUT" for m in self.msgs)


def _run(lines: list[bytes], *, output: dict[str, Any] | None = None,
         clock: float | None = None) -> tuple[list[Any], MavlinkGpsSink, RoverPipeline]:
    ap = _Autopilot()
    out = RoverOutputs(mavlink_url=ap.url, **(output or {}))
    cfg = RoverConfig(output=out)
    sink = MavlinkGpsSink(cfg)
    if clock is not None:
        sink.wall_clock = lambda: clock  # type: ignore[method-assign]
    pipe = RoverPipeline(cfg, sinks=[sink])
    for i, line in enumerate(lines):
        pipe.feed(line)
        if i % 20 == 19:
            time.sleep(0.001)  # let the collector drain the socket buffer
    pipe.finish()
    return ap.gps(sink.sent), sink, pipe


def _assert_never_zero_alt_3d(gps: list[Any]) -> None:
    for m in gps:
        if m.fix_type >= 3:
            assert not m.ignore_flags & mio.GPS_INPUT_IGNORE_FLAG_ALT
            assert abs(m.alt - ALT0) < 1.0, f"3D fix with alt {m.alt}"


def test_rmc_only_receiver_sends_2d_fixes_with_the_alt_flag() -> None:  # item 1
    lines = [_rmc(t, la, lo, 2.0, 45.0) for t, la, lo, _ in _track(30, 1.0)]
    gps, sink, _ = _run(lines)
    assert len(gps) == 30
    assert all(m.fix_type == 2 and m.ignore_flags & mio.GPS_INPUT_IGNORE_FLAG_ALT for m in gps)
    assert sink.stats()["alt_unknown_2d"] == 30


def test_lost_gga_holds_the_last_altitude_with_raised_vertical_accuracy() -> None:  # item 1
    lines: list[bytes] = []
    lost = {5, 6, 12, 20, 21, 22}
    for i, (t, la, lo, alt) in enumerate(_track(40, 1.0, seed=1)):
        lines += [_gga(t, la, lo, alt, bad=i in lost), _rmc(t, la, lo, 2.0, 45.0)]
    gps, sink, _ = _run(lines)
    assert len(gps) == 40
    _assert_never_zero_alt_3d(gps)
    normal = max(m.vert_accuracy for i, m in enumerate(gps) if i not in lost)
    for i in lost:
        assert gps[i].fix_type == 3, "an RMC-only epoch is a receiver fix, not DGPS"
        assert gps[i].vert_accuracy > normal
    assert gps[22].vert_accuracy > gps[20].vert_accuracy  # grows with the altitude's age
    assert sink.stats()["alt_held"] == len(lost)


def test_receiver_dead_reckoning_quality_6_is_no_fix() -> None:  # item 2
    lines: list[bytes] = []
    dr = set(range(15, 20))
    for i, (t, la, lo, alt) in enumerate(_track(30, 1.0, seed=2)):
        lines += [_gga(t, la, lo, alt, quality=6 if i in dr else 2), _rmc(t, la, lo, 2.0, 45.0)]
    gps, sink, _ = _run(lines)
    assert len(gps) == 30
    for i, m in enumerate(gps):
        if i in dr:
            assert m.fix_type <= 1 and m.lat == 0 and m.lon == 0
        else:
            assert m.fix_type >= 3
    assert sink.stats()["estimated_no_fix"] == len(dr)


def test_gga_vtg_receiver_without_date_takes_the_system_date() -> None:  # item 3
    lines: list[bytes] = []
    for t, la, lo, alt in _track(20, 1.0, seed=3):
        lines += [_gga(t, la, lo, alt), _vtg(2.0, 45.0)]
    now = calendar.timegm((2024, 6, 3, 10, 0, 30))  # the system clock, 30 s after the first fix
    gps, sink, _ = _run(lines, clock=float(now))
    assert len(gps) == 20
    week, ms = gps_week_ms(unix_time(DATE, 36000.0))
    assert (gps[0].time_week, gps[0].time_week_ms) == (week, ms)
    assert sink.stats()["date_from_clock"] == 20


def test_no_date_and_no_clock_sends_week_zero() -> None:  # item 3
    lines: list[bytes] = []
    for t, la, lo, alt in _track(10, 1.0, seed=4):
        lines += [_gga(t, la, lo, alt), _vtg(2.0, 45.0)]
    gps, sink, _ = _run(lines, clock=1000.0)  # a companion whose clock was never set (1970)
    assert len(gps) == 10
    assert all(m.time_week == 0 and m.fix_type >= 3 for m in gps)
    assert gps[0].time_week_ms == 36000 * 1000  # UTC time of day
    assert sink.stats()["no_date"] == 10


@pytest.mark.parametrize("seed", [5, 6, 7])
def test_10hz_gga_with_1hz_rmc_never_leaves_a_stale_velocity(seed: int) -> None:  # item 4
    lines: list[bytes] = []
    for i, (t, la, lo, alt) in enumerate(_track(100, 10.0, seed=seed)):
        lines.append(_gga(t, la, lo, alt))
        if i % 10 == 0:
            lines.append(_rmc(t, la, lo, 2.0, 45.0))
    gps, sink, _ = _run(lines)
    fixes = [m for m in gps if m.fix_type >= 3]
    assert len(fixes) == 100
    vn = ve = 2.0 * math.cos(math.radians(45.0))
    for m in fixes:
        assert not m.ignore_flags & mio.GPS_INPUT_IGNORE_FLAG_VEL_HORIZ
        assert math.hypot(m.vn - vn, m.ve - ve) < 0.2
        assert m.speed_accuracy <= 2.0
    st = sink.stats()
    assert st["velocity_held"] >= 80 and st["velocity_unknown"] == 0


@pytest.mark.parametrize("seed", [8, 9])
def test_gga_only_receiver_velocity_from_positions(seed: int) -> None:  # item 4
    lines = [_gga(t, la, lo, alt) for t, la, lo, alt in _track(60, 10.0, seed=seed)]
    gps, sink, _ = _run(lines)
    assert len(gps) == 60
    truth = 2.0 * math.cos(math.radians(45.0))
    st = sink.stats()
    assert st["velocity_unknown"] == 5  # the first 0.5 s: no baseline yet
    for m in gps[:5]:  # sent as zero with an accuracy the EKF gives no weight, never stale
        assert (m.vn, m.ve) == (0.0, 0.0) and m.speed_accuracy >= 10.0
    errs = [math.hypot(m.vn - truth, m.ve - truth) for m in gps[5:]]
    accs = [m.speed_accuracy for m in gps[5:]]
    assert max(errs) < 0.3
    assert all(e <= a for e, a in zip(errs, accs, strict=True)), "accuracy must cover the error"


def test_gps_id_is_configurable_for_gps2() -> None:  # item 5
    lines: list[bytes] = []
    for t, la, lo, alt in _track(5, 1.0):
        lines += [_gga(t, la, lo, alt), _rmc(t, la, lo, 2.0, 45.0)]
    gps, _, _ = _run(lines, output={"gps_id": 1})
    assert len(gps) == 5 and all(m.gps_id == 1 for m in gps)


def test_yaw_encoding() -> None:  # item 5 (the encoder; see the report about HDT parsing)
    assert mio.gps_input_yaw(None) == 0
    assert mio.gps_input_yaw(0.0) == 36000 and mio.gps_input_yaw(360.0) == 36000
    assert mio.gps_input_yaw(90.004) == 9000 and mio.gps_input_yaw(-90.0) == 27000


def _write(tmp_path: Path, output: str) -> Path:
    p = tmp_path / "v.toml"
    p.write_text(f"[rover.output]\n{output}\n")
    return p


@pytest.mark.parametrize(("output", "mode"), [
    ('vehicle = "rover"', "HOLD"), ('vehicle = "sub"', "ALT_HOLD"),
    ('vehicle = "sub"\nalarm_mode = "SURFACE"', "SURFACE"),
    ('vehicle = "copter"\nalarm_mode = "LAND"', "LAND"),
    ('vehicle = "plane"\nalarm_mode = "CIRCLE"', "CIRCLE"),
])
def test_alarm_mode_defaults_and_named_modes_load(tmp_path: Path, output: str,
                                                  mode: str) -> None:  # item 6
    from drivers.mavlink.modes import alarm_mode

    cfg = load_file(BridgeConfig, _write(tmp_path, output))
    o = cfg.rover.output
    assert alarm_mode(o.vehicle, o.alarm_mode) == mode


@pytest.mark.parametrize("output", [
    'vehicle = "sub"\nalarm_mode = "HOLD"', 'vehicle = "copter"', 'vehicle = "plane"',
    'vehicle = "rover"\nalarm_mode = "AUTO"', 'vehicle = "tank"',
])
def test_invalid_alarm_mode_is_refused_at_load(tmp_path: Path, output: str) -> None:  # item 6
    with pytest.raises(ConfigError, match=r"alarm_mode|vehicle"):
        load_file(BridgeConfig, _write(tmp_path, output))


def test_sub_alarm_sends_alt_hold_and_keeps_the_gps_input(tmp_path: Path) -> None:  # item 6
    from firmware_host.commands.replay import build_sinks, run_replay
    from firmware_host.devtools.rover_sim import RoverScenario, write_run

    sc = RoverScenario(rate_hz=5.0, duration_s=150.0, seed=6, kinds=("frozen",),
                       frozen_s=20.0, fault_every_s=60.0)
    write_run(sc, tmp_path / "run")
    ap = _Autopilot()
    cfg = BridgeConfig()
    cfg = replace(cfg, rover=replace(cfg.rover, output=RoverOutputs(
        mavlink_url=ap.url, vehicle="sub")))
    run_replay(cfg, tmp_path / "run" / "rover.nmea", tmp_path / "out", speed=50.0,
               sinks=build_sinks(cfg, None, None))
    epochs = (tmp_path / "out" / "epochs.jsonl").read_text().splitlines()
    gps = ap.gps(len(epochs))
    assert len(gps) == len(epochs), "no epoch's GPS_INPUT is lost at the alarm"
    cmds = [m for m in ap.msgs if m.get_type() == "COMMAND_LONG"]
    assert cmds and cmds[0].command == 176 and cmds[0].param2 == 2  # DO_SET_MODE ALT_HOLD


def test_mode_tables_match_pymavlink() -> None:
    from drivers.mavlink.modes import MODES

    for vehicle, table in mio.pymavlink_mode_tables().items():
        ours = MODES[vehicle]
        for number, name in table.items():
            if name in ours:
                assert ours[name] == number, (vehicle, name)
        assert all(table.get(n) == name for name, n in ours.items()), vehicle


@pytest.mark.parametrize("answer", ["refuse", "accept", "silent"])
def test_direct_endpoint_confirms_the_mode_request(answer: str) -> None:  # item 7 (no router)
    import socket

    ap = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    ap.bind(("127.0.0.1", 0))
    ap.settimeout(0.2)
    ep = mio.MavEndpoint(f"udpout:127.0.0.1:{ap.getsockname()[1]}")
    ep.command_retry_s = 0.05
    packer = mio.MavPacker(1, 1)
    try:
        ep.request_mode(1, "HOLD", "rover")
        data, addr = ap.recvfrom(65535)
        assert mio.decode_packet(data).get_type() == "COMMAND_LONG"
        if answer != "silent":
            result = mio.MAV_RESULT_DENIED if answer == "refuse" else mio.MAV_RESULT_ACCEPTED
            ap.sendto(packer.send_command_ack(176, result, 1, 191), addr)
        end = time.monotonic() + 2.0
        while ep._pending is not None and time.monotonic() < end:
            ep.send_heartbeat()  # every later send looks for the answer (never blocks)
            time.sleep(0.01)
        st = ep.command_stats
        if answer == "refuse":
            assert st["command_refused"] == 1 and st["command_sent"] == 1
        elif answer == "accept":
            assert st["command_accepted"] == 1
        else:
            assert st["command_unacked"] == 1 and st["command_sent"] == ep.command_retries
    finally:
        ep.close()
        ap.close()
