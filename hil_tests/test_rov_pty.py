"""The simulated vehicle and the bridge over a real pty (both wirings), short runs.

The vehicle runs in a thread on the pty's master side; the bridge opens the slave path by URL
with the same driver and controller as the real-vehicle mode (:func:`run_rov`). No sleeps to
wait for events: the bridge's own fixed-rate loop paces the run, and the vehicle thread is
stopped with an event.
"""

from __future__ import annotations

import threading
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

from drivers.outland.framecodec import load_protocol
from drivers.outland.link import OutlandLink, ThrusterCommand
from drivers.ptypair import PtyPair
from drivers.transport import SerialSettings, open_port
from firmware_host.devtools.rov_sim import RovPlant, RovSimServer, parse_fault, serve_pty
from firmware_host.rov.app import run_rov
from firmware_host.rov.config import LinkConfig, RovConfig

ROOT = Path(__file__).resolve().parent.parent
PROTO = load_protocol(ROOT / "config" / "protocols" / "outland1000.toml")


def _run(wiring: str, steps: int, faults: list[str]) -> tuple[dict[str, Any], list[dict]]:
    cfg = RovConfig(period_s=0.05)  # 20 Hz to keep the test short; the step is the same
    with PtyPair() as pty:
        plant = RovPlant(cfg.sim, [parse_fault(f) for f in faults])
        srv = RovSimServer(plant, PROTO, wiring, node=1, period_s=cfg.period_s)
        stop = threading.Event()
        th = threading.Thread(target=serve_pty, args=(pty, srv, stop), daemon=True)
        th.start()
        link = LinkConfig(port=SerialSettings(url=pty.url, baudrate=115200), wiring=wiring,
                          reply_timeout_s=0.03)
        cfg = replace(cfg, link=link)
        epochs: list[dict] = []
        try:
            stats = run_rov(cfg, time.monotonic, time.sleep, base_dir=ROOT / "config",
                            max_steps=steps, on_epoch=epochs.append)
        finally:
            stop.set()
            th.join(timeout=2.0)
        return stats, epochs


def test_rs485_polling_over_pty_turns_to_setpoint() -> None:
    stats, epochs = _run("rs485", 80, [])
    assert stats["counts"]["telemetry"] >= 78
    assert stats["counts"].get("timeouts", 0) <= 2
    assert sum(stats["rejects"].values()) == 0
    headings = [e["heading_meas"] for e in epochs if e["heading_meas"] is not None]
    assert headings[0] < 115.0 and headings[-1] > 125.0  # turning from 110 toward 150


def test_rs232_streaming_over_pty() -> None:
    stats, _ = _run("rs232", 40, [])
    assert stats["counts"]["telemetry"] >= 30
    assert stats["counts"]["commands"] == 40
    assert sum(stats["rejects"].values()) == 0
    # The step's time is reported; its goal (p99 < 0.5 ms) is `fdi-bridge bench`'s, not a
    # test's: under a loaded CI machine a 40-step p99 is one slow step (26.9 ms seen with 3
    # test workers on 2 cores).
    assert 0.0 < stats["proc_p99_ms"] < float("inf")


def test_rs485_reply_timeout_on_silent_vehicle() -> None:
    with PtyPair() as pty:  # nobody answers on the master side
        port = open_port(SerialSettings(url=pty.url, timeout_s=0.005))
        link = OutlandLink(port, PROTO, "rs485", node=1, reply_timeout_s=0.05)
        t0 = time.monotonic()
        assert link.poll(ThrusterCommand(10, -10)) is None
        elapsed = time.monotonic() - t0
        assert 0.05 <= elapsed < 0.5
        assert link.counts["timeouts"] == 1
        sent = pty.read(timeout_s=1.0)
        assert sent.startswith(bytes(PROTO.sync))  # the poll itself went out
        port.close()


def test_dropout_over_pty_goes_neutral() -> None:
    _, epochs = _run("rs485", 60, ["dropout@0.5-10"])
    actions = [e["action"] for e in epochs]
    assert "hold" in actions and "neutral" in actions
    assert all(e["port_pct"] == 0.0 for e in epochs if e["action"] == "neutral")
