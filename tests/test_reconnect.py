"""Port loss and return: reported once, the loop keeps running, the same URL reopened, data resumes.

The first tests drive :class:`ResilientPort` with a fake device on a :class:`FakeClock`
(backoff schedule, cap, report-once). The pty tests run the real rover bridge and the real ROV
loop in a thread on a real pseudo-terminal, close its far end or remove its symlinked device
path, and poll (with a deadline) until data flows again; nothing sleeps to wait for an event.
"""

from __future__ import annotations

import itertools
import logging
import os
import threading
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from drivers.ptypair import PtyPair
from drivers.transport import SerialSettings
from fdi.errors import PortError
from firmware_host.config import BridgeConfig, RoverConfig
from firmware_host.loop import FakeClock
from firmware_host.reconnect import ResilientPort
from firmware_host.rover_sim import RoverScenario, generate
from firmware_host.run import RoverBridge, run_rov_bridge

ROOT = Path(__file__).resolve().parents[1]


def wait_for(cond: Callable[[], bool], timeout_s: float = 10.0, what: str = "") -> None:
    """Poll ``cond`` until true or the deadline (yields the CPU with a short select)."""
    deadline = time.monotonic() + timeout_s
    ev = threading.Event()
    while not cond():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what or cond}")
        ev.wait(0.005)


class FakeDevice:
    def __init__(self) -> None:
        self.present = True
        self.broken = False
        self.data = bytearray()
        self.opens: list[float] = []


class FakePort:
    def __init__(self, dev: FakeDevice) -> None:
        self.dev = dev
        self.port = "fake"

    @property
    def in_waiting(self) -> int:
        if self.dev.broken:
            raise OSError(5, "Input/output error")
        return len(self.dev.data)

    def read(self, size: int = 1) -> bytes:
        if self.dev.broken:
            raise OSError(5, "Input/output error")
        out = bytes(self.dev.data[:size])
        del self.dev.data[:size]
        return out

    def write(self, data: bytes) -> int:
        if self.dev.broken:
            raise OSError(5, "Input/output error")
        return len(data)

    def close(self) -> None:
        pass


def _opener(dev: FakeDevice, clock: FakeClock):
    def opener(settings: SerialSettings) -> FakePort:
        dev.opens.append(clock())
        if not dev.present:
            raise PortError(f"could not open {settings.url!r}: no such file")
        dev.broken = False
        return FakePort(dev)

    return opener


def test_backoff_is_capped_and_loss_reported_once(caplog: pytest.LogCaptureFixture) -> None:
    clock = FakeClock(100.0)
    dev = FakeDevice()
    got = bytearray()
    port = ResilientPort(SerialSettings(url="/dev/ttyUSB9"), backoff_min_s=0.1,
                         backoff_max_s=1.0, clock=clock, opener=_opener(dev, clock),
                         on_rx=got.extend)
    dev.data += b"abc"
    assert port.read_some() == b"abc"
    caplog.set_level(logging.DEBUG, logger="fdi_bridge.port")
    caplog.clear()
    dev.broken, dev.present = True, False  # unplugged
    t_loss = clock()
    for _ in range(1000):  # the loop keeps running: reads return b"" at once, never raise
        assert port.read_some() == b""
        assert port.write(b"x") == 0
        clock.advance(0.01)
    assert port.losses == 1
    lost = [r for r in caplog.records if r.levelno >= logging.WARNING]
    assert len(lost) == 1 and "lost" in lost[0].getMessage()
    # Attempts after the loss: +0.1, then gaps 0.1 0.2 0.4 0.8 1.0 1.0 ... (capped at 1.0 s).
    opens = [t - t_loss for t in dev.opens[1:]]
    gaps = [round(b - a, 2) for a, b in itertools.pairwise(opens)]
    assert opens[0] == pytest.approx(0.1, abs=0.011)
    assert gaps[:4] == pytest.approx([0.1, 0.2, 0.4, 0.8], abs=0.011)
    assert all(g == pytest.approx(1.0, abs=0.011) for g in gaps[4:]) and len(gaps) >= 8
    assert port.tx_dropped == 1000
    # Plugged back: the same URL opens at the next attempt and data resumes.
    dev.present = True
    caplog.clear()
    dev.data += b"def"
    for _ in range(120):
        got_now = port.read_some()
        if got_now:
            break
        clock.advance(0.01)
    assert got_now == b"def" and port.up and port.reopens == 1
    back = [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]
    assert len(back) == 1 and "is back" in back[0]
    assert bytes(got) == b"abcdef" and port.bytes_rx == 6


def test_absent_at_start_is_not_fatal() -> None:
    clock = FakeClock()
    dev = FakeDevice()
    dev.present = False
    port = ResilientPort(SerialSettings(url="/dev/gps"), clock=clock, opener=_opener(dev, clock))
    assert not port.up and port.read_some() == b""
    dev.present = True
    clock.advance(0.2)
    assert port.service() and port.up and port.reopens == 1


# --------------------------------------------------------------------------- real ptys


def _epochs(n: int, seed: int = 3) -> list[bytes]:
    sc = RoverScenario(rate_hz=10.0, duration_s=n / 10.0, seed=seed, fault_every_s=1e9)
    return [data for _, data, _ in generate(sc)]


class _RoverThread:
    def __init__(self, url: str) -> None:
        settings = SerialSettings(url=url, baudrate=9600, timeout_s=0.02)
        cfg = BridgeConfig(rover=RoverConfig(port=settings, reconnect_max_s=0.2))
        self.bridge = RoverBridge(cfg)
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self.bridge.run, args=(self.stop.is_set,),
                                       daemon=True)
        self.thread.start()

    def close(self) -> None:
        self.stop.set()
        self.thread.join(5.0)
        self.bridge.close()


def _feed(pty: PtyPair, chunks: list[bytes]) -> None:
    for c in chunks:
        pty.write(c)


def test_rover_survives_far_end_closing_and_reopening(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING)
    link = tmp_path / "gps"
    epochs = _epochs(120)
    pty = PtyPair(link=link, baudrate=9600)
    rover = _RoverThread(str(link))
    try:
        b = rover.bridge
        _feed(pty, epochs[:50])
        wait_for(lambda: b.pipeline.epochs >= 49, what="first epochs")
        # The far end closes (the device's side of the pty goes away); the link goes stale.
        os.close(pty.master_fd)
        pty.master_fd = -1
        wait_for(lambda: b.port.losses == 1, what="loss detected")
        wait_for(lambda: b.port.open_failures >= 2, what="reopen attempts")
        # It comes back under the same name: the bridge reopens that URL by itself.
        pty.close_slave_keepalive()
        pty2 = PtyPair(link=link, baudrate=9600)
        wait_for(lambda: b.port.up, what="port back")
        _feed(pty2, epochs[50:])
        wait_for(lambda: b.pipeline.epochs >= 118, what="data resumed")
        assert b.port.losses == 1 and b.port.reopens == 1
        assert rover.thread.is_alive()
        lost = [r for r in caplog.records if "lost" in r.getMessage()]
        assert len(lost) == 1
        pty2.close()
    finally:
        rover.close()
        pty.close()


def test_rover_survives_device_path_removed_and_recreated(tmp_path: Path) -> None:
    link = tmp_path / "ttyUSB-gps"  # a udev-style symlink
    epochs = _epochs(120, seed=4)
    pty = PtyPair(link=link)
    rover = _RoverThread(str(link))
    try:
        b = rover.bridge
        _feed(pty, epochs[:40])
        wait_for(lambda: b.pipeline.epochs >= 39, what="first epochs")
        pty.close()  # unplugged: the device node is removed and the open port fails
        assert not link.exists()
        wait_for(lambda: b.port.losses == 1 and b.port.open_failures >= 3, what="retrying")
        assert rover.thread.is_alive()
        pty2 = PtyPair(link=link)  # plugged back in: the same path appears again
        wait_for(lambda: b.port.up, what="reopened")
        _feed(pty2, epochs[40:])
        wait_for(lambda: b.pipeline.epochs >= 118, what="data resumed")
        assert b.port.reopens == 1
        pty2.close()
    finally:
        rover.close()


def test_rov_link_survives_far_end_closing(tmp_path: Path) -> None:
    """`fdi-bridge run` on an ROV config: the link's pty goes away and comes back."""
    from drivers.framecodec import load_protocol
    from firmware_host.rov_config import SimConfig
    from firmware_host.rov_sim import RovPlant, RovSimServer, serve_pty

    proto = load_protocol(ROOT / "config" / "protocols" / "outland1000.toml")
    link = tmp_path / "rovlink"
    cfg_file = tmp_path / "rov.toml"
    cfg_file.write_text(
        "period_s = 0.05\ndropout_hold_s = 0.1\n[link]\nwiring = \"rs232\"\n"
        f"protocol = \"{ROOT / 'config' / 'protocols' / 'outland1000.toml'}\"\n"
        "reconnect_max_s = 0.2\n[link.port]\n"
        f"url = \"{link}\"\nbaudrate = 115200\n"
    )

    def serve(pty: PtyPair, stop: threading.Event) -> threading.Thread:
        srv = RovSimServer(RovPlant(SimConfig()), proto, "rs232", node=1, period_s=0.05)
        th = threading.Thread(target=serve_pty, args=(pty, srv, stop), daemon=True)
        th.start()
        return th

    records: list[dict] = []
    stop_bridge = threading.Event()
    pty = PtyPair(link=link, baudrate=115200)
    stop1 = threading.Event()
    th1 = serve(pty, stop1)
    result: dict = {}
    bridge = threading.Thread(
        target=lambda: result.update(run_rov_bridge(cfg_file, stop_event=stop_bridge,
                                                    on_epoch=records.append)),
        daemon=True)
    bridge.start()
    try:
        def telemetry() -> int:
            return sum(r["heading_meas"] is not None for r in list(records))

        wait_for(lambda: telemetry() >= 20, what="telemetry")
        stop1.set()
        th1.join(2.0)
        pty.close()  # the vehicle's side goes away (and its symlink)
        n_lost = len(records)
        wait_for(lambda: any(r["action"] == "neutral" for r in records[n_lost:]),
                 what="neutral after the hold")
        before = telemetry()
        pty2 = PtyPair(link=link, baudrate=115200)
        stop2 = threading.Event()
        th2 = serve(pty2, stop2)
        wait_for(lambda: telemetry() >= before + 20, what="telemetry resumed")
        assert bridge.is_alive()
        stop_bridge.set()
        bridge.join(5.0)
        stop2.set()
        th2.join(2.0)
        pty2.close()
        assert result["port"]["losses"] == 1 and result["port"]["reopens"] == 1
        assert result["failsafe"]["neutral"] >= 1
        assert records[-1]["action"] in ("control", "substitute")
    finally:
        stop_bridge.set()
        stop1.set()
        bridge.join(5.0)
        pty.close()
