"""``fdi-bridge doctor``: each check finds what it should, and the exit status says so."""

from __future__ import annotations

import grp
import os
import signal
import socket
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from drivers.configload import read_toml
from drivers.ptypair import PtyPair
from firmware_host.cli import main
from firmware_host.commands import run as run_cmd
from firmware_host.commands.doctor import Report, check_device, check_mavlink_url, diagnose
from firmware_host.runtime.config import BridgeFile

ROOT = Path(__file__).resolve().parents[1]


def _rover_toml(tmp_path: Path, url: str, extra: str = "") -> Path:
    p = tmp_path / "rover.toml"
    p.write_text(f'[rover.port]\nurl = "{url}"\n{extra}')
    return p


def test_all_good_on_a_pty(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with PtyPair(link=tmp_path / "gps") as pty:
        cfg = _rover_toml(tmp_path, pty.url,
                          '[rover.output]\nmavlink_url = "udpout:127.0.0.1:14550"\n'
                          f'[recorder]\ndir = "{tmp_path / "rec"}"\n')
        assert main(["doctor", "--config", str(cfg)]) == 0
    out = capsys.readouterr().out
    assert "GPS input" in out and "readable and writable" in out
    assert "no problems found" in out and "PROBLEM" not in out


def test_missing_device_and_bad_endpoint_fail(tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    cfg = _rover_toml(tmp_path, str(tmp_path / "ttyUSB7"),
                      '[rover.output]\nmavlink_url = "udpout:127.0.0.1:notaport"\n')
    assert main(["doctor", "--config", str(cfg)]) == 1
    out = capsys.readouterr().out
    problems = [line for line in out.splitlines() if line.startswith("PROBLEM")]
    # the endpoint is refused where the file is loaded (issue C), naming the key and the value
    assert len(problems) == 1
    assert "rover.output.mavlink_url" in problems[0] and "notaport" in problems[0]
    cfg = _rover_toml(tmp_path, str(tmp_path / "ttyUSB7"),
                      '[rover.output]\nmavlink_url = "udpout:127.0.0.1:14550"\n')
    assert main(["doctor", "--config", str(cfg)]) == 1
    problems = [line for line in capsys.readouterr().out.splitlines()
                if line.startswith("PROBLEM")]
    assert len(problems) == 1 and "ttyUSB7 does not exist" in problems[0]


def test_permission_problem_names_the_group() -> None:
    rep = Report()
    with PtyPair() as pty:
        gid = os.stat(pty.slave_path).st_gid
        check_device(rep, "GPS input", pty.slave_path, access=lambda p, m: False,
                     groups=lambda: [])
    group = grp.getgrgid(gid).gr_name
    assert len(rep.problems) == 1
    assert f"join group {group!r}" in rep.problems[0]
    assert f"usermod -aG {group}" in rep.problems[0]


def test_udp_port_in_use_is_found_on_localhost_only() -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
        rep = Report()
        check_mavlink_url(rep, "MAVLink", f"udpin:127.0.0.1:{port}")
        assert rep.problems and "already in use" in rep.problems[0]
    rep = Report()
    check_mavlink_url(rep, "MAVLink", f"udpin:0.0.0.0:{port}")  # free again: ok
    assert not rep.problems and rep.ok


def test_bad_config_and_unwritable_recorder(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text("[rover.detector]\nalpha = 1.5\n")
    rep = diagnose(bad, list_ports=lambda: [])
    assert len(rep.problems) == 1 and "rover.detector.alpha" in rep.problems[0]
    neither = tmp_path / "neither.toml"
    neither.write_text("name = 'x'\n")
    rep = diagnose(neither, list_ports=lambda: [])
    assert "neither" in rep.problems[0]
    blocker = tmp_path / "file"
    blocker.write_text("")
    with PtyPair() as pty:
        cfg = _rover_toml(tmp_path, pty.slave_path, f'[recorder]\ndir = "{blocker / "rec"}"\n')
        rep = diagnose(cfg, list_ports=lambda: ["/dev/ttyFAKE0"])
    assert rep.ports == ["/dev/ttyFAKE0"]
    assert len(rep.problems) == 1 and "recorder" in rep.problems[0]


def test_rov_config_checks_the_link(tmp_path: Path) -> None:
    rep = diagnose(ROOT / "config" / "rov.toml", list_ports=lambda: [],
                   record_dir=str(tmp_path))
    assert rep.ok[0].endswith("(rov)")
    assert any("ROV link" in p for p in rep.problems) or any("ROV link" in o for o in rep.ok)


SHIPPED = sorted((ROOT / "config").glob("*.toml"))


@pytest.fixture
def keep_signal_handlers() -> Iterator[None]:
    saved = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    yield
    for s, h in saved.items():
        signal.signal(s, h)


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.stem)
def test_doctor_and_run_accept_the_same_files(
        path: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        keep_signal_handlers: None, capsys: pytest.CaptureFixture[str]) -> None:
    """Every shipped config: doctor reports a config problem exactly when run refuses it."""
    rep = diagnose(path, list_ports=lambda: [], record_dir=str(tmp_path / "rec"))
    doctor_accepts = not any(p.startswith("config:") for p in rep.problems)
    routed: list[list[str]] = []

    real_run_file = run_cmd.run_file

    def router_instead(bf: BridgeFile, **kw: Any) -> dict[str, Any]:
        # A [mavlink] file runs the vehicle with the router: not started here (mavlink-example
        # sends to a radio-network address); run got as far as handing it the file.
        if bf.mavlink is None:
            return real_run_file(bf, **kw)
        routed.append([str(bf.path)])
        return {}

    monkeypatch.setattr(run_cmd, "run_file", router_instead)
    status = main(["run", "--config", str(path), "--duration", "0.3",
                   "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert status in (0, 2), err
    run_accepts = status == 0
    assert doctor_accepts == run_accepts, (rep.problems, err)
    if "mavlink" in read_toml(path):
        assert routed == [[str(path)]]
        vehicle = "rov" if "rov" in read_toml(path) else "rover"
        assert any(o.startswith("config:") and f"(mavlink; tables {vehicle}, mavlink)" in o
                   for o in rep.ok)
        assert any("MAVLink autopilot" in line for line in rep.ok + rep.problems)
    # an INS/GNSS preset: sim only; with [rover] too (insgnss-live-*): the live INS/GNSS vehicle
    assert run_accepts == (not path.stem.startswith("insgnss") or "rover" in read_toml(path))
