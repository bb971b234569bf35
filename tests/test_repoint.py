"""A re-pointed device path (issue 18 item 4): a udev symlink such as /dev/gps0 now naming
another device while the old one stays open. The port notices (the path's device/inode
changed) and reopens on the new device; the bridge follows."""

from __future__ import annotations

import logging
import os
import threading
import time
from pathlib import Path

import pytest

from drivers.ptypair import PtyPair
from drivers.resilient import ResilientPort
from drivers.transport import SerialSettings
from firmware_host.commands.run import RoverBridge
from firmware_host.devtools.rover_sim import RoverScenario, generate
from firmware_host.runtime.config import BridgeConfig, RoverConfig
from firmware_host.runtime.loop import FakeClock


def _repoint(link: Path, target: str) -> None:
    """Move the symlink atomically, as udev does (a new link renamed over the old one)."""
    tmp = link.with_name(link.name + ".new")
    os.symlink(target, tmp)
    os.replace(tmp, link)


def _read_for(port: ResilientPort, seconds: float = 1.0) -> bytes:
    got = b""
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        got += port.read_some()
        if got.endswith(b"\n"):
            break
        threading.Event().wait(0.01)
    return got


def test_repointed_symlink_is_followed_while_the_old_pty_stays_open(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    link = tmp_path / "gps0"
    clock = FakeClock()
    with PtyPair(link=link) as old, PtyPair() as new:
        port = ResilientPort(SerialSettings(url=str(link), timeout_s=0.0), name="gps",
                             clock=clock, repoint_check_s=1.0)
        old.write(b"$OLD,1\r\n")
        assert _read_for(port) == b"$OLD,1\r\n"
        _repoint(link, new.slave_path)  # the old pty is still open and still writable
        old.write(b"$OLD,2\r\n")
        clock.now = 0.5  # before the next check: still on the old device
        assert _read_for(port) == b"$OLD,2\r\n" and port.repoints == 0
        clock.now = 1.0
        with caplog.at_level(logging.WARNING, logger="fdi_bridge.port"):
            port.read_some()  # the check: the path names another device now
        assert port.repoints == 1 and port.up
        assert sum("now names another device" in r.getMessage() for r in caplog.records) == 1
        new.write(b"$NEW,1\r\n")
        old.write(b"$OLD,3\r\n")  # the stale device is no longer read
        assert _read_for(port) == b"$NEW,1\r\n"
        clock.now = 5.0  # later checks find the same device: no more reopening
        port.read_some()
        assert port.repoints == 1 and port.counters()["repoints"] == 1
        assert port.losses == 0  # not a loss: the old device never failed
        port.close()


def test_urls_that_are_not_paths_are_never_checked() -> None:
    clock = FakeClock()
    port = ResilientPort(SerialSettings(url="loop://", timeout_s=0.0), clock=clock)
    port.write(b"abc")
    clock.now = 10.0
    assert port.read_some() == b"abc" and port.repoints == 0
    port.close()


def test_rover_bridge_follows_a_repointed_gps_symlink(tmp_path: Path) -> None:
    """The rover running in a thread on a symlinked pty; the link is re-pointed to a second
    receiver while the first stays open; epochs resume from the new one (real clock, the
    check every 0.2 s)."""
    link = tmp_path / "gps0"
    sc = RoverScenario(rate_hz=10.0, duration_s=6.0, seed=3)
    epochs = [data for _, data, _ in generate(sc)]
    cfg = BridgeConfig(rover=RoverConfig(port=SerialSettings(url=str(link), timeout_s=0.02)))
    with PtyPair(link=link) as first, PtyPair() as second:
        bridge = RoverBridge(cfg)
        bridge.port.repoint_check_s = 0.2
        stop = threading.Event()
        th = threading.Thread(target=bridge.run, args=(stop.is_set,), daemon=True)
        th.start()
        try:
            for data in epochs[:30]:
                first.write(data)
            deadline = time.monotonic() + 10.0
            while bridge.pipeline.epochs < 29 and time.monotonic() < deadline:
                stop.wait(0.02)
            n_first = bridge.pipeline.epochs
            assert n_first >= 29
            _repoint(link, second.slave_path)
            deadline = time.monotonic() + 10.0
            while bridge.port.repoints == 0 and time.monotonic() < deadline:
                first.write(b"$GPTXT,01,01,02,stale*00\r\n")  # the old one is still alive
                stop.wait(0.05)
            assert bridge.port.repoints == 1
            for data in epochs[30:]:
                second.write(data)
            deadline = time.monotonic() + 10.0
            while bridge.pipeline.epochs < 59 and time.monotonic() < deadline:
                stop.wait(0.02)
            assert bridge.pipeline.epochs >= 59  # epochs from the new receiver
        finally:
            stop.set()
            th.join(5.0)
            bridge.close()
