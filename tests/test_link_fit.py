"""Issue E: a receiver's sentences at its rate against its line's baud rate.

9600 baud 8N1 carries 960 B/s; GGA+RMC+VTG (about 206 B an epoch) at 10 Hz needs 2 060 B/s:
at most 4.66 Hz fits (19200: 9.3 Hz; 38400: 18.6 Hz). ``run`` says so once and shows it on
the status line, ``doctor`` reports it, ``replay`` warns about a capture whose header's baud
rate cannot carry it, and ``sim rover`` writes a header baud rate its output fits.
"""

from __future__ import annotations

import logging
import os
import re
import threading
import time
from dataclasses import replace
from pathlib import Path

import pytest

from drivers.capture import CaptureReader, CaptureWriter, Channel
from drivers.gps.link import LinkFit, bits_per_byte, max_rate_hz, smallest_baud
from drivers.ptypair import PtyPair
from drivers.transport import SerialSettings
from firmware_host.cli import main
from firmware_host.commands.doctor import Report, check_gps_rate
from firmware_host.commands.run import RoverBridge
from firmware_host.devtools.rover_sim import RoverScenario, generate
from firmware_host.runtime.config import BridgeConfig, RoverConfig

SC = RoverScenario(rate_hz=10.0, duration_s=4.0, seed=2, kinds=())
EPOCHS = [data for _t, data, _truth in generate(SC)]


def test_the_arithmetic() -> None:
    assert bits_per_byte() == 10.0 and bits_per_byte(8, "E", 2.0) == 12.0
    assert max_rate_hz(206, 9600) == pytest.approx(4.66, abs=0.005)
    assert max_rate_hz(206, 19200) == pytest.approx(9.32, abs=0.005)
    assert max_rate_hz(206, 38400) == pytest.approx(18.64, abs=0.005)
    assert pytest.approx(0.0537, abs=1e-4) == 206 / 3840  # a 10 Hz epoch on 38400: 53.7 ms
    assert smallest_baud(206, 10.0) == 38400 and smallest_baud(206, 4.0) == 9600
    assert smallest_baud(206, 1000.0) is None
    fit = LinkFit(9600, 206.0, 10.0, ("GGA", "RMC", "VTG"))
    assert not fit.fits and fit.load == pytest.approx(2.146, abs=0.001)
    text = fit.message()
    assert "at most 4 Hz fits (4.66 Hz)" in text and "GGA+RMC+VTG" in text
    assert "38400 baud" in text


@pytest.mark.parametrize(("rate", "baud"), [(10.0, 38400), (5.0, 19200), (1.0, 9600)])
def test_sim_rover_writes_a_baud_rate_its_output_fits(tmp_path: Path, rate: float,
                                                      baud: int) -> None:
    assert main(["sim", "rover", "--rate", str(rate), "--duration", "30", "--gst", "--zda",
                 "--out", str(tmp_path)]) == 0
    reader = CaptureReader(tmp_path / "rover.cap")
    assert reader.channels[0].baudrate == baud
    records = list(reader)
    span_s = (records[-1].t_us - records[0].t_us) / 1e6 + 1.0 / rate
    need = sum(len(r.data) for r in records) / span_s
    assert need <= baud / 10.0, f"{need:.0f} B/s on {baud} baud"
    assert f"baud: {baud}" in (tmp_path / "rover.nmea").read_text().splitlines()[1]


def _capture(path: Path, baud: int) -> Path:
    with CaptureWriter(path, [Channel("gps", url="/dev/ttyUSB0", baudrate=baud)]) as cap:
        for k, data in enumerate(EPOCHS):
            cap.write(0, data, t_us=1_750_000_000_000_000 + k * 100_000)
    return path


@pytest.mark.parametrize("speed", ["0", "1"])
def test_replay_warns_once_when_the_capture_cannot_fit_its_baud(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], speed: str) -> None:
    cap = _capture(tmp_path / "slow.cap", 9600)
    assert main(["replay", str(cap), "--speed", speed, "--out", str(tmp_path / "o")]) == 0
    err = capsys.readouterr().err
    assert err.count("does not fit 9600 baud") == 1, err
    assert "at most 4 Hz fits" in err and "38400 baud" in err
    cap = _capture(tmp_path / "fast.cap", 38400)
    assert main(["replay", str(cap), "--speed", speed, "--out", str(tmp_path / "o2")]) == 0
    assert "does not fit" not in capsys.readouterr().err


def _bridge_on_pty(tmp_path: Path, baud: int) -> tuple[RoverBridge, PtyPair]:
    pty = PtyPair(link=tmp_path / f"gps{baud}")
    rc = RoverConfig()
    cfg = BridgeConfig(rover=replace(rc, port=SerialSettings(url=pty.url, baudrate=baud,
                                                              timeout_s=0.02)))
    return RoverBridge(cfg), pty


@pytest.mark.parametrize(("baud", "warns"), [(9600, True), (38400, False)])
def test_run_says_it_once_and_shows_it(tmp_path: Path, caplog: pytest.LogCaptureFixture,
                                       baud: int, warns: bool) -> None:
    bridge, pty = _bridge_on_pty(tmp_path, baud)
    try:
        with caplog.at_level(logging.WARNING, logger="fdi_bridge"):
            deadline = time.monotonic() + 20.0
            sent = 0
            while bridge.pipeline.epochs < len(EPOCHS) - 1 and time.monotonic() < deadline:
                if sent < len(EPOCHS) and sent - bridge.pipeline.epochs < 10:
                    os.write(pty.master_fd, EPOCHS[sent])
                    sent += 1
                bridge.step()
            fields = bridge.vehicle.status_fields()
    finally:
        bridge.close()
        pty.close()
    assert bridge.pipeline.epochs >= 30
    said = [r.getMessage() for r in caplog.records if "GPS link" in r.getMessage()]
    link = bridge.summary()["link"]
    assert link["rate_hz"] == pytest.approx(10.0, rel=1e-3)
    assert link["bytes_per_epoch"] == pytest.approx(len(b"".join(EPOCHS)) / len(EPOCHS),
                                                    rel=0.05)
    if warns:
        assert len(said) == 1 and "does not fit 9600 baud" in said[0], said
        assert "at most 4 Hz fits" in said[0]
        assert (link["fits"] is False and fields["LINK"].endswith("9600 baud, max 4.68 Hz")) \
            or fields["LINK"].startswith("2.1x 9600 baud")
    else:
        assert said == [] and link["fits"] is True and "LINK" not in fields


def _feed(pty: PtyPair, stop: threading.Event) -> None:
    t0 = time.monotonic()
    for k, data in enumerate(EPOCHS):
        if stop.wait(max(0.0, t0 + k * 0.1 - time.monotonic())):
            return
        os.write(pty.master_fd, data)


@pytest.mark.parametrize(("baud", "warns"), [(9600, True), (38400, False)])
def test_doctor_reports_it(baud: int, warns: bool) -> None:
    pty = PtyPair()
    stop = threading.Event()
    feeder = threading.Thread(target=_feed, args=(pty, stop), daemon=True)
    try:
        feeder.start()
        rep = Report()
        check_gps_rate(rep, pty.url, baud, 2.5, autopilot=False)
    finally:
        stop.set()
        feeder.join(timeout=2.0)
        pty.close()
    text = " ".join(rep.warnings)
    assert ("does not fit 9600 baud" in text) is warns, rep.lines()
    if warns:
        assert "at most 4 Hz fits" in text
    else:
        assert any("GPS link" in m and "38400 baud" in m for m in rep.ok), rep.lines()


def test_the_readme_walk_through_fits_its_baud_rate() -> None:
    """The README's walk-through: the status line's byte rate fits the banner's baud rate, the
    config it writes says that baud rate, and its pty path is the user's own (not /tmp/...)."""
    text = (Path(__file__).resolve().parents[1] / "README.md").read_text(encoding="utf-8")
    banner = re.search(r"port gps  (\S+) at (\d+) baud", text)
    status = re.search(r"\| gps up ([\d.]+) kB/s \|", text)
    assert banner is not None and status is not None
    baud = int(banner.group(2))
    assert float(status.group(1)) * 1000.0 <= baud / 10.0, (status.group(0), baud)
    assert f"baudrate = {baud}" in text
    assert "/tmp/fdi-gps" not in text and "pty:$GPS" in text
