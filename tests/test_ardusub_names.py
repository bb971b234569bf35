"""What the bridge tells an ArduSub user: current parameter names, and whether its heading FDI
has a gyro (issue A).

* ArduPilot 4.7 renamed the stream rates ``SR0_*``..``SR9_*`` to ``MAV1_*``..``MAV10_*`` and
  ``SYSID_MYGCS`` to ``MAV_GCS_SYSID`` (a current ArduSub ignores the old names when set): the
  docs, the shipped configs and the code's strings name the new ones, an old name only beside
  its new one;
* without a gyro witness (the Outland link, or ``[rov.ardusub] gyro = "none"``) the start
  banner and ``fdi-bridge doctor`` say "compass only: slow drifts are not detectable";
* the ArduSub link always carries a gyro: ``gyro`` defaults to ``attitude`` with ``heading =
  "attitude"`` and to ``imu`` with ``heading = "raw_compass"``; ``"none"`` stays possible.
"""

from __future__ import annotations

import io
import re
from pathlib import Path

import pytest

from firmware_host.commands.config_cmd import effective_toml
from firmware_host.commands.doctor import diagnose
from firmware_host.commands.live import ConsoleStatus, console_status
from firmware_host.runtime.config import load_bridge_file
from firmware_host.runtime.config_rov import COMPASS_ONLY, ArduSubConfig
from firmware_host.runtime.status import Banner

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "config" / "rov-ardusub-example.toml"
OLD_RATE = re.compile(r"\bSR(?:[0-9]|n|\()")  # SR0_RAW_SENS, SRn_EXTRA1, SR(n-1)_...
NEW_RATE = re.compile(r"\bMAV(?:[0-9]+|n|m)_(?:[A-Z]|\*)")


def _text_files() -> list[Path]:
    files = [*ROOT.glob("docs/*.md"), *ROOT.glob("config/*.toml"), ROOT / "README.md"]
    return files + sorted((ROOT / "firmware_host").rglob("*.py"))


def test_parameter_names_are_the_current_ones() -> None:
    stale = []
    for path in _text_files():
        for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            where = f"{path.relative_to(ROOT)}:{n}"
            if OLD_RATE.search(line) and not NEW_RATE.search(line):
                stale.append(f"{where}: {line.strip()}")
            if "SYSID_MYGCS" in line and "MAV_GCS_SYSID" not in line:
                stale.append(f"{where}: {line.strip()}")
    assert stale == [], "\n".join(stale)


def _banner(path: Path) -> str:
    bf = load_bridge_file(path)
    out = io.StringIO()
    ConsoleStatus(console_status(path, bf).header, stream=out, tty=False).banner(
        Banner(vehicle="rov"))
    return out.getvalue()


def _no_gyro(tmp_path: Path) -> Path:
    text = EXAMPLE.read_text()
    assert 'gyro = "imu"' in text
    p = tmp_path / "no-gyro.toml"
    p.write_text(text.replace('gyro = "imu"', 'gyro = "none"'))
    return p


def test_the_banner_says_compass_only_without_a_gyro(tmp_path: Path) -> None:
    assert COMPASS_ONLY == "compass only: slow drifts are not detectable"
    outland = _banner(ROOT / "config" / "rov.toml")
    assert COMPASS_ONLY in outland, outland
    assert COMPASS_ONLY in _banner(_no_gyro(tmp_path))
    shipped = _banner(EXAMPLE)
    assert COMPASS_ONLY not in shipped and "gyro witness (RAW_IMU gyro)" in shipped, shipped
    assert "heading FDI" not in _banner(ROOT / "config" / "rover.toml")  # not an ROV


def test_doctor_says_compass_only_without_a_gyro(tmp_path: Path) -> None:
    def said(path: Path) -> tuple[list[str], list[str]]:
        rep = diagnose(path, list_ports=lambda: [], record_dir=str(tmp_path))
        return rep.warnings, rep.ok

    warn, _ = said(ROOT / "config" / "rov.toml")
    assert any(COMPASS_ONLY in w and "Outland link carries no gyro" in w for w in warn), warn
    warn, _ = said(_no_gyro(tmp_path))
    assert any(COMPASS_ONLY in w and 'gyro = "none"' in w for w in warn), warn
    warn, ok = said(EXAMPLE)
    assert not any(COMPASS_ONLY in w for w in warn)
    assert any("gyro witness (RAW_IMU gyro)" in o for o in ok), ok


@pytest.mark.parametrize("keys, gyro", [
    ("", "attitude"),
    ('heading = "attitude"\n', "attitude"),
    ('heading = "raw_compass"\n', "imu"),
    ('heading = "raw_compass"\ngyro = "none"\n', "none"),
    ('heading = "attitude"\ngyro = "imu"\n', "imu"),
])
def test_gyro_defaults_by_heading(tmp_path: Path, keys: str, gyro: str) -> None:
    p = tmp_path / "a.toml"
    p.write_text('[rov]\nheading_source = "mavlink"\n[rov.ardusub]\n' + keys + "[mavlink]\n")
    bf = load_bridge_file(p)
    assert bf.rov is not None and bf.rov.ardusub.gyro == gyro
    shown = tmp_path / "shown.toml"  # `config show` states it and loads back the same
    shown.write_text(effective_toml(bf))
    assert f'gyro = "{gyro}"' in shown.read_text()
    again = load_bridge_file(shown)
    assert again.rov is not None and again.rov.ardusub == bf.rov.ardusub
    assert ArduSubConfig().gyro == "attitude"
    assert ArduSubConfig(heading="raw_compass").gyro == "imu"
