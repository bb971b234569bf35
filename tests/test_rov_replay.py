"""The ROV's recording replays step by step (``fdi-bridge replay`` of an ROV capture).

The Outland ROV runs on the Runner against the simulator on a real pty (RS-232 streaming and
RS-485 polling), with a flight recorder and a telemetry dropout; the replay of the recording
must give the same ``epochs.jsonl`` bytes and the same commands. The end-to-end check through a
``fdi-bridge run`` subprocess is ``hil_tests/test_deployment.py::test_rov_with_operator_link``.
"""

from __future__ import annotations

import json
import threading
from pathlib import Path

import pytest

from drivers.capture import CaptureReader, CaptureWriter, Channel
from drivers.outland.framecodec import load_protocol
from drivers.ptypair import PtyPair
from firmware_host.cli import main
from firmware_host.commands import replay as replay_cmd
from firmware_host.devtools.rov_sim import RovPlant, RovSimServer, parse_fault, serve_pty
from firmware_host.rov import replay as rov_replay
from firmware_host.rov.config import SimConfig
from firmware_host.rov.replay import is_rov_capture, replay_rov
from firmware_host.rov.vehicle import LINK, TICK, OutlandRovVehicle
from firmware_host.runtime.config import load_bridge_file, rov_config
from firmware_host.runtime.recorder import FlightRecorder, RecorderConfig
from firmware_host.runtime.runner import Runner

ROOT = Path(__file__).resolve().parents[1]
PROTOCOL = ROOT / "config" / "protocols" / "outland1000.toml"


def _config(tmp_path: Path, wiring: str, link: Path) -> Path:
    cfg = tmp_path / "rov.toml"
    cfg.write_text(
        "[rov]\nperiod_s = 0.1\ndropout_hold_s = 0.3\n"
        f'[rov.link]\nwiring = "{wiring}"\nprotocol = "{PROTOCOL}"\nreply_timeout_s = 0.05\n'
        f'[rov.link.port]\nurl = "{link}"\nbaudrate = 115200\n')
    return cfg


def _live(tmp_path: Path, wiring: str) -> tuple[Path, Path, dict[str, object]]:
    """Run the ROV for 3 s on the simulator (dropout 1.0-1.8 s); return (config, capture,
    summary)."""
    link = tmp_path / "rovlink"
    cfg = _config(tmp_path, wiring, link)
    rcfg, base = rov_config(load_bridge_file(cfg))
    plant = RovPlant(SimConfig(), [parse_fault("dropout@1.0-1.8")])
    srv = RovSimServer(plant, load_protocol(PROTOCOL), wiring, node=1, period_s=0.1)
    halt = threading.Event()
    rec = FlightRecorder(tmp_path / "rec", RecorderConfig(dir=str(tmp_path / "rec")))
    with PtyPair(link=link, baudrate=115200) as pty:
        th = threading.Thread(target=serve_pty, args=(pty, srv, halt), daemon=True)
        th.start()
        try:
            runner = Runner(OutlandRovVehicle(rcfg, base), out_dir=tmp_path / "live",
                            recorder=rec, duration_s=3.0, handle_signals=False)
            summary = runner.run()
        finally:
            halt.set()
            th.join(2.0)
    caps = sorted((tmp_path / "rec").glob("*.cap"))
    assert len(caps) == 1
    return cfg, caps[0], summary


@pytest.mark.parametrize("wiring", ["rs232", "rs485"])
def test_replay_gives_the_live_records(tmp_path: Path, wiring: str) -> None:
    cfg, cap, live = _live(tmp_path, wiring)
    assert is_rov_capture(CaptureReader(cap))
    assert main(["replay", str(cap), "--config", str(cfg), "--out", str(tmp_path / "re")]) == 0
    want = (tmp_path / "live" / "epochs.jsonl").read_bytes()
    got = (tmp_path / "re" / "epochs.jsonl").read_bytes()
    assert want.count(b"\n") >= 20
    counts = live["counts"]
    assert isinstance(counts, dict) and counts["telemetry"] >= 10  # the link worked
    assert b'"action":"neutral"' in want or b'"action":"hold"' in want  # the dropout is in it
    assert got == want
    s = json.loads((tmp_path / "re" / "summary.json").read_text())
    assert s["replay"]["tx_match"] and s["replay"]["rx_unread"] == 0
    assert s["counts"] == live["counts"] and s["failsafe"] == live["failsafe"]
    assert s["actions"] == live["actions"]


def test_a_changed_step_shows(tmp_path: Path) -> None:
    """The comparison can fail: the same recording under another setpoint sends other
    commands, and the records differ."""
    cfg, cap, _ = _live(tmp_path, "rs232")
    other = tmp_path / "other.toml"
    other.write_text(cfg.read_text().replace("[rov]\n", "[rov]\nsetpoint_deg = 10.0\n", 1))
    rcfg, base = rov_config(load_bridge_file(other))
    s = replay_rov(rcfg, base, cap, tmp_path / "re")
    assert not s["replay"]["tx_match"] and s["replay"]["tx_steps_differ"] > 0
    assert (tmp_path / "re" / "epochs.jsonl").read_bytes() != (
        tmp_path / "live" / "epochs.jsonl").read_bytes()


def test_rov_capture_without_ticks_or_config(tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    old = tmp_path / "old.cap"
    with CaptureWriter(old, [Channel("rov link rx"), Channel("rov link tx", direction="tx")]) as w:
        w.write(0, b"\x00\x01")
    assert main(["replay", str(old), "--out", str(tmp_path / "o")]) != 0
    assert "without step ticks" in capsys.readouterr().err
    ticked = tmp_path / "new.cap"
    with CaptureWriter(ticked, [Channel("rov link rx"), Channel(TICK, direction="tx")]) as w:
        w.write(1, b'{"k": 0, "t": 0.0}')
    assert main(["replay", str(ticked), "--out", str(tmp_path / "n")]) != 0
    err = capsys.readouterr().err
    assert "--config" in err and "Traceback" not in err


def test_the_command_knows_the_vehicle_channel_names() -> None:
    """``commands/replay.py`` names the channels itself (so that a rover replay imports no ROV
    code); they must be the vehicle's."""
    assert (TICK, f"{LINK} rx") == (replay_cmd.ROV_TICK, replay_cmd.ROV_LINK_RX)
    assert rov_replay.__name__ == replay_cmd.ROV_REPLAY
