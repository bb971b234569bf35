"""A recording of the ArduSub ROV replays byte for byte (``fdi-bridge replay`` of its capture).

The live runs record with a flight recorder (channels ``ardusub tick``/``rx``/``tx``: each
step's mark, the frames it took from the router, the commands it sent); the replay runs the
same vehicle on those frames with no router and must write the same ``epochs.jsonl``, byte for
byte, and the same commands. One run in lockstep with the simulated ArduSub over UDP on
127.0.0.1 that goes through every state (drift confirmed, pilot takeover, AUTO, unplugged,
RC_CHANNELS_OVERRIDE with the raw compass and the gyro), and one real-time run of the CLI
(``fdi-bridge run`` in a subprocess, the simulator serving in real time).
"""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import threading
import time
from dataclasses import replace
from pathlib import Path

import pytest

from drivers.capture import CaptureReader
from firmware_host.devtools.ardusub_sim import ArduSubSim
from firmware_host.devtools.rov_sim import parse_fault
from firmware_host.rov.config import RovConfig, load_rov_config, project_root
from firmware_host.rov.replay import is_ardusub_capture, replay_ardusub
from firmware_host.runtime.recorder import FlightRecorder
from tests.ardusub_bench import Bench

ROOT = Path(__file__).resolve().parents[1]


def _cfg(**ardusub: object) -> RovConfig:
    c, _ = load_rov_config(project_root() / "config" / "rov.toml")
    return replace(c, heading_source="mavlink", ardusub=replace(c.ardusub, **ardusub))


def _scenario(b: Bench) -> None:
    """75 s: a pilot (yaw centred) throughout except where said; drift at 50 s."""
    centred, turn = (300, 0, 500, 0), (300, 0, 500, 500)
    for _ in range(20 * 5):
        b.period(centred)
    for _ in range(3 * 5):
        b.period(turn)  # takeover
    for _ in range(5 * 5):
        b.period(centred)  # handed back
    for _ in range(3 * 5):
        b.period()  # the pilot goes silent: pilot_silent
    b.sim.set_mode("AUTO")
    for _ in range(3 * 5):
        b.period(centred)
    b.sim.set_mode("ALT_HOLD")
    for _ in range(30 * 5):
        b.period(centred)  # 44-74 s: the drift at 50 s, confirmed
    b.sim.unplugged = True
    for _ in range(5 * 5):
        b.period(centred)
    b.sim.unplugged = False
    for _ in range(5 * 5):
        b.period(centred)


@pytest.mark.parametrize("keys, sim", [
    ({}, {}),
    ({"heading": "raw_compass", "gyro": "imu", "output": "rc_override"},
     {"compass": "RAW_IMU", "fault_on": "magnetometer"}),
], ids=["attitude-manual_control", "raw_compass-gyro-rc_override"])
def test_lockstep_recording_replays_byte_for_byte(tmp_path: Path, keys: dict[str, object],
                                                  sim: dict[str, object]) -> None:
    cfg = _cfg(**keys)
    rec = FlightRecorder(tmp_path / "rec")
    b = Bench(cfg, ("drift:30@50",), sim=sim, recorder=rec, out_dir=tmp_path / "live")
    try:
        _scenario(b)
    finally:
        live_summary = b.close()
    rec.close()
    states = live_summary["ardusub_states"]
    assert {"steer", "pilot", "pilot_silent", "mode", "no_heartbeat"} <= set(states), states
    (cap,) = rec.recordings()
    assert is_ardusub_capture(CaptureReader(cap))
    summary = replay_ardusub(cfg, cap, tmp_path / "replayed")
    live = (tmp_path / "live" / "epochs.jsonl").read_bytes()
    again = (tmp_path / "replayed" / "epochs.jsonl").read_bytes()
    assert live.count(b"\n") == summary["epochs"] == sum(states.values())
    assert b'"event": "confirmed"' in live or b'"event":"confirmed"' in live
    assert again == live
    r = summary["replay"]
    assert r["tx_match"] and r["tx_steps_differ"] == 0, r
    assert summary["ardusub_states"] == states
    sent_key = "manual_control_sent" if cfg.ardusub.output == "manual_control" else \
        "rc_override_sent"
    assert summary[sent_key] == live_summary[sent_key] > 0


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_cli_run_recording_replays_byte_for_byte(tmp_path: Path) -> None:
    """``fdi-bridge run`` against the simulator in real time (6 s, a drift at 2 s on the raw
    compass), recorded; ``fdi-bridge replay`` of the capture writes the same epochs.jsonl."""
    ap, gcs = _free_udp_port(), _free_udp_port()
    conf = tmp_path / "bridge.toml"
    conf.write_text(
        '[rov]\nheading_source = "mavlink"\nsetpoint_deg = 110.0\n'
        '[rov.ardusub]\nheading = "raw_compass"\ngyro = "imu"\n'
        'send_without_pilot = true\n'  # no ground station here: an unattended hold
        f'[mavlink]\n[mavlink.autopilot]\nurl = "udpin:127.0.0.1:{ap}"\n'
        f'[[mavlink.gcs]]\nurl = "udpin:127.0.0.1:{gcs}"\n')
    cfg = _cfg(heading="raw_compass", gyro="imu")
    sim = ArduSubSim(f"udpout:127.0.0.1:{ap}", cfg.sim, [parse_fault("drift:30@2")],
                     compass="RAW_IMU", fault_on="magnetometer")
    stop = threading.Event()
    th = threading.Thread(target=sim.serve, args=(stop,), daemon=True)
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    cli = [sys.executable, "-m", "firmware_host.cli"]
    th.start()
    try:
        run = subprocess.run([*cli, "run", "--config", str(conf), "--duration", "6", "--out",
                              str(tmp_path / "live"), "--record", str(tmp_path / "rec"),
                              "--json"], env=env, capture_output=True, text=True, timeout=60)
    finally:
        stop.set()
        th.join(2.0)
        sim.close()
    assert run.returncode == 0, run.stderr
    live_summary = json.loads(run.stdout.strip().splitlines()[-1])
    assert live_summary["compass_received"] > 30 and sim.counters.accepted > 10
    (cap,) = sorted((tmp_path / "rec").glob("*.cap"))
    rep = subprocess.run([*cli, "replay", str(cap), "--config", str(conf), "--out",
                          str(tmp_path / "replayed"), "--json"], env=env,
                         capture_output=True, text=True, timeout=60)
    assert rep.returncode == 0, rep.stderr
    summary = json.loads(rep.stdout)
    live = (tmp_path / "live" / "epochs.jsonl").read_bytes()
    assert live.count(b"\n") >= 25 and summary["epochs"] == live.count(b"\n")
    assert (tmp_path / "replayed" / "epochs.jsonl").read_bytes() == live
    assert summary["replay"]["tx_match"], summary["replay"]
    time.sleep(0)  # nothing to wait for: both processes have ended
