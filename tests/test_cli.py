"""The command line: lazy imports, ``--help`` of every command, ``--version``, the logging
options on either side of the command, ``presets`` and ``config check|show``."""

from __future__ import annotations

import argparse
import json
import logging
import os
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from drivers.gps.nmea import with_checksum
from firmware_host import cli
from firmware_host.commands.config_cmd import effective_toml
from firmware_host.runtime.config import load_bridge_file, parse_bridge_file

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = sorted((ROOT / "config").glob("*.toml"))


def _python(code: str, cwd: Path = ROOT) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-c", code], cwd=cwd, capture_output=True,
                          text=True, timeout=60, env=dict(os.environ, PYTHONPATH=str(ROOT)))


def _modules_after(argv: list[str]) -> list[str]:
    code = ("import sys\nfrom firmware_host.cli import main\n"
            f"try:\n    main({argv!r})\nexcept SystemExit:\n    pass\n"
            "print('\\n'.join(sorted(sys.modules)), file=sys.stderr)\n")
    out = _python(code)
    return out.stderr.split()


def test_replay_help_does_not_import_pymavlink() -> None:
    mods = _modules_after(["replay", "--help"])
    assert "firmware_host.cli" in mods  # the probe ran
    assert not [m for m in mods if m.startswith("pymavlink")]
    assert "firmware_host.commands.replay" not in mods  # only its argument module
    assert "firmware_host.commands.replay_args" in mods


def test_top_level_help_imports_no_command() -> None:
    mods = _modules_after(["--help"])
    ours = sorted(m for m in mods if m.split(".")[0] in ("firmware_host", "drivers", "fdi"))
    assert ours == ["fdi", "fdi.errors", "firmware_host", "firmware_host.cli"]
    assert "numpy" not in mods


def test_running_replay_imports_only_what_replay_needs(tmp_path: Path) -> None:
    # A real (empty) input: a missing one is refused while parsing, before replay is imported.
    (tmp_path / "empty.nmea").write_bytes(b"")
    mods = _modules_after(["replay", "--config", "rover", str(tmp_path / "empty.nmea"), "--out",
                           str(tmp_path / "out")])
    assert "firmware_host.commands.replay" in mods
    for other in ("firmware_host.devtools.insgnss_sim", "firmware_host.devtools.bench",
                  "firmware_host.commands.mavlink", "firmware_host.mavlink.router"):
        assert other not in mods
    # The two heavy libraries a rover replay without MAVLink output does not need (issue 19:
    # 0.37 -> 0.14 s of process time for the nmea-rtk replay, fdi-bridge bench --only startup).
    assert "numpy" not in mods
    assert "pymavlink" not in mods


def test_a_whole_rover_replay_imports_neither_numpy_nor_pymavlink(tmp_path: Path) -> None:
    lines = [with_checksum(f"GPGGA,1200{s:02d}.00,3415.0000,N,10854.0000,E,2,08,0.9,400.0,M,"
                           "-20.0,M,,") for s in range(10)]
    (tmp_path / "in.nmea").write_bytes(b"".join(lines))
    mods = _modules_after(["replay", str(tmp_path / "in.nmea"), "--out", str(tmp_path / "o")])
    assert (tmp_path / "o" / "epochs.jsonl").read_text().count("\n") == 10  # it replayed
    assert "numpy" not in mods
    assert not [m for m in mods if m.startswith("pymavlink")]


def _every_command() -> list[list[str]]:
    out = [[name] for name in cli.COMMANDS if name != "demo"]
    out += [["sim", kind] for kind in cli.SIM_COMMANDS]
    out += [["demo", kind] for kind in cli.DEMO_COMMANDS] + [["demo"], ["sim"], []]
    return out


@pytest.mark.parametrize("command", _every_command(), ids=lambda c: " ".join(c) or "top")
def test_help_of_every_command(command: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as info:
        cli.main([*command, "--help"])
    assert info.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith("usage: fdi-bridge")
    if command != ["sim"]:  # "sim" only lists its kinds
        assert "--log-level" in out  # the logging options, on every command's parser


def _every_parser() -> list[tuple[str, argparse.ArgumentParser]]:
    """(command, parser) for every command, sim kind and demo kind."""
    top = cli.build_parser(None)
    out: list[tuple[str, argparse.ArgumentParser]] = []
    subs = next(a for a in top._actions if isinstance(a, argparse._SubParsersAction))
    for name, p in subs.choices.items():
        if name == "sim":
            ssubs = next(a for a in p._actions if isinstance(a, argparse._SubParsersAction))
            out += [(f"sim {k}", sp) for k, sp in ssubs.choices.items()]
        elif name != "demo":
            out.append((name, p))
    out += [(f"demo {k}", cli.demo_parser(k)) for k in cli.DEMO_COMMANDS]
    return out


def test_every_option_has_help_and_every_command_an_example() -> None:
    parsers = _every_parser()
    assert len(parsers) == len(cli.COMMANDS) - 1 + len(cli.SIM_COMMANDS) + len(cli.DEMO_COMMANDS)
    for name, parser in parsers:
        for action in parser._actions:
            assert action.help, f"{name}: {action.option_strings or action.dest} has no help"
        assert parser.epilog and "example:\n  fdi-bridge " + name.split()[0] in parser.epilog, name
        formatter = cli._HelpFormatter(parser.prog)
        for action in parser._actions:  # a default worth stating is stated
            if action.default is None or action.default is False or action.default in (
                    argparse.SUPPRESS, []):
                continue
            shown = formatter._get_help_string(action) or ""
            assert "default" in shown, (name, action.dest, shown)


@pytest.mark.parametrize(("command", "option", "shown"), [
    (["replay"], "--speed", "(default: 0.0)"),
    (["record"], "--baud", "(default: 9600)"),
    (["record"], "--parity", "(default: N)"),
    (["bench"], "--duration", "(default: 60.0)"),
    (["sim", "rov"], "--duration", "(default: 130.0)"),
    (["demo", "rover"], "--duration", "(default: 600.0)"),
])
def test_help_shows_defaults(command: list[str], option: str, shown: str,
                             capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        cli.main([*command, "--help"])
    out = " ".join(capsys.readouterr().out.split())  # argparse wraps the help text
    options = out[out.index("options:"):]
    after = options[options.index(option + " "):]
    assert shown in after[:200]


def test_record_has_the_line_settings() -> None:
    args = cli.build_parser(["record"]).parse_args(
        ["record", "loop://", "--out", "x.cap", "--parity", "E", "--bytesize", "7",
         "--stopbits", "2"])
    assert (args.parity, args.bytesize, args.stopbits) == ("E", 7, 2.0)


def test_demo_help_names_the_other_demo(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        cli.main(["demo", "--help"])
    assert "demo rov" in capsys.readouterr().out


def test_version(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as info:
        cli.main(["--version"])
    assert info.value.code == 0
    assert capsys.readouterr().out.strip() == f"fdi-bridge {cli.version()}"


@pytest.mark.parametrize(("argv", "level"), [
    (["config", "check", "rover"], logging.WARNING),
    (["-v", "config", "check", "rover"], logging.INFO),
    (["config", "check", "rover", "-v"], logging.INFO),
    (["config", "check", "-vv", "rover"], logging.DEBUG),
    (["-v", "config", "check", "rover", "-v"], logging.DEBUG),
    (["config", "check", "rover", "-q"], logging.ERROR),
    (["-q", "config", "check", "rover", "-q"], logging.CRITICAL),
    (["--log-level", "error", "config", "check", "rover"], logging.ERROR),
    (["config", "check", "rover", "--log-level", "debug"], logging.DEBUG),
    (["--log-level", "error", "config", "check", "rover", "--log-level", "info"], logging.INFO),
])
def test_logging_options_before_or_after_the_command(argv: list[str], level: int) -> None:
    args = cli.build_parser(argv).parse_args(argv)
    assert cli._log_level(args) == level


def test_logging_options_after_a_demo() -> None:
    args = cli._demo_args(["-q", "demo", "rov", "-v", "-v", "--drift", "5"])
    assert args is not None and cli._log_level(args) == logging.INFO


def test_presets_lists_every_shipped_file(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["presets", "--json"]) == 0
    rows = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert {r["name"] for r in rows} == {p.stem for p in SHIPPED}
    by_name = {r["name"]: r for r in rows}
    assert by_name["rov"]["tables"] == "rov"
    assert by_name["mavlink-example"]["tables"] == "rover, mavlink"
    assert all(r["description"] and "does not load" not in r["description"] for r in rows)


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.stem)
def test_config_show_is_the_effective_config_and_loads_back(
        path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["config", "show", str(path)]) == 0
    text = capsys.readouterr().out
    original = load_bridge_file(path)
    again = parse_bridge_file(tomllib.loads(text), "shown.toml", path)
    assert again == original
    assert text == effective_toml(original)
    shown = tomllib.loads(text)
    for section in original.sections:
        assert section in shown
    if original.rover is not None:  # every default stated, not only what the file says
        assert shown["rover"]["detector"]["q_accel"] == original.rover.detector.q_accel
        assert "silence_s" in shown["rover"]


def test_config_check_reports_every_error(tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text("[rover.detector]\nalpah = 0.05\nwindow = 2\n"
                   "[rover.port]\nbaudrate = 'fast'\n[recorder]\nfile_max_mb = nan\n")
    assert cli.main(["config", "check", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "4 errors" in err
    for key in ("rover.detector.alpah", "rover.detector.window", "rover.port.baudrate",
                "recorder.file_max_mb"):
        assert f"{bad}: {key}: expected" in err
    assert "did you mean 'alpha'?" in err
    assert "a finite number" in err
    assert "Traceback" not in err


def test_config_check_ok(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["config", "check", "mavlink-example"]) == 0
    out = capsys.readouterr().out
    assert "ok; tables rover, mavlink" in out and "MAVLink router with the rover" in out


@pytest.mark.parametrize("command", [["run", "--config"], ["doctor", "--config"],
                                     ["config", "check"], ["replay", "--out", "x", "--config"]])
def test_a_file_that_is_not_utf8_is_a_config_error(tmp_path: Path, command: list[str]) -> None:
    binary = tmp_path / "binary.toml"
    binary.write_bytes(b"\x7fELF\x02\x01\x01\x00\xff\xfe" + bytes(range(256)))
    argv = [*command, str(binary)] + (["/dev/null"] if command[0] == "replay" else [])
    out = subprocess.run([sys.executable, "-m", "firmware_host.cli", *argv], cwd=tmp_path,
                         capture_output=True, text=True, timeout=60,
                         env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert "Traceback" not in out.stderr
    if command[0] == "doctor":  # doctor reports it as a problem, exit 1
        assert out.returncode == 1 and "PROBLEM  config:" in out.stdout
        assert "expected UTF-8 text" in out.stdout
    else:
        assert out.returncode == 2, out.stderr
        assert f"{binary}: (file): expected UTF-8 text, found invalid byte at" in out.stderr


def test_an_abbreviated_global_option_is_a_usage_error(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as info:
        cli.main(["--log", "debug", "config", "check", "rover"])
    assert info.value.code == 2
    assert "Traceback" not in capsys.readouterr().err


def test_a_directory_named_like_a_preset_does_not_hide_it(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.chdir(tmp_path)
    (tmp_path / "rov").mkdir()  # `fdi-bridge demo rov --out rov/` made it
    assert cli.main(["config", "check", "rov"]) == 0
    assert str(ROOT / "config" / "rov.toml") in capsys.readouterr().out
