"""GPS_INPUT ``yaw`` from the receiver's true heading, over real UDP to a pymavlink autopilot.

ArduPilot's ``AP_GPS_MAV.cpp``: ``have_yaw = packet.yaw != 0``, ``gps_yaw = wrap_360(yaw *
0.01)``; the field is centidegrees with 0 meaning "not available" and 36000 for north. The
rover pipeline is fed the NMEA a dual-antenna receiver sends (GGA, RMC, then HDT or THS) and
the GPS_INPUT the autopilot stand-in on 127.0.0.1 receives is read back.
"""

from __future__ import annotations

import time
from typing import Any

from drivers.gps.nmea import with_checksum
from firmware_host.rover.outputs import MavlinkGpsSink
from firmware_host.rover.pipeline import RoverPipeline
from firmware_host.runtime.config import RoverConfig, RoverOutputs
from hil_tests.test_gps_input_semantics import _Autopilot, _gga, _rmc, _track


def _epochs(n: int, heading: list[str | None], jump_at: frozenset[int] = frozenset(),
            jump_m: float = 0.0) -> list[bytes]:
    """GGA + RMC per epoch at 5 Hz, then the heading sentence body of that epoch (if any)."""
    lines: list[bytes] = []
    for i, (t, la, lo, alt) in enumerate(_track(n, 5.0, speed=2.0, course=45.0, seed=3)):
        if i in jump_at:
            la += jump_m / 111_320.0
        lines.append(_gga(t, la, lo, alt))
        lines.append(_rmc(t, la, lo, 2.0, 45.0))
        body = heading[i % len(heading)]
        if body is not None:
            lines.append(with_checksum(body))
    return lines


def _send(lines: list[bytes]) -> tuple[list[Any], RoverPipeline]:
    ap = _Autopilot()
    cfg = RoverConfig(output=RoverOutputs(mavlink_url=ap.url))
    sink = MavlinkGpsSink(cfg)
    pipe = RoverPipeline(cfg, sinks=[sink])
    for i, line in enumerate(lines):
        pipe.feed(line)
        if i % 20 == 19:
            time.sleep(0.001)  # let the collector drain the socket buffer
    pipe.finish()
    return ap.gps(sink.sent), pipe


def test_hdt_goes_out_as_yaw_in_centidegrees() -> None:
    headings = ["GPHDT,274.07,T", "GPHDT,0.00,T", "GPHDT,359.996,T", "GPHDT,45.5,T"]
    gps, _ = _send(_epochs(20, headings))
    assert len(gps) == 20
    # 0.00 and 359.996 are north: 36000, never 0 (which would mean "no yaw").
    assert [m.yaw for m in gps] == [27407, 36000, 36000, 4550] * 5
    assert all(m.fix_type >= 3 for m in gps)


def test_epoch_without_heading_sends_zero() -> None:
    gps, _ = _send(_epochs(20, ["GPHDT,120.0,T", None, "GPHDT,,T"]))
    assert len(gps) == 20
    want = [12000 if i % 3 == 0 else 0 for i in range(20)]  # never held from the last epoch
    assert [m.yaw for m in gps] == want


def test_ths_only_mode_a_is_a_heading() -> None:
    gps, _ = _send(_epochs(20, ["GPTHS,77.52,A", "GPTHS,77.52,V", "GPTHS,77.52,E",
                                "GPTHS,,V", "GPTHS,10.0,M"]))
    assert len(gps) == 20
    assert [m.yaw for m in gps] == [7752, 0, 0, 0, 0] * 4


def test_replaced_fix_keeps_only_its_own_epochs_heading() -> None:
    """A 40 m jump for a few epochs: the replaced fixes carry that epoch's HDT, or 0."""
    lines = _epochs(60, ["GPHDT,33.0,T", None], jump_at=frozenset(range(30, 34)), jump_m=40.0)
    gps, pipe = _send(lines)
    assert len(gps) == 60
    assert pipe.actions["accept"] < 60, "the jump was not replaced: the test checks nothing"
    for i, m in enumerate(gps):
        if m.fix_type >= 2:
            assert m.yaw == (3300 if i % 2 == 0 else 0), (i, m.yaw)
        else:
            assert m.yaw == 0
