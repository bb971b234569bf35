"""drivers.configload and firmware_host.runtime.config: TOML -> typed objects, errors that help.

Every error must name the file, the dotted key, what was expected and what was found.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from drivers.configload import load_dataclass, read_toml
from fdi.errors import ConfigError
from firmware_host import cli
from firmware_host.runtime.config import CONFIG_DIR, BridgeConfig, ReferencePoint, load_config


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
        ("[rover.detector]\nalpha = 1.5\n", "rover.detector.alpha", "a number < 1.0",
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
    assert "expected a number < 1.0, found 1.5" in captured.err
    assert captured.out == ""
    assert not out.exists()  # it failed at start, before doing anything
