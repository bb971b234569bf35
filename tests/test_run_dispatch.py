"""``fdi-bridge run --config FILE`` picks the vehicle from the file: [rover] or [rov]."""

from __future__ import annotations

import json
import threading
from pathlib import Path

import pytest

from drivers.ptypair import PtyPair
from fdi.errors import ConfigError
from firmware_host.cli import main
from firmware_host.commands.run import vehicle_of
from firmware_host.devtools.rover_sim import RoverScenario, generate

ROOT = Path(__file__).resolve().parents[1]


def test_vehicle_rule(tmp_path: Path) -> None:
    assert vehicle_of("rover") == "rover"
    assert vehicle_of("rover-paper") == "rover"
    assert vehicle_of("rov") == "rov"
    assert vehicle_of(ROOT / "config" / "rov-paper.toml") == "rov"
    both = tmp_path / "both.toml"
    both.write_text("[rover]\n[rov]\n")
    with pytest.raises(ConfigError, match="both"):
        vehicle_of(both)
    neither = tmp_path / "neither.toml"
    neither.write_text("[recorder]\ndir = '/tmp/x'\n")
    with pytest.raises(ConfigError, match="neither"):
        vehicle_of(neither)
    with pytest.raises(ConfigError, match=r"(?i)no such file"):
        vehicle_of(tmp_path / "missing.toml")
    with pytest.raises(ConfigError, match="no such file or preset"):
        vehicle_of("no-such-preset")
    legacy = tmp_path / "legacy.toml"  # the ROV's keys at the top level: still the ROV
    legacy.write_text("period_s = 0.1\n[link]\nwiring = 'rs232'\n")
    assert vehicle_of(legacy) == "rov"


def test_run_rover_from_the_cli_with_recorder(tmp_path: Path) -> None:
    sc = RoverScenario(rate_hz=10.0, duration_s=5.0, seed=2)
    epochs = [d for _, d, _ in generate(sc)]
    with PtyPair(link=tmp_path / "gps") as pty:
        cfg = tmp_path / "r.toml"
        cfg.write_text(f'[rover.port]\nurl = "{pty.url}"\ntimeout_s = 0.02\n')
        done = threading.Event()
        rc: list[int] = []

        def go() -> None:
            rc.append(main(["run", "--config", str(cfg), "--out", str(tmp_path / "out"),
                            "--record", str(tmp_path / "rec"), "--duration", "1.5"]))
            done.set()

        th = threading.Thread(target=go)
        th.start()
        for data in epochs:  # the receiver, at 50 Hz (pyserial flushes input on open)
            if done.wait(0.02):
                break
            pty.write(data)
        th.join(20.0)
    assert rc == [0]
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["vehicle"] == "rover"
    assert summary["port"]["losses"] == 0 and summary["epochs"] >= 10
    assert summary["recorder"]["bytes_by_channel"]["gps rx"] == summary["input"]["bytes_in"]
    assert list((tmp_path / "rec").glob("fdi-*.cap"))


def test_run_rov_from_the_cli(tmp_path: Path) -> None:
    from drivers.outland.framecodec import load_protocol
    from firmware_host.devtools.rov_sim import RovPlant, RovSimServer, serve_pty
    from firmware_host.rov.config import SimConfig

    proto = load_protocol(ROOT / "config" / "protocols" / "outland1000.toml")
    with PtyPair(link=tmp_path / "rov") as pty:
        stop = threading.Event()
        srv = RovSimServer(RovPlant(SimConfig()), proto, "rs232", node=1, period_s=0.05)
        th = threading.Thread(target=serve_pty, args=(pty, srv, stop), daemon=True)
        th.start()
        cfg = tmp_path / "rov.toml"
        cfg.write_text(
            "[rov]\nperiod_s = 0.05\n[rov.link]\nwiring = \"rs232\"\n"
            f"protocol = \"{ROOT / 'config' / 'protocols' / 'outland1000.toml'}\"\n"
            f"[rov.link.port]\nurl = \"{pty.url}\"\nbaudrate = 115200\n")
        try:
            rc = main(["run", "--config", str(cfg), "--out", str(tmp_path / "out"),
                       "--duration", "1.0"])
        finally:
            stop.set()
            th.join(2.0)
    assert rc == 0
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["vehicle"] == "rov"
    assert summary["counts"]["telemetry"] >= 5
    lines = (tmp_path / "out" / "epochs.jsonl").read_text().splitlines()
    assert len(lines) >= 15


def test_a_config_with_a_mavlink_table_runs_the_router(tmp_path: Path) -> None:
    """`fdi-bridge run` on a vehicle file with [mavlink]: the vehicle on the runtime with the
    router attached, one process; the summary has both."""
    cfg = tmp_path / "vehicle.toml"
    cfg.write_text(
        'name = "t"\n[mavlink]\ntlog_dir = ""\nparam_file = ""\n'
        '[mavlink.autopilot]\nurl = "udpin:127.0.0.1:0"\n'
        '[[mavlink.gcs]]\nurl = "udpin:127.0.0.1:0"\n'
        f'[rover.port]\nurl = "{tmp_path / "no-such-gps"}"\n'
    )
    out = tmp_path / "out"
    assert main(["run", "--config", str(cfg), "--duration", "0.5", "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["vehicle"] == "rover" and summary["runtime"]["stopped_by"] == "duration"
    assert summary["epochs"] == 0  # no receiver: nothing invented
    assert summary["port"]["open_failures"] >= 1  # the receiver's port is retried
    assert "autopilot" in summary["router"]


def test_the_mavlink_command_runs_a_vehicle_file_on_the_runtime(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`fdi-bridge mavlink --config F` with [rover]: the same runtime as `run` (the rover's
    reader loop of the router is gone); without a vehicle, the router alone."""
    cfg = tmp_path / "vehicle.toml"
    cfg.write_text(
        '[mavlink]\n[mavlink.autopilot]\nurl = "udpin:127.0.0.1:0"\n'
        '[[mavlink.gcs]]\nurl = "udpin:127.0.0.1:0"\n'
        f'[rover]\nreconnect_max_s = 0.2\n[rover.port]\nurl = "{tmp_path / "no-gps"}"\n')
    assert main(["mavlink", "--config", str(cfg), "--seconds", "1.0", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["vehicle"] == "rover" and "autopilot" in summary["router"]
    assert summary["port"]["open_failures"] >= 5  # 0.1, 0.2, 0.2 ... s apart (5 s cap: 4)
    alone = tmp_path / "router.toml"
    alone.write_text(cfg.read_text().split("[rover]")[0])
    assert main(["mavlink", "--config", str(alone), "--seconds", "0.3", "--json"]) == 0
    assert set(json.loads(capsys.readouterr().out)) == {"router", "runtime"}
