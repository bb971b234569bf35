"""Selecting the ROV through an ArduSub autopilot from a config file (``[rov] heading_source``)."""

from __future__ import annotations

from pathlib import Path

import pytest

from fdi.errors import ConfigError, ConfigErrors
from firmware_host.commands.launch import vehicle_from_file
from firmware_host.rov.ardusub import ArduSubRovVehicle
from firmware_host.rov.vehicle import OutlandRovVehicle
from firmware_host.runtime.config import load_bridge_file

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "config" / "rov-ardusub-example.toml"


def test_example_loads_and_selects_the_ardusub_vehicle() -> None:
    bf = load_bridge_file(EXAMPLE)
    assert bf.rov is not None and bf.mavlink is not None
    assert bf.rov.heading_source == "mavlink"
    assert bf.mavlink.pilot_system_id == 255 and bf.rov.ardusub.vehicle_system_id == 1
    urls = [bf.mavlink.autopilot.url, *(g.url for g in bf.mavlink.gcs)]
    assert all("127.0.0.1" in u for u in urls), urls  # loopback only
    vehicle, _ = vehicle_from_file(bf)
    assert isinstance(vehicle, ArduSubRovVehicle) and vehicle.vehicle_system_id == 1


def test_outland_stays_the_default() -> None:
    bf = load_bridge_file("rov")
    assert bf.rov is not None and bf.rov.heading_source == "outland"
    assert isinstance(vehicle_from_file(bf)[0], OutlandRovVehicle)


def test_mavlink_heading_without_a_mavlink_table_names_the_key(tmp_path: Path) -> None:
    p = tmp_path / "bad.toml"
    p.write_text('[rov]\nheading_source = "mavlink"\n')
    with pytest.raises(ConfigError) as exc:
        load_bridge_file(p)
    assert "rov.heading_source" in str(exc.value) and "[mavlink]" in str(exc.value)


@pytest.mark.parametrize("text, key", [
    ('[rov]\nheading_source = "gps"\n', "rov.heading_source"),
    ('[rov.ardusub]\nmodes = ["AUTO"]\n[mavlink]\n',
     "rov.ardusub: expected consistent values, found modes: AUTO"),
    ('[rov.ardusub]\nyaw_dead_band = 2000\n', "rov.ardusub.yaw_dead_band"),
])
def test_bad_values_are_refused_at_load(tmp_path: Path, text: str, key: str) -> None:
    p = tmp_path / "bad.toml"
    p.write_text(text)
    with pytest.raises((ConfigError, ConfigErrors)) as exc:
        load_bridge_file(p)
    assert key in str(exc.value)


def test_example_sets_the_raw_compass_and_its_keys() -> None:
    bf = load_bridge_file(EXAMPLE)
    assert bf.rov is not None
    a = bf.rov.ardusub
    assert (a.heading, a.compass_message, a.gyro, a.output) == (
        "raw_compass", "RAW_IMU", "imu", "manual_control")
    assert (a.rc_yaw_channel, a.rc_throttle_channel, a.rc_forward_channel,
            a.rc_lateral_channel) == (4, 3, 5, 6)  # ArduSub's default RCMAP
    assert bf.recorder.dir == ""  # off unless the user sets it


@pytest.mark.parametrize("text, key", [
    ('[rov.ardusub]\nheading = "vfr_hud"\n', "rov.ardusub.heading"),
    ('[rov.ardusub]\ncompass_message = "HIGHRES_IMU"\n', "rov.ardusub.compass_message"),
    ('[rov.ardusub]\ngyro = "ahrs2"\n', "rov.ardusub.gyro"),
    ('[rov.ardusub]\noutput = "servo"\n', "rov.ardusub.output"),
    ('[rov.ardusub]\nrc_yaw_channel = 9\n', "rov.ardusub.rc_yaw_channel"),
    ('[rov.ardusub]\nrc_yaw_channel = 3\n', "must differ"),
    ('[rov.ardusub]\ndeclination_deg = 200.0\n', "rov.ardusub.declination_deg"),
])
def test_bad_new_keys_are_refused_at_load(tmp_path: Path, text: str, key: str) -> None:
    p = tmp_path / "bad.toml"
    p.write_text(text)
    with pytest.raises((ConfigError, ConfigErrors)) as exc:
        load_bridge_file(p)
    assert key in str(exc.value)
