"""The runner says what it is doing (issue 17): the banner, the live status and the summary.

The runner, on a fake clock with a simulated GPS that is unplugged for a while, hands its
status sink a banner and one snapshot a second (epochs, faults, each port's state and byte
rate, the last epoch's age); the console view refreshes one line on a terminal and logs the
same line once a minute elsewhere; the end summary is an aligned table. The real terminal and
the real pipe: ``hil_tests/test_run_status.py``.
"""

from __future__ import annotations

import io
import logging
from dataclasses import replace
from typing import Any

import pytest

from drivers.transport import SerialSettings
from firmware_host.commands.live import ConsoleStatus, run_summary_text, status_line
from firmware_host.devtools.rover_sim import RoverScenario, generate
from firmware_host.devtools.soak import SimDevice, sim_opener
from firmware_host.rover.vehicle import RoverVehicle
from firmware_host.runtime.config import BridgeConfig, RoverConfig
from firmware_host.runtime.loop import FakeClock
from firmware_host.runtime.mavout import packer_output
from firmware_host.runtime.runner import Runner
from firmware_host.runtime.status import Banner, PortStatus, Snapshot


class Collect:
    def __init__(self) -> None:
        self.banners: list[Banner] = []
        self.snaps: list[Snapshot] = []

    def banner(self, banner: Banner) -> None:
        self.banners.append(banner)

    def update(self, snapshot: Snapshot) -> None:
        self.snaps.append(snapshot)


def _device(clock: FakeClock, n: int, unplugged: list[tuple[float, float]]) -> SimDevice:
    sc = RoverScenario(rate_hz=10.0, duration_s=n / 10.0, seed=5, fault_every_s=1e9)
    chunks = [data for _, data, _ in generate(sc)]
    state = {"k": 0}

    def produce(now: float) -> bytes:
        out = b""
        while state["k"] < len(chunks) and state["k"] * 0.1 <= now + 1e-9:
            out += chunks[state["k"]]
            state["k"] += 1
        return out

    return SimDevice("gps", clock, produce, unplugged=unplugged)


def _run(unplugged: list[tuple[float, float]]) -> tuple[Collect, dict[str, Any], SimDevice]:
    clock = FakeClock(0.0)
    dev = _device(clock, 100, unplugged)
    cfg = BridgeConfig(rover=replace(RoverConfig(), port=SerialSettings(url="sim://gps"),
                                     reconnect_max_s=0.5))
    sink = Collect()
    runner = Runner(RoverVehicle(cfg), mavlink_output=packer_output(clock=clock), clock=clock,
                    opener=sim_opener({"sim://gps": dev}), handle_signals=False, status=sink)
    runner.start()
    for k in range(101):
        clock.now = k * 0.1
        runner.step()
    return sink, runner.close(), dev


def test_banner_and_one_snapshot_a_second() -> None:
    sink, summary, dev = _run([])
    assert len(sink.banners) == 1
    b = sink.banners[0]
    assert b.vehicle == "rover" and [(p.name, p.url) for p in b.ports] == [("gps", "sim://gps")]
    assert b.outputs == ("MAVLink (the caller's output)",) and b.recorder is None
    assert len(sink.snaps) == 10  # t = 1, 2, ... 10 s
    assert [round(s.elapsed_s) for s in sink.snaps] == list(range(1, 11))
    epochs = [s.epochs for s in sink.snaps]
    assert epochs == sorted(epochs) and 9 <= epochs[0] <= 11 and epochs[-1] == summary["epochs"]
    rates = [s.ports[0].rx_bps for s in sink.snaps]
    total = sum(r * 1.0 for r in rates)  # one second between snapshots
    assert abs(total - dev.generated) <= 0.02 * dev.generated
    assert all(s.ports[0].up for s in sink.snaps)
    assert all(s.last_record_age_s is not None and s.last_record_age_s <= 0.11
               for s in sink.snaps)
    assert sink.snaps[-1].faults == summary["faults"]


def test_an_unplugged_port_shows_as_waiting_and_the_fix_ages() -> None:
    sink, summary, _ = _run([(3.05, 6.05)])
    by_t = {round(s.elapsed_s): s for s in sink.snaps}
    assert by_t[2].ports[0].up and by_t[2].ports[0].rx_bps > 0
    waiting = [t for t, s in by_t.items() if not s.ports[0].up]
    assert waiting and 4 in waiting and 5 in waiting
    five = by_t[5]
    assert five.ports[0].down_s is not None and 1.0 <= five.ports[0].down_s <= 2.5
    assert five.last_record_age_s is not None and five.last_record_age_s >= 1.5
    assert "gps WAITING" in status_line(five)
    assert by_t[9].ports[0].up and by_t[9].ports[0].rx_bps > 0
    assert summary["ports"]["gps"]["losses"] >= 1


def _snap(t: float, **kw: Any) -> Snapshot:
    return Snapshot(elapsed_s=t, epochs=int(t * 10), faults=1, alarms=0,
                    ports=(PortStatus("gps", True, 1234.0, 0.0),), last_record_age_s=0.04, **kw)


def test_status_line_text() -> None:
    line = status_line(_snap(65.2))
    assert line == ("0:01:05 epochs 652 faults 1 alarms 0 | gps up 1.23 kB/s | "
                    "last epoch 0.0 s ago")
    rov = Snapshot(elapsed_s=3.0, epochs=15, ports=(PortStatus("rov link", False, 0, 0, 2.5),),
                   extra={"hold": 4})
    assert status_line(rov) == ("0:00:03 epochs 15 hold 4 | rov link WAITING 2.5 s | "
                                "last epoch none yet")


def test_console_on_a_terminal_refreshes_one_line() -> None:
    out = io.StringIO()
    view = ConsoleStatus([("config", "x.toml")], stream=out, tty=True)
    view.banner(Banner(vehicle="rover"))
    for t in (1.0, 2.0, 3.0):
        view.update(_snap(t))
    view.close()
    text = out.getvalue()
    head, live = text.split("\n\r", 1)
    assert "config" in head and "vehicle   rover" in head
    assert live.count("\r") == 2 and live.count("\x1b[K") == 3 and live.endswith("\x1b[K\n")


def test_console_elsewhere_logs_the_line_once_a_minute(caplog: pytest.LogCaptureFixture
                                                       ) -> None:
    out = io.StringIO()
    clock = FakeClock(0.0)
    view = ConsoleStatus(stream=out, tty=False, clock=clock)
    view.banner(Banner(vehicle="rover"))
    with caplog.at_level(logging.INFO, logger="fdi_bridge.status"):
        for k in range(1, 181):  # three minutes, one update a second
            clock.now = float(k)
            view.update(_snap(float(k)))
    view.close()
    assert "\r" not in out.getvalue() and "vehicle" in out.getvalue()
    lines = [r.getMessage() for r in caplog.records if r.name == "fdi_bridge.status"]
    assert len(lines) == 2  # at 61 s and 121 s (not at the start; 181 s not reached)
    assert all(m.startswith("status 0:0") and "gps up" in m for m in lines)


def test_quiet_shows_nothing() -> None:
    out = io.StringIO()
    view = ConsoleStatus(stream=out, tty=True, quiet=True)
    view.banner(Banner(vehicle="rover"))
    view.update(_snap(1.0))
    view.close()
    assert out.getvalue() == ""


def test_summary_text_is_an_aligned_table() -> None:
    _, summary, _ = _run([(3.05, 6.05)])
    text = run_summary_text(summary)
    lines = text.splitlines()
    assert lines[0].split() == ["vehicle", "rover"]
    assert any(line.split()[:2] == ["epochs", str(summary["epochs"])] for line in lines)
    header = next(line for line in lines if line.startswith("port"))
    row = lines[lines.index(header) + 1]
    assert row.split()[0] == "gps" and row.split()[1] == str(summary["ports"]["gps"]["bytes_rx"])
    assert len(row) == len(header)  # numbers right-aligned under their labels
    assert "{" not in text and "'" not in text  # no Python dicts


def test_a_log_record_on_the_terminal_clears_the_status_line_first() -> None:
    out = io.StringIO()
    handler = logging.StreamHandler(out)
    root = logging.getLogger()
    root.addHandler(handler)
    try:
        view = ConsoleStatus(stream=out, tty=True)
        view.update(_snap(1.0))
        logging.getLogger("fdi_bridge.test").warning("port lost")
        view.update(_snap(2.0))
        view.close()
        logging.getLogger("fdi_bridge.test").warning("after")
    finally:
        root.removeHandler(handler)
    text = out.getvalue()
    assert "last epoch 0.0 s ago\x1b[K\r\x1b[Kport lost\n\r0:00:02" in text
    assert text.endswith("\x1b[K\nafter\n")  # after close: no clearing
