"""drivers.configload and firmware_host.runtime.config: TOML -> typed objects, errors that help.

Every error must name the file, the dotted key, what was expected and what was found.
"""

from __future__ import annotations

import dataclasses
import logging
from pathlib import Path

import pytest

from drivers.configload import load_dataclass, read_toml
from fdi.errors import ConfigError, ConfigErrors
from firmware_host import cli
from firmware_host.devtools.insgnss_sim import load_setup
from firmware_host.mavlink.router import load_mavlink_config
from firmware_host.rov.config import load_rov_config
from firmware_host.runtime.config import (
    CONFIG_DIR,
    BridgeConfig,
    ReferencePoint,
    load_bridge_file,
    load_config,
    resolve_config_path,
    vehicle_of,
)
from firmware_host.runtime.config_mavlink import MavlinkConfig


def write(tmp_path: Path, text: str, name: str = "bad.toml") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def load_error(path: Path) -> ConfigError:
    with pytest.raises(ConfigError) as info:
        load_config(path)
    return info.value


def test_rover_toml_states_the_built_in_defaults() -> None:
    cfg = load_config(CONFIG_DIR / "rover.toml")
    default = BridgeConfig()
    assert cfg.name == "rover"
    assert cfg.description != ""
    assert dataclasses.replace(cfg, name=default.name, description=default.description) == default
    assert load_config("rover") == cfg  # a bare preset name is looked up in config/
    assert load_config(None) == default


def test_paper_preset_loads_and_differs_where_it_says() -> None:
    paper = load_config("rover-paper")
    assert paper.name == "rover-paper"
    d = paper.rover.detector
    assert (d.window, d.predictor, d.gate_axes, d.gate_sigmas, d.use_gst) == (
        5, "raw", "per_axis", 0.0, False
    )
    assert paper.rover.port == BridgeConfig().rover.port  # not stated: the default


@pytest.mark.parametrize(
    ("text", "key", "expected", "found"),
    [
        # an unknown key (a typo), with the known keys listed
        ("[rover]\nmax_lines = 120\n", "rover.max_lines", "one of the keys detector, max_line",
         "an unknown key (did you mean 'max_line'?)"),
        ("nmae = 'x'\n", "nmae", "one of the keys description, insgnss, mavlink, name",
         "an unknown key (did you mean 'name'?)"),
        ("[rover]\nzzz = 1\n", "rover.zzz", "one of the keys", "an unknown key"),  # none close
        # wrong types
        ("[rover]\nmax_line = \"120\"\n", "rover.max_line", "an integer", "'120' (str)"),
        ("[rover.port]\nbaudrate = 9600.0\n", "rover.port.baudrate", "an integer",
         "9600.0 (float)"),
        ("[rover.detector]\nwindow = true\n", "rover.detector.window", "an integer",
         "True (bool)"),
        ("[rover.detector]\nalpha = \"0.05\"\n", "rover.detector.alpha", "a number",
         "'0.05' (str)"),
        ("rover = 3\n", "rover", "a table [RoverConfig]", "3 (int)"),
        # bounds
        ("[rover.detector]\nalpha = 1.5\n", "rover.detector.alpha", "a number <= 0.5",
         "1.5 (float)"),
        ("[rover.detector]\nwindow = 2\n", "rover.detector.window", "a number >= 4", "2 (int)"),
        ("[rover.port]\nbytesize = 9\n", "rover.port.bytesize", "a number <= 8", "9 (int)"),
        # a literal outside its choices
        ("[rover.detector]\npredictor = \"magic\"\n", "rover.detector.predictor",
         "one of 'raw', 'doppler'", "'magic' (str)"),
        ("[rover.port]\nparity = \"X\"\n", "rover.port.parity", "one of 'N'", "'X' (str)"),
    ],
)
def test_every_error_names_file_key_expected_found(
    tmp_path: Path, text: str, key: str, expected: str, found: str
) -> None:
    path = write(tmp_path, text)
    err = load_error(path)
    assert err.file == str(path)
    assert err.key == key
    assert err.expected.startswith(expected)
    assert err.found == found
    message = str(err)
    assert message.startswith(f"{path}: {key}: expected {expected}")
    assert message.endswith(f"found {found}")


def test_toml_syntax_error(tmp_path: Path) -> None:
    path = write(tmp_path, "name = \"x\"\n[rover\nmax_line = 1\n")
    err = load_error(path)
    assert (err.file, err.key, err.expected) == (str(path), "(syntax)", "valid TOML")
    assert "line 2" in err.found  # where the mistake is


def test_invalid_utf8(tmp_path: Path) -> None:
    path = tmp_path / "latin1.toml"
    path.write_bytes("description = \"Genève\"\n".encode("latin-1"))
    err = load_error(path)
    assert (err.file, err.key, err.expected) == (str(path), "(file)", "UTF-8 text")
    assert err.found == "invalid byte at 18"  # the è


def test_missing_file(tmp_path: Path) -> None:
    path = tmp_path / "nope.toml"
    err = load_error(path)
    assert (err.file, err.key, err.expected) == (str(path), "(file)", "a readable TOML file")
    assert err.found == "No such file or directory"
    with pytest.raises(ConfigError):
        read_toml(tmp_path)  # a directory is not a readable file


def test_optional_nested_table_loads(tmp_path: Path) -> None:
    path = write(tmp_path, "[rover.reference]\nlat_deg = 32.02\nlon_deg = 118.8\n")
    cfg = load_config(path)
    assert cfg.rover.reference == ReferencePoint(32.02, 118.8, 0.0)
    assert isinstance(cfg.rover.reference.lat_deg, float)


@pytest.mark.parametrize(
    ("text", "key", "expected"),
    [
        ("[rover.reference]\nlat_deg = 91.0\n", "rover.reference.lat_deg", "a number <= 90.0"),
        ("[rover.reference]\nlat = 32.0\n", "rover.reference.lat", "one of the keys"),
    ],
)
def test_error_inside_an_optional_table_names_the_inner_key(
    tmp_path: Path, text: str, key: str, expected: str
) -> None:
    err = load_error(write(tmp_path, text))
    assert err.key == key
    assert err.expected.startswith(expected)


def test_load_dataclass_rejects_non_dataclasses() -> None:
    with pytest.raises(TypeError):
        load_dataclass(dict, {}, "x.toml")


def test_cli_exits_2_and_names_file_and_key(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = write(tmp_path, "[rover.detector]\nalpha = 1.5\n", name="BAD.toml")
    log = tmp_path / "some.log"
    log.write_bytes(b"$GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,*47\r\n")
    out = tmp_path / "out"
    status = cli.main(["replay", "--config", str(bad), str(log), "--out", str(out)])
    captured = capsys.readouterr()
    assert status == 2
    assert str(bad) in captured.err
    assert "rover.detector.alpha" in captured.err
    assert "expected a number <= 0.5, found 1.5" in captured.err
    assert captured.out == ""
    assert not out.exists()  # it failed at start, before doing anything


# --------------------------------------------------------------------------- issue 11 / 17


@pytest.mark.parametrize(("text", "key"), [
    ("[rover.detector]\nalpha = inf\n", "rover.detector.alpha"),
    ("[rover.detector]\nalpha = nan\n", "rover.detector.alpha"),
    ("[rover.reference]\nalt_m = nan\n", "rover.reference.alt_m"),  # a float with no bounds
    ("[rover]\nsilence_s = inf\n", "rover.silence_s"),  # inf passes "> 0": refused anyway
    ("[recorder]\ndir_max_mb = -inf\n", "recorder.dir_max_mb"),
    ("[rov.pid]\nkp = nan\n", "rov.pid.kp"),
])
def test_non_finite_numbers_are_refused(tmp_path: Path, text: str, key: str) -> None:
    with pytest.raises(ConfigError) as info:
        load_bridge_file(write(tmp_path, text))
    assert info.value.key == key
    assert info.value.expected == "a finite number"


@pytest.mark.parametrize(("text", "key"), [
    ("[rover.detector]\nalpha = 5e-324\n", "rover.detector.alpha"),
    ("[rover.detector]\nalpha = 1e-300\n", "rover.detector.alpha"),
    ("[rover.detector.three_zone]\nalpha1 = 0.1\nalpha2 = 5e-324\n",
     "rover.detector.three_zone.alpha2"),
    ("[insgnss.filter.three_zone]\nalpha1 = 1e-200\nalpha2 = 1e-300\n",
     "insgnss.filter.three_zone.alpha1"),
])
def test_a_level_whose_threshold_is_not_finite_is_below_its_bound(
        tmp_path: Path, text: str, key: str) -> None:
    with pytest.raises(ConfigError) as info:
        load_bridge_file(write(tmp_path, text))
    assert info.value.key == key
    assert info.value.expected == "a number >= 1e-15"  # issue C: the level's own bound
    # the smallest level the message promises is accepted
    load_bridge_file(write(tmp_path, "[rover.detector]\nalpha = 1e-15\n", "ok.toml"))


def test_a_protocol_scale_of_zero_is_refused_at_load(tmp_path: Path) -> None:
    proto = (CONFIG_DIR / "protocols" / "outland1000.toml").read_text()
    assert 'scale = 0.01, unit = "deg",' in proto
    (tmp_path / "protocols").mkdir()
    (tmp_path / "protocols" / "outland1000.toml").write_text(
        proto.replace('scale = 0.01, unit = "deg",', 'scale = 0, unit = "deg",', 1))
    cfg = write(tmp_path, "[rov]\nperiod_s = 0.2\n")
    with pytest.raises(ConfigError) as info:
        load_bridge_file(cfg)
    assert info.value.file == str(tmp_path / "protocols" / "outland1000.toml")
    assert info.value.key == "messages[0].fields[0].scale"
    assert info.value.expected == "a number other than 0.0"


def test_the_protocol_is_found_beside_the_file_then_packaged(tmp_path: Path) -> None:
    cfg = write(tmp_path, "[rov]\n", "rov-here.toml")
    assert load_bridge_file(cfg).rov.link.protocol == str(  # type: ignore[union-attr]
        CONFIG_DIR / "protocols" / "outland1000.toml")
    (tmp_path / "protocols").mkdir()
    beside = tmp_path / "protocols" / "outland1000.toml"
    beside.write_text((CONFIG_DIR / "protocols" / "outland1000.toml").read_text())
    assert load_bridge_file(cfg).rov.link.protocol == str(beside)  # type: ignore[union-attr]
    rcfg, base = load_rov_config(cfg)
    assert (rcfg.link.protocol, base) == (str(beside), tmp_path.resolve())
    missing = write(tmp_path, "[rov.link]\nprotocol = 'nope.toml'\n", "missing.toml")
    with pytest.raises(ConfigError, match=r"nope\.toml"):
        load_bridge_file(missing)


def test_every_error_of_a_file_is_reported_in_file_order(tmp_path: Path) -> None:
    path = write(tmp_path, "nmae = 'x'\n[rover]\nmax_lines = 1\nsilence_s = -1\n"
                 "[rover.detector]\nwindow = 2\nalpha = 2.0\n[mavlink]\nsystem_id = 0\n")
    with pytest.raises(ConfigErrors) as info:
        load_bridge_file(path)
    keys = [e.key for e in info.value.errors]
    assert keys == ["nmae", "rover.max_lines", "rover.silence_s", "rover.detector.window",
                    "rover.detector.alpha", "mavlink.system_id"]
    assert all(e.file == str(path) for e in info.value.errors)
    assert str(info.value).count("\n") == 5  # one line each
    assert isinstance(info.value, ConfigError) and info.value.key == "nmae"  # the first


def test_errors_in_a_list_of_tables_are_all_reported(tmp_path: Path) -> None:
    path = write(tmp_path, "[mavlink]\n[[mavlink.gcs]]\nurl = 1\n[[mavlink.gcs]]\n"
                 "url = 'udpin:127.0.0.1:14551'\nbaud = 0\nsigning = 'yes'\n")
    with pytest.raises(ConfigErrors) as info:
        load_bridge_file(path)
    assert [e.key for e in info.value.errors] == [
        "mavlink.gcs[0].url", "mavlink.gcs[1].baud", "mavlink.gcs[1].signing"]


def test_one_file_holds_every_section(tmp_path: Path) -> None:
    path = write(tmp_path, "name = 'all'\n[rover]\n[rov]\n[insgnss]\n[mavlink]\n"
                 "[recorder]\ndir = 'rec'\n")
    bf = load_bridge_file(path)
    assert bf.sections == ("rover", "rov", "insgnss", "mavlink")
    assert bf.rov is not None and bf.rov.recorder == bf.recorder  # one [recorder] per file
    assert load_rov_config(path)[0].recorder.dir == "rec"
    assert load_config(path).recorder.dir == "rec"
    with pytest.raises(ConfigError, match="both"):
        vehicle_of(bf)  # `run` runs one vehicle


def test_a_file_is_frozen() -> None:
    bf = load_bridge_file("rover")
    with pytest.raises(dataclasses.FrozenInstanceError):
        bf.name = "x"  # type: ignore[misc]


ROV_FLAT = ("period_s = 0.1\nsetpoint_deg = 90.0\n[detector]\norder = 20\n[link]\n"
            "address = 3\n[link.port]\nurl = 'loop://'\n[sim]\nseed = 7\n"
            "[recorder]\ndir = 'r'\n")
ROV_NESTED = ("[rov]\nperiod_s = 0.1\nsetpoint_deg = 90.0\n[rov.detector]\norder = 20\n"
              "[rov.link]\naddress = 3\n[rov.link.port]\nurl = 'loop://'\n[rov.sim]\nseed = 7\n"
              "[recorder]\ndir = 'r'\n")


def test_the_old_flat_rov_layout_loads_with_one_warning(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    flat = write(tmp_path, ROV_FLAT, "flat.toml")
    nested = write(tmp_path, ROV_NESTED, "nested.toml")
    caplog.set_level(logging.WARNING, logger="fdi_bridge.config")
    a = load_bridge_file(flat)
    b = load_bridge_file(nested)
    assert a.rov == b.rov and a.rov is not None and a.rov.sim.seed == 7
    assert load_bridge_file(flat) == a  # a second load: no second warning
    load_rov_config(flat)
    warnings = [r for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warnings) == 1
    assert str(flat) in warnings[0].getMessage()
    assert "[rov]" in warnings[0].getMessage() and "deprecated" in warnings[0].getMessage()


def test_the_old_flat_insgnss_layout_loads(tmp_path: Path) -> None:
    old = write(tmp_path, "[filter]\nstrategy = 'none'\n[sim]\nepochs = 40\n", "old.toml")
    new = write(tmp_path, "[insgnss.filter]\nstrategy = 'none'\n[insgnss.sim]\nepochs = 40\n",
                "new.toml")
    assert load_bridge_file(old).insgnss == load_bridge_file(new).insgnss
    assert load_setup(old) == load_setup(new)
    assert load_setup(old).sim.epochs == 40


@pytest.mark.parametrize("text", [
    "period_s = 0.1\n[rov]\nsetpoint_deg = 1.0\n",  # old and new layout mixed
    "period_s = 0.1\n[filter]\nstrategy = 'none'\n",  # two old layouts
])
def test_mixed_layouts_are_an_error(tmp_path: Path, text: str) -> None:
    with pytest.raises(ConfigError):
        load_bridge_file(write(tmp_path, text))


def test_shipped_rov_presets_use_the_rov_table() -> None:
    for name in ("rov", "rov-paper"):
        table = read_toml(CONFIG_DIR / f"{name}.toml")
        assert "rov" in table and "period_s" not in table and "link" not in table


def test_a_preset_name_wins_over_a_directory_but_not_over_a_file(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    (tmp_path / "rov").mkdir()  # as `fdi-bridge demo rov --out rov/` leaves it
    assert resolve_config_path("rov") == CONFIG_DIR / "rov.toml"
    assert load_rov_config("rov")[0].link.port.url == "/dev/ttyUSB0"
    assert resolve_config_path("rover.toml") == CONFIG_DIR / "rover.toml"
    (tmp_path / "rover").write_text("[rover.port]\nurl = 'loop://'\n")  # a file: it wins
    assert resolve_config_path("rover") == Path("rover")
    assert load_config("rover").rover.port.url == "loop://"
    with pytest.raises(ConfigError, match="no such file or preset") as info:
        resolve_config_path("rovr")
    assert "rov-paper" in info.value.expected  # the names it could have been
    with pytest.raises(ConfigError, match="a readable TOML file"):
        load_bridge_file(tmp_path / "rov")  # a directory given as a path: not a file


def test_views_refuse_a_file_for_another_vehicle() -> None:
    with pytest.raises(ConfigError, match=r"\[rover\] table"):
        load_config("rov")
    with pytest.raises(ConfigError, match=r"\[rov\] table"):
        load_rov_config("rover")
    assert load_mavlink_config("rover") == MavlinkConfig()  # absent: its defaults
