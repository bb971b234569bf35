"""Issue C item 9 (the loader's part): a config file holds only what the bridge can run with.

``udpout:127.0.0.1:99999`` passed a file although the command line refused it,
``reconnect_max_s = 1e308``, ``silence_s = 1e-300`` and ``gate_sigmas = 1e-38`` passed the
loader, and ``nmea_url = "tcp://..."`` passed ``config check`` and was retried forever. Now a
URL is checked at load with the command line's own check (the accepted schemes listed), and
every float of every section has a finite ceiling and, where it must be positive, a floor.
"""

from __future__ import annotations

import dataclasses
import typing
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from drivers.configload import MAX_MAGNITUDE, toml_fields
from fdi.errors import ConfigError
from firmware_host.cli import main
from firmware_host.runtime.config import BridgeFile, load_bridge_file, parse_bridge_file
from firmware_host.runtime.config_mavlink import EndpointConfig

GCS = "udpin:127.0.0.1:14550"


def _error(table: dict[str, Any]) -> ConfigError:
    with pytest.raises(ConfigError) as info:
        parse_bridge_file(table, "probe.toml")
    err = info.value
    errors: list[ConfigError] = getattr(err, "errors", [err])
    return errors[0]


@pytest.mark.parametrize(("table", "key"), [
    ({"mavlink": {"autopilot": {"url": "udpout:127.0.0.1:99999"}}}, "mavlink.autopilot.url"),
    ({"mavlink": {"gcs": [{"url": GCS}, {"url": "udpout:127.0.0.1:99999"}]}},
     "mavlink.gcs[1].url"),
    ({"rover": {"output": {"mavlink_url": "udpout:127.0.0.1:99999"}}},
     "rover.output.mavlink_url"),
    ({"rover": {"output": {"mavlink_url": "udpout:127.0.0.1:0"}}}, "rover.output.mavlink_url"),
    ({"rover": {"output": {"nmea_url": "socket://127.0.0.1:70000"}}}, "rover.output.nmea_url"),
])
def test_a_port_out_of_range_fails_at_load_as_on_the_command_line(
        table: dict[str, Any], key: str) -> None:
    err = _error(table)
    assert err.key == key
    assert "out of range" in err.found and "port" in err.found


def test_the_same_url_is_refused_by_the_file_and_the_command_line(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    url = "udpout:127.0.0.1:99999"
    err = _error({"rover": {"output": {"mavlink_url": url}}})
    with pytest.raises(SystemExit) as info:
        main(["run", "--config", "rover", "--mavlink", url])
    assert info.value.code == 2
    cli = capsys.readouterr().err
    assert "port 99999 out of range 1-65535" in cli
    assert err.found == f"{url!r} (port 99999 out of range 1-65535)"
    assert "udpin:, udpout:, udp:, udpbcast:, tcp:, tcpin:" in err.expected


@pytest.mark.parametrize(("key", "table"), [
    ("rover.output.nmea_url", {"rover": {"output": {"nmea_url": "tcp://127.0.0.1:10110"}}}),
    ("rover.port.url", {"rover": {"port": {"url": "tcp://127.0.0.1:2947"}}}),
    ("rov.link.port.url", {"rov": {"link": {"port": {"url": "udp://127.0.0.1:5000"}}}}),
    ("insgnss.live.imu_url", {"insgnss": {"live": {"imu_url": "tcp://127.0.0.1:5762"}}}),
])
def test_an_unknown_url_scheme_names_the_accepted_ones(key: str, table: dict[str, Any]) -> None:
    err = _error(table)
    assert err.key == key
    assert "unknown URL scheme" in err.found
    for scheme in ("loop://", "socket://", "rfc2217://", "spy://"):
        assert scheme in err.expected


def test_config_check_refuses_a_tcp_nmea_url(tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    cfg = tmp_path / "bridge.toml"
    cfg.write_text('[rover.port]\nurl = "/dev/ttyUSB0"\n[rover.output]\n'
                   'nmea_url = "tcp://192.168.2.1:10110"\n')
    assert main(["config", "check", str(cfg)]) == 2
    err = capsys.readouterr().err
    assert f"{cfg}: rover.output.nmea_url: expected" in err
    assert "pty:PATH or a device path or a pyserial URL (loop://, socket://" in err
    assert "found 'tcp://192.168.2.1:10110' (unknown URL scheme 'tcp')" in err
    assert "internal error" not in err


@pytest.mark.parametrize("url", [
    "udpin:127.0.0.1:14550", "udpin:14550", "udpout:192.168.2.1:14550", "tcp:127.0.0.1:5760",
    "tcpin:0.0.0.0:5760", "/dev/ttyACM0", "socket://127.0.0.1:5760",
])
def test_the_documented_urls_still_load(url: str) -> None:
    bf = parse_bridge_file({"mavlink": {"autopilot": {"url": url}},
                            "rover": {"output": {"mavlink_url": url, "nmea_url": "pty:/x/gps"}},
                            "insgnss": {"live": {"imu_url": "router"}}}, "ok.toml")
    assert bf.mavlink is not None and bf.mavlink.autopilot.url == url


@pytest.mark.parametrize(("table", "key", "expected"), [
    ({"rover": {"reconnect_max_s": 1e308}}, "rover.reconnect_max_s", "a number <= 3600.0"),
    ({"mavlink": {"reconnect_max_s": 1e308}}, "mavlink.reconnect_max_s", "a number <= 3600.0"),
    ({"rov": {"link": {"reconnect_max_s": 1e308}}}, "rov.link.reconnect_max_s",
     "a number <= 3600.0"),
    ({"rover": {"silence_s": 1e-300}}, "rover.silence_s", "a number >= 0.1"),
    ({"rover": {"detector": {"gate_sigmas": 1e-38}}}, "rover.detector.gate_sigmas",
     "0.0 (off) or a number >= 1.0"),
    ({"rover": {"detector": {"gate_sigmas": 0.5}}}, "rover.detector.gate_sigmas",
     "0.0 (off) or a number >= 1.0"),
    ({"rover": {"detector": {"doppler_sigmas": 0.0}}}, "rover.detector.doppler_sigmas",
     "a number >= 1.0"),
    ({"rover": {"detector": {"max_consecutive": 0}}}, "rover.detector.max_consecutive",
     "a number >= 1"),
    ({"rover": {"detector": {"alpha": 0.6}}}, "rover.detector.alpha", "a number <= 0.5"),
    ({"rov": {"ft": {"gyro_sigma0_deg": 1e-38}}}, "rov.ft.gyro_sigma0_deg", "a number >= 1e-06"),
    ({"insgnss": {"filter": {"gnss_sigma_h_m": 1e308}}}, "insgnss.filter.gnss_sigma_h_m",
     "a number <= 1e+06"),
])
def test_values_no_algorithm_works_with_fail_at_load(table: dict[str, Any], key: str,
                                                     expected: str) -> None:
    err = _error(table)
    assert (err.key, err.expected) == (key, expected)


def test_gate_sigmas_zero_is_the_documented_fixed_gate() -> None:
    """0 is "off" (the paper's fixed gate, the paper presets' value), not a width of 0 σ."""
    bf = load_bridge_file("rover-paper")
    assert bf.rover is not None and bf.rover.detector.gate_sigmas == 0.0


def _float_keys(cls: type[Any], prefix: str) -> Iterator[tuple[str, dict[str, Any]]]:
    """Every float key of ``cls`` (nested tables walked) with the smallest table holding it."""
    hints = typing.get_type_hints(cls)
    for name, fld in toml_fields(cls).items():
        tp = hints[name]
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        if tp is float or (args and all(a is float for a in args)):
            yield f"{prefix}{name}", fld.metadata  # type: ignore[misc]
            continue
        if typing.get_origin(tp) is tuple:
            if dataclasses.is_dataclass(args[0]) and isinstance(args[0], type):
                yield from _float_keys(args[0], f"{prefix}{name}[].")  # a list of tables
            continue
        inner = [a for a in (tp, *args) if dataclasses.is_dataclass(a)]
        if inner and isinstance(inner[0], type):
            yield from _float_keys(inner[0], f"{prefix}{name}.")


def _table_for(dotted: str, value: float) -> dict[str, Any]:
    parts = dotted.split(".")
    table: dict[str, Any] = {parts[-1]: value}
    for i in range(len(parts) - 2, -1, -1):
        part = parts[i]
        if part.endswith("[]"):
            table = {part[:-2]: [{"url": GCS, **table}]}
        elif part == "autopilot":
            table = {part: {"url": GCS, **table}}
        else:
            table = {part: table}
    return table


FLOAT_KEYS = list(_float_keys(BridgeFile, ""))


def _refused(key: str, value: float) -> bool:
    """True when a file with ``key = value`` fails at load on that key (and no other)."""
    try:
        parse_bridge_file(_table_for(key, value), "probe.toml")
    except ConfigError as err:
        errors = getattr(err, "errors", [err])
        assert [e.key for e in errors] == [key.replace("[]", "[0]")], (key, value, str(err))
        return True
    return False


def test_every_float_of_every_section_is_walked() -> None:
    keys = [k for k, _ in FLOAT_KEYS]
    assert len(keys) > 150
    for key in ("rover.silence_s", "mavlink.gcs[].max_out_pps", "rov.ft.gyro_h",
                "insgnss.live.hold_s", "recorder.flush_interval_s",
                "rover.port.rs485.delay_before_tx"):
        assert key in keys


@pytest.mark.parametrize("value", [1e308, -1e308, 2 * MAX_MAGNITUDE])
def test_no_float_takes_a_value_beyond_its_ceiling(value: float) -> None:
    """Nothing passes at 1e308 (a time overflows a selector's timeout, a σ its square)."""
    assert [key for key, _meta in FLOAT_KEYS if not _refused(key, value)] == []


def test_no_positive_float_takes_a_denormal() -> None:
    """A key that must be positive (``gt``, or a floor ``ge`` > 0) refuses 1e-38 and 1e-300."""
    positive = [k for k, m in FLOAT_KEYS
                if ("gt" in m and m["gt"] >= 0.0) or ("ge" in m and m["ge"] > 0.0)]
    assert len(positive) > 80
    assert [(k, v) for k in positive for v in (1e-38, 1e-300) if not _refused(k, v)] == []


def test_every_shipped_preset_loads() -> None:
    from firmware_host.runtime.config import preset_names
    names = preset_names()
    assert len(names) >= 12
    for name in names:
        load_bridge_file(name)


def test_endpoint_url_is_a_mavlink_url_field() -> None:
    meta = {f.name: f.metadata for f in dataclasses.fields(EndpointConfig)}
    assert meta["url"]["url"] == "mavlink"
