"""``demo insgnss --gyro-drift --outage`` (issue G): ArduPilot's simulated gyro drift, the live
example's filter, a 20 s GNSS outage at rest, end to end (ptys, GPS_INPUT over UDP on
127.0.0.1): every coast epoch's true error within twice the accuracy sent, then no-fix; no
WARNING on the terminal of a demo that worked."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from firmware_host.cli import main
from firmware_host.runtime.config import CONFIG_DIR


def test_demo_insgnss_with_the_gyro_drift_and_an_outage(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rc = main(["demo", "insgnss", "--config", str(CONFIG_DIR / "insgnss-live-example.toml"),
               "--gyro-drift", "0.05", "--imu", "RAW_IMU", "--rest", "200",
               "--outage", "140,20", "--epochs", "20", "--out", str(tmp_path / "d")])
    out, err = capsys.readouterr()
    assert rc == 0, err
    assert "WARNING" not in err and "WARNING" not in out
    assert "aligned by attitude" in out, out
    m = re.search(r"GNSS outage 140\.\.160 s: the INS's coast sent as 3D fixes (\d+) epochs "
                  r"\(true error at most ([\d.]+)x the accuracy sent, [\d.]+ m\), then no-fix "
                  r"(\d+) epochs \((\d+) coast claims failed\)", out)
    assert m is not None, out
    sent, ratio, no_fix = int(m.group(1)), float(m.group(2)), int(m.group(3))
    assert 9 <= sent <= 11 and sent + no_fix == 20
    assert ratio <= 2.0


@pytest.mark.parametrize("bad", ["140", "x,20", "-5,20", "140,0"])
def test_a_bad_outage_is_one_line(bad: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["demo", "insgnss", f"--outage={bad}", "--epochs", "20"]) == 2
    err = capsys.readouterr().err
    assert "--outage" in err and err.count("\n") == 1
