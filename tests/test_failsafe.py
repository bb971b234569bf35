"""Silence watchdogs and failsafes, driven by a FakeClock (no real time passes).

Rover: after ``silence_s`` without a valid fix the autopilot gets a STATUSTEXT and a no-fix
GPS_INPUT (repeated each second); when fixes are valid again, a "data back" STATUSTEXT and
normal GPS_INPUT. ROV: the last command is held for ``dropout_hold_s``, then neutral thrust
goes on the wire; heading hold resumes when telemetry returns, and the bridge says so.
"""

from __future__ import annotations

import logging
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest

from drivers.outland.framecodec import load_protocol
from drivers.outland.link import NEUTRAL
from drivers.transport import SerialSettings
from firmware_host.commands.run import RoverBridge, run_rov_bridge
from firmware_host.devtools.rov_sim import RovPlant, RovSimServer, parse_fault
from firmware_host.devtools.rover_sim import RoverScenario, generate
from firmware_host.devtools.soak import SimDevice, rov_device, sim_opener
from firmware_host.rov.config import SimConfig
from firmware_host.rover.failsafe import RoverFailsafe
from firmware_host.runtime.config import BridgeConfig, RoverConfig
from firmware_host.runtime.failsafe import SilenceWatchdog
from firmware_host.runtime.loop import FakeClock

ROOT = Path(__file__).resolve().parents[1]


def test_watchdog_events_once() -> None:
    clock = FakeClock()
    wd = SilenceWatchdog(2.0, clock)
    events = []
    for k in range(100):
        clock.now = k * 0.1
        if k < 10 or k >= 60:
            events.append((k, wd.valid()))
        events.append((k, wd.check()))
    fired = [(k, e) for k, e in events if e]
    assert fired == [(29, "silent"), (60, "back")]  # 0.9 s + 2.0 s; then the first valid


class FakeEndpoint:
    def __init__(self, clock: FakeClock) -> None:
        self.clock = clock
        self.calls: list[tuple[float, str, Any]] = []

    def send_statustext(self, severity: int, text: str) -> bytes:
        self.calls.append((self.clock(), "statustext", (severity, text)))
        return b"s"

    def send_gps_input(self, fix: Any) -> bytes:
        self.calls.append((self.clock(), "gps_input", fix))
        return b"g"

    def send_heartbeat(self) -> bytes:
        self.calls.append((self.clock(), "heartbeat", None))
        return b"h"

    def request_mode(self, *a: Any) -> bytes:
        self.calls.append((self.clock(), "mode", a))
        return b"m"

    def send_named_value(self, name: str, value: float) -> None:
        self.calls.append((self.clock(), "named_value", (name, value)))

    def send_manual_control(self, *a: Any) -> None:
        self.calls.append((self.clock(), "manual_control", a))

    def counters(self) -> dict[str, int]:
        return {"packets": len(self.calls)}

    def close(self) -> None:
        pass


def test_rover_silence_sends_no_fix_and_says_when_data_is_back(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.WARNING, logger="fdi_bridge.failsafe")
    clock = FakeClock()
    sc = RoverScenario(rate_hz=10.0, duration_s=20.0, seed=5, fault_every_s=1e9)
    epochs = [data for _, data, _ in generate(sc)]
    state = {"k": 0}

    def produce(now: float) -> bytes:  # the receiver is silent in [5, 10) s (port still open)
        out = b""
        while state["k"] < len(epochs) and state["k"] * 0.1 <= now + 1e-9:
            k = state["k"]
            if not 5.0 <= k * 0.1 < 10.0:
                out += epochs[k]
            state["k"] += 1
        return out

    dev = SimDevice("gps", clock, produce)
    cfg = BridgeConfig(rover=replace(RoverConfig(), port=SerialSettings(url="sim://gps"),
                                     silence_s=2.0))
    ep = FakeEndpoint(clock)
    bridge = RoverBridge(cfg, clock=clock, opener=sim_opener({"sim://gps": dev}), endpoint=ep)
    for k in range(150):
        clock.now = k * 0.1
        bridge.step()
    bridge.close()
    texts = [(t, a) for t, kind, a in ep.calls if kind == "statustext"]
    assert len(texts) == 2
    (t_silent, (sev1, msg1)), (t_back, (sev2, msg2)) = texts
    assert t_silent == pytest.approx(4.9 + 2.0, abs=0.11) and sev1 == 2 and "no valid" in msg1
    assert t_back == pytest.approx(10.0, abs=0.11) and sev2 == 5 and "back" in msg2
    fixes = [(t, f.fix_type) for t, kind, f in ep.calls if kind == "gps_input"]
    no_fix = [t for t, ft in fixes if ft == 1]
    assert no_fix == pytest.approx([6.9, 7.9, 8.9, 9.9], abs=0.11)  # 1 Hz while silent
    assert all(ft >= 3 for t, ft in fixes if t < 5.0 or t > 10.05)
    assert sum(1 for t, _ in fixes if t > 10.05) >= 45  # normal stream resumed
    assert bridge.failsafe.watchdog.episodes == 1
    msgs = [r.getMessage() for r in caplog.records if r.name == "fdi_bridge.failsafe"]
    assert len(msgs) == 2 and "no valid fix" in msgs[0] and "valid fixes again" in msgs[1]


def test_rov_dropout_holds_then_neutral_then_resumes(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING)
    for name in ("firmware_host.rov.control", "fdi_bridge.failsafe"):  # whatever set them
        caplog.set_level(logging.WARNING, logger=name)
    clock = FakeClock()
    proto = load_protocol(ROOT / "config" / "protocols" / "outland1000.toml")
    plant = RovPlant(SimConfig(), [parse_fault("dropout@20-24")])
    server = RovSimServer(plant, proto, "rs232", node=1, period_s=0.2)
    dev = rov_device(server, clock)
    cfg_file = tmp_path / "rov.toml"
    cfg_file.write_text(
        "[rov]\nperiod_s = 0.2\ndropout_hold_s = 1.0\n[rov.link]\nwiring = \"rs232\"\n"
        f"protocol = \"{ROOT / 'config' / 'protocols' / 'outland1000.toml'}\"\n"
        "[rov.link.port]\nurl = \"loop://\"\nbaudrate = 115200\n")  # the opener maps it
    seen: list[tuple[float, str, Any]] = []

    def on_epoch(rec: dict[str, Any]) -> None:
        seen.append((clock(), rec["action"], server.command))

    out = run_rov_bridge(cfg_file, clock=clock, sleep=clock.sleep,
                         opener=sim_opener({"loop://": dev}), max_steps=200,
                         on_epoch=on_epoch)
    # Telemetry frames stop during [20, 24) s of the vehicle's time.
    lost = [(t, a) for t, a, _ in seen if a in ("hold", "neutral") and 19.0 < t < 26.0]
    holds = [t for t, a in lost if a == "hold"]
    neutral = [t for t, a in lost if a == "neutral"]
    assert holds and neutral
    assert neutral[0] - holds[0] == pytest.approx(1.0, abs=0.21)  # held dropout_hold_s
    assert neutral[-1] - holds[0] == pytest.approx(4.0, abs=0.41)
    # What the vehicle received: the last command while holding, then neutral thrust.
    held = [c for t, a, c in seen if a == "hold" and t >= holds[0]]
    assert held[0] != NEUTRAL
    assert all(c == NEUTRAL for t, a, c in seen if a == "neutral")
    after = [a for t, a, _ in seen if t > neutral[-1] + 0.01]
    assert after and all(a in ("control", "substitute") for a in after)
    assert out["failsafe"] == {"episodes": 1, "neutral": 1}
    msgs = [r.getMessage() for r in caplog.records]
    assert any("neutral thrust" in m for m in msgs)
    assert any("telemetry back" in m for m in msgs)


def test_no_fix_goes_to_the_configured_gps_instance() -> None:
    """With ``gps_id = 1`` (GPS2) the failsafe's no-fix must go to GPS2 too, not GPS1."""
    clock = FakeClock()
    cfg = replace(RoverConfig(), silence_s=1.0)
    cfg = replace(cfg, output=replace(cfg.output, gps_id=1))
    ep = FakeEndpoint(clock)
    fs = RoverFailsafe(cfg, ep, clock=clock)
    for k in range(30):
        clock.now = k * 0.1
        fs.check()
    fixes = [a for _, kind, a in ep.calls if kind == "gps_input"]
    assert fixes and all(f.gps_id == 1 and f.fix_type == 1 for f in fixes)
