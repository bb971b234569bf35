"""``fdi-bridge run --config FILE`` on the ArduSub ROV, against the simulated ArduSub.

The shipped example (``config/rov-ardusub-example.toml``) with its two UDP ports moved to free
ones on 127.0.0.1; the simulated autopilot serves in real time in a thread, a ground station
(pymavlink, system 255) sends its 1 Hz HEARTBEAT (the example steers only with a pilot or ground
station present: ``send_without_pilot = false``); the command runs for 4 s and writes its
records and summary.
"""

from __future__ import annotations

import json
import signal
import socket
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest

from drivers.mavlink import io as mio
from firmware_host.cli import main
from firmware_host.devtools.ardusub_sim import ArduSubSim
from firmware_host.rov.config import SimConfig

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "config" / "rov-ardusub-example.toml"


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.fixture
def keep_signal_handlers() -> Iterator[None]:
    saved = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    yield
    for s, h in saved.items():
        signal.signal(s, h)


def test_run_the_example_against_the_simulated_ardusub(
        tmp_path: Path, keep_signal_handlers: None) -> None:
    ap_port, gcs_port = _free_udp_port(), _free_udp_port()
    text = EXAMPLE.read_text()
    assert 'url = "udpin:127.0.0.1:14555"' in text and 'url = "udpin:127.0.0.1:14550"' in text
    text = text.replace("udpin:127.0.0.1:14555", f"udpin:127.0.0.1:{ap_port}")
    text = text.replace("udpin:127.0.0.1:14550", f"udpin:127.0.0.1:{gcs_port}")
    text = text.replace("setpoint_deg = 150.0", "setpoint_deg = 110.0")  # where the sim starts
    assert 'tlog_dir = "logs/tlog"' in text
    text = text.replace('tlog_dir = "logs/tlog"', f'tlog_dir = "{tmp_path / "tlog"}"')
    cfg = tmp_path / "rov-ardusub.toml"
    cfg.write_text(text)
    sim = ArduSubSim(f"udpout:127.0.0.1:{ap_port}", SimConfig(seed=3))
    stop = threading.Event()
    th = threading.Thread(target=sim.serve, args=(stop,), daemon=True)
    th.start()
    gcs = mio.MavEndpoint(f"udpout:127.0.0.1:{gcs_port}", source_system=255,
                          source_component=190)

    def ground_station() -> None:
        while not stop.is_set():
            gcs.send_heartbeat()
            stop.wait(1.0)

    gs = threading.Thread(target=ground_station, daemon=True)
    gs.start()
    out = tmp_path / "out"
    try:
        status = main(["run", "--config", str(cfg), "--duration", "4", "--out", str(out)])
    finally:
        stop.set()
        th.join(2.0)
        gs.join(2.0)
        sim.close()
        gcs.close()
    assert status == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["vehicle"] == "rov-ardusub"
    assert summary["attitude_received"] >= 30 and summary["heartbeat_received"] >= 3
    assert summary["ardusub_states"].get("steer", 0) >= 10
    assert summary["gcs_heartbeats_received"] >= 3
    records = [json.loads(line) for line in (out / "epochs.jsonl").read_text().splitlines()]
    assert len(records) >= 15 and records[-1]["ardusub"] == "steer"
    assert sim.counters.accepted >= 10 and sim.counters.refused == 0
    assert any((tmp_path / "tlog").glob("*.tlog"))  # the dive was recorded
    assert abs((sim.plant.heading_true - 110.0 + 180.0) % 360.0 - 180.0) < 5.0
