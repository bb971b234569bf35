"""Issue E: data a real autopilot accepts, and a journal worth reading.

* a no-fix GPS_INPUT carries ``satellites_visible = 0`` (ArduPilot's GPS_RAW_INT otherwise
  shows "no fix, 10 satellites");
* ``sim rover`` dates its NMEA after 2022-01-01 (AP_GPS refuses earlier GPS times);
* on the project's own healthy receiver the default preset logs no gate-health line at ``-v``,
  while a gate that really cannot see the minimum jump is said once, not every 10 s.
"""

from __future__ import annotations

import logging
import os
import socket
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest

from drivers.capture import CaptureReader
from drivers.gps.nmea import format_date, format_lat, format_lon, format_time, with_checksum
from drivers.ptypair import PtyPair
from drivers.ratelog import RateLimitedLog
from drivers.transport import SerialSettings
from fdi.gate_health import GateHealthReport
from firmware_host.cli import main
from firmware_host.commands.live import status_line
from firmware_host.commands.run import RoverBridge
from firmware_host.devtools.rover_sim import RoverScenario, generate
from firmware_host.rover.outputs import MavlinkGpsSink
from firmware_host.rover.pipeline import RoverPipeline
from firmware_host.runtime.config import BridgeConfig, RoverConfig


class _Endpoint:
    """Records what the sink sends (the sink under test is real)."""

    def __init__(self) -> None:
        self.fixes: list[Any] = []

    def send_heartbeat(self) -> bytes:
        return b""

    def send_gps_input(self, fix: Any) -> bytes:
        self.fixes.append(fix)
        return b""

    def send_statustext(self, severity: int, text: str) -> bytes:
        return b""

    def request_mode(self, *args: Any) -> None:
        pass

    def close(self) -> None:
        pass


def _epoch(k: int, quality: int, sats: int) -> bytes:
    ts = format_time(36000.0 + 0.1 * k)
    la, ns = format_lat(32.02 + 1e-6 * k)
    lo, ew = format_lon(118.85)
    pos = f"{la},{ns},{lo},{ew}" if quality else ",,,"
    gga = with_checksum(f"GPGGA,{ts},{pos},{quality},{sats:02d},0.9,10.0,M,3.0,M,,")
    rmc = with_checksum(f"GPRMC,{ts},{'A' if quality else 'V'},{pos},0.0,0.0,"
                        f"{format_date((2025, 5, 12))},,,{'D' if quality else 'N'}")
    return gga + rmc


@pytest.mark.parametrize(("quality", "sats_sent"), [(2, 10), (0, 0), (6, 0), (7, 0)])
def test_no_fix_gps_input_has_no_satellites(quality: int, sats_sent: int) -> None:
    cfg = BridgeConfig().rover
    ep = _Endpoint()
    pipe = RoverPipeline(cfg, sinks=[MavlinkGpsSink(cfg, endpoint=ep)])  # type: ignore[arg-type]
    data = b"".join(_epoch(k, 2, 10) for k in range(5)) + _epoch(5, quality, 10) + _epoch(
        6, 2, 10)
    pipe.feed(data)
    pipe.finish()
    fix = ep.fixes[5]
    assert fix.fix_type == (4 if quality == 2 else 1)
    assert fix.satellites_visible == sats_sent
    assert ep.fixes[4].satellites_visible == 10


def test_simulated_receiver_is_dated_after_2022(tmp_path: Path) -> None:
    _t, data, _truth = next(generate(RoverScenario(duration_s=1.0)))
    rmc = next(line for line in data.split(b"\r\n") if line.startswith(b"$GPRMC"))
    ddmmyy = rmc.split(b",")[9].decode()
    assert 2000 + int(ddmmyy[4:]) >= 2022, rmc
    assert main(["sim", "rover", "--duration", "2", "--zda", "--out", str(tmp_path)]) == 0
    text = (tmp_path / "rover.nmea").read_bytes()
    zda = next(line for line in text.split(b"\r\n") if line.startswith(b"$GPZDA"))
    assert int(zda.split(b",")[4]) >= 2022
    first = next(iter(CaptureReader(tmp_path / "rover.cap")))
    assert first.t_us >= 1_640_995_200_000_000  # 2022-01-01T00:00:00Z


def _gate_records(caplog: pytest.LogCaptureFixture) -> list[logging.LogRecord]:
    return [r for r in caplog.records if "gate health" in r.getMessage()
            and r.levelno >= logging.INFO]


def test_healthy_receiver_logs_no_gate_health_at_info(caplog: pytest.LogCaptureFixture) -> None:
    """10 minutes of the simulator's clean receiver at 10 Hz, the default preset: on main this
    logged an INFO "gate health: ... S is much larger ..." every 100 epochs (60 lines here,
    8 640 a day); now none."""
    sc = RoverScenario(duration_s=600.0, seed=3, kinds=())
    pipe = RoverPipeline(BridgeConfig().rover)
    with caplog.at_level(logging.INFO, logger="fdi_bridge"):
        for _t, data, _truth in generate(sc):
            pipe.feed(data)
        pipe.finish()
    assert pipe.epochs == 6000
    assert pipe.summary()["gate_health"]["status"] != "ok"  # still in the summary
    assert _gate_records(caplog) == []


def test_gate_that_cannot_see_the_minimum_jump_is_said_once(
        caplog: pytest.LogCaptureFixture) -> None:
    """The chi-square test alone (no grey test to cover it) with R far too wide: inert for
    1.05 m jumps, a warning -- once, not every 10 s of the run."""
    base = BridgeConfig().rover
    cfg = replace(base, detector=replace(base.detector, strategy="chi2", sigma_m=3.0))
    now = [0.0]  # the receiver's time: the rate limit of the old code let one through a 10 s
    ratelog = RateLimitedLog(logging.getLogger("fdi_bridge.rover"), clock=lambda: now[0])
    pipe = RoverPipeline(cfg, ratelog=ratelog)
    with caplog.at_level(logging.INFO, logger="fdi_bridge"):
        for t, data, _truth in generate(RoverScenario(duration_s=300.0, seed=3, kinds=())):
            now[0] = t
            pipe.feed(data)
    warnings = [r for r in _gate_records(caplog) if r.levelno == logging.WARNING]
    assert len(warnings) == 1, [r.getMessage()[:80] for r in _gate_records(caplog)]
    assert "far below" in warnings[0].getMessage()


def test_status_line_shows_the_fix_under_a_pty(tmp_path: Path) -> None:
    """The rover's status line, from a receiver on a pty to GPS_INPUT on a real UDP socket on
    127.0.0.1: the receiver's fix (quality, satellites, HDOP), the output's position from the
    first fix and its speed, what was sent (the decision, GPS_INPUT's fix type, accuracy) and
    the receiver's sentences."""
    sc = RoverScenario(rate_hz=10.0, duration_s=4.0, seed=2, kinds=())
    epochs = [data for _t, data, _truth in generate(sc)]
    sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sink.bind(("127.0.0.1", 0))
    pty = PtyPair(link=tmp_path / "gps")
    rc = RoverConfig()
    cfg = BridgeConfig(rover=replace(
        rc, port=SerialSettings(url=pty.url, baudrate=38400, timeout_s=0.02),
        output=replace(rc.output, mavlink_url=f"udpout:127.0.0.1:{sink.getsockname()[1]}")))
    bridge = RoverBridge(cfg)
    try:
        deadline = time.monotonic() + 20.0
        sent = 0
        while bridge.pipeline.epochs < 30 and time.monotonic() < deadline:
            if sent < len(epochs) and sent - bridge.pipeline.epochs < 10:
                os.write(pty.master_fd, epochs[sent])
                sent += 1
            bridge.step()
        line = status_line(bridge.runner.snapshot())
        last = bridge.pipeline.last_outcome
    finally:
        bridge.close()
        pty.close()
        sink.close()
    assert last is not None and last.decision.out_enu is not None
    e = last.epoch
    sections = line.split(" | ")
    assert sections[0].startswith("0:00:") and "LINK" not in sections[0], line
    assert sections[1].startswith("gps up "), line
    east, north = last.decision.out_enu[0], last.decision.out_enu[1]
    assert sections[3] == (f"DGPS {e.num_sats}sv HDOP {e.hdop:.1f} {east:+.1f}E {north:+.1f}N "
                           f"m {e.speed_mps:.1f} m/s"), line
    # Without GST: h_acc = sigma sqrt(2) max(1, HDOP), sigma 0.35 m (firmware_host/rover/outputs).
    h_acc = 0.35 * 2 ** 0.5 * max(1.0, e.hdop or 1.0)
    assert sections[4] == f"out accept DGPS {h_acc:.2f} m", line
    assert sections[5] == "GGA+RMC+VTG", line


@pytest.mark.parametrize(("root_level", "shown"), [(logging.WARNING, False),
                                                    (logging.INFO, True)])
def test_demo_insgnss_expected_alarms_only_at_v(root_level: int, shown: bool,
                                                caplog: pytest.LogCaptureFixture) -> None:
    """``demo insgnss`` injects GPS faults: its alarm, gate-health and unacknowledged-HOLD
    warnings (its GPS_INPUT goes to a UDP socket, not an autopilot) are the demo working, said
    at ``-v`` only; errors always."""
    from firmware_host.devtools.demo_insgnss import expected_quiet

    root = logging.getLogger()
    old = root.level
    root.setLevel(root_level)
    try:
        with caplog.at_level(root_level), expected_quiet():
            logging.getLogger("fdi_bridge.rover").warning("GPS alarm at utc 1.0")
            logging.getLogger("fdi_bridge.mavlink").warning("no COMMAND_ACK for mode HOLD")
            logging.getLogger("fdi_bridge.rover").error("a real error")
    finally:
        root.setLevel(old)
    texts = [r.getMessage() for r in caplog.records]
    assert ("GPS alarm at utc 1.0" in texts) is shown
    assert ("no COMMAND_ACK for mode HOLD" in texts) is shown
    assert "a real error" in texts
    assert logging.getLogger("fdi_bridge.rover").level == logging.NOTSET  # restored


@pytest.mark.parametrize(("greys", "said"), [
    # the grey gate over the minimum jump (1.05 m), one value a check: what is said
    ([1.08, 1.04, 1.08, 1.10], []),  # within the 10 % margin: never a warning
    ([1.20, 1.04, 1.20, 1.04], []),  # single checks' excursions: the fixes' noise
    ([1.20, 1.20, 1.20], ["WARNING"]),  # held: said once
    ([1.20, 1.20, 1.08, 1.08, 1.04], ["WARNING", "INFO"]),  # cleared only within the jump
])
def test_the_grey_gate_s_warning_has_a_margin_and_needs_two_checks(
        greys: list[float], said: list[str], caplog: pytest.LogCaptureFixture) -> None:
    """Issue E, measured on 24 h of the simulated DGPS receiver at 1 Hz with the default
    preset: the grey gate sat at 1.05-1.08 m against the 1.05 m minimum jump and the warning
    and its all-clear alternated 20 times; with the margin and two checks, none."""
    pipe = RoverPipeline(BridgeConfig().rover)
    for g in greys:
        report = GateHealthReport(
            status="nis_low", epochs=200, dof=3, mean_nis=0.1, mean_nis_window=0.1,
            flagged_fraction=0.0, min_detectable_jump_m=2.67, grey_gate_h_m=g, min_jump_m=1.05,
            chi2_inert_fraction=1.0, messages=("mean normalised innovation squared 0.1 ...",))
        pipe.gate_health.report = lambda r=report: r  # type: ignore[method-assign]
        with caplog.at_level(logging.INFO, logger="fdi_bridge"):
            pipe._check_gate_health()
    assert [r.levelname for r in _gate_records(caplog)] == said
