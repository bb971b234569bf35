"""The rover pipeline's MAVLink output reaches a pymavlink autopilot stand-in over real UDP.

GPS_INPUT at the GPS rate with the corrected positions, GPS week and milliseconds, fix type,
and raised accuracy on replaced fixes; on an alarm, STATUSTEXT and a mode change to HOLD.
"""

from __future__ import annotations

import json
import threading
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

from drivers.mavlink.io import MavEndpoint
from firmware_host.commands.replay import build_sinks, run_replay
from firmware_host.devtools.rover_sim import RoverScenario, write_run
from firmware_host.rover.outputs import gps_week_ms, unix_time
from firmware_host.runtime.config import BridgeConfig, RoverOutputs


class _Collector(threading.Thread):
    """Receives on the autopilot stand-in while the pipeline sends (a UDP buffer is small)."""

    def __init__(self, ep: MavEndpoint) -> None:
        super().__init__(daemon=True)
        self.ep = ep
        self.msgs: list[Any] = []
        self.stop = threading.Event()

    def run(self) -> None:
        while not self.stop.is_set():
            msg = self.ep.recv(0.05)
            if msg is not None:
                self.msgs.append(msg)

    def finish(self, n_gps: int, deadline_s: float = 5.0) -> list[Any]:
        end = time.monotonic() + deadline_s
        while time.monotonic() < end:
            if sum(m.get_type() == "GPS_INPUT" for m in self.msgs) >= n_gps:
                break
            time.sleep(0.01)  # polling the receiver thread, with a deadline
        self.stop.set()
        self.join(timeout=2.0)
        return self.msgs


def _run(tmp_path: Path, sc: RoverScenario) -> tuple[list[dict[str, Any]], list[Any]]:
    write_run(sc, tmp_path / "run")
    ap = MavEndpoint("udpin:127.0.0.1:0", source_system=1, source_component=1)
    collector = _Collector(ap)
    collector.start()
    try:
        addr = ap.local_address
        assert addr is not None
        cfg = BridgeConfig()
        cfg = replace(cfg, rover=replace(cfg.rover, output=RoverOutputs(
            mavlink_url=f"udpout:127.0.0.1:{addr[1]}")))
        sinks = build_sinks(cfg, None, None)
        run_replay(cfg, tmp_path / "run" / "rover.nmea", tmp_path / "out", speed=50.0,
                   sinks=sinks)
        text = (tmp_path / "out" / "epochs.jsonl").read_text()
        epochs = [json.loads(x) for x in text.splitlines() if x]
        msgs = collector.finish(len(epochs))
    finally:
        collector.stop.set()
        ap.close()
    return epochs, msgs


def test_gps_input_per_epoch_with_raised_accuracy_on_replaced(tmp_path: Path) -> None:
    epochs, msgs = _run(tmp_path, RoverScenario(rate_hz=1.0, duration_s=120.0, seed=3))
    gps = [m for m in msgs if m.get_type() == "GPS_INPUT"]
    assert len(gps) == len(epochs)
    assert any(m.get_type() == "HEARTBEAT" for m in msgs)
    acc_ok, acc_rep = set(), set()
    for e, m in zip(epochs, gps, strict=True):
        week, ms = gps_week_ms(unix_time(RoverScenario().date, e["utc"]))
        assert (m.time_week, m.time_week_ms) == (week, ms)
        assert m.lat == round(e["lat"] * 1e7) and m.lon == round(e["lon"] * 1e7)
        if e["action"] == "accept":
            assert m.fix_type == 4  # DGPS
            acc_ok.add(round(m.horiz_accuracy, 3))
        else:
            assert e["action"] == "replace"
            assert m.fix_type == 3
            acc_rep.add(round(m.horiz_accuracy, 3))
    assert acc_rep, "the run should contain replaced fixes"
    assert min(acc_rep) >= 2.9 * max(acc_ok)
    # The simulator's 2025-05-12 (a Monday) 10:00:00 UTC is GPS week 2366; GPS - UTC is 18 s.
    assert RoverScenario().date == (2025, 5, 12)
    assert gps[0].time_week == 2366
    assert gps[0].time_week_ms == (1 * 86400 + 10 * 3600 + 18) * 1000


def test_alarm_sends_statustext_and_hold(tmp_path: Path) -> None:
    sc = RoverScenario(rate_hz=5.0, duration_s=150.0, seed=6, kinds=("frozen",),
                       frozen_s=20.0, fault_every_s=60.0)
    epochs, msgs = _run(tmp_path, sc)
    assert any(e["alarm_raised"] for e in epochs)
    texts = [m for m in msgs if m.get_type() == "STATUSTEXT"]
    assert any(m.severity == 2 and "auto-nav stop" in m.text for m in texts)
    cmds = [m for m in msgs if m.get_type() == "COMMAND_LONG"]
    assert cmds and cmds[0].command == 176 and cmds[0].param2 == 4  # DO_SET_MODE, Rover HOLD
    assert any(m.severity == 5 and "alarm cleared" in m.text for m in texts)
    # While the alarm is up the autopilot gets no-fix, never a position.
    gps = [m for m in msgs if m.get_type() == "GPS_INPUT"]
    for e, m in zip(epochs, gps, strict=True):
        if e["action"] == "alarm":
            assert m.fix_type <= 1 and m.lat == 0
