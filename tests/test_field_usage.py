"""What a field engineer trips on first (issue 45's small items): a misspelt option is named as
such, an unknown preset gets the nearest name, ``doctor`` lists the ports without a file."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

from fdi.errors import ConfigError
from firmware_host.cli import main
from firmware_host.runtime.config import resolve_config_path


@pytest.mark.parametrize("argv, meant", [
    (["record", "--outt", "x", "/dev/null"], "--out"),
    (["sim", "rover", "--outt", "x"], "--out"),
    (["run", "--confg", "rover"], "--config"),
])
def test_a_misspelt_required_option_is_named_not_reported_missing(
        argv: list[str], meant: str, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert "unrecognized arguments: " + argv[-3 if argv[0] == "record" else -2] in err, err
    assert f"did you mean {meant}?" in err, err
    assert "are required" not in err
    assert err.count("\n") == 1  # one line


def test_a_missing_required_option_is_still_reported_missing(
        capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["record", "/dev/null"])
    assert "the following arguments are required: --out" in capsys.readouterr().err


def test_an_unknown_preset_gets_the_nearest_name(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(ConfigError, match=r"did you mean 'rover'\?"):
        resolve_config_path("rovr")
    with pytest.raises(ConfigError) as info:
        resolve_config_path("zzzzzz")
    assert "did you mean" not in str(info.value)
    assert main(["config", "check", "rover-papr"]) == 2
    assert "did you mean 'rover-paper'?" in capsys.readouterr().err


def test_doctor_lists_the_ports_without_a_config(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["doctor", "--gps-probe-s", "0"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("serial ports on this system:")
    assert "no configuration checked" in out and "PROBLEM" not in out
    assert main(["doctor", "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert isinstance(rep["ports"], list) and rep["problems"] == []



def test_the_demo_s_plot_hint_suits_a_wheel_user(monkeypatch: pytest.MonkeyPatch,
                                                 tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    """Without matplotlib the demo says how to get a PNG: the package's extra, which works for
    a wheel (``pip install -e .`` needs a checkout)."""
    from firmware_host.devtools import demo_rover

    monkeypatch.setattr(demo_rover, "HAVE_MATPLOTLIB", False)
    assert demo_rover._plots([], tmp_path, [], sys.stdout) == 0
    out = capsys.readouterr().out
    assert "pip install 'fdi-bridge[dev]'" in out and "-e" not in out
