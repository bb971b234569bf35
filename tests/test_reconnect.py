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
from drivers.resilient import ResilientPort
from drivers.transport import SerialSettings
from fdi.errors import PortError
from firmware_host.commands.run import RoverBridge, run_rov_bridge
from firmware_host.devtools.rover_sim import RoverScenario, generate
from firmware_host.runtime.config import BridgeConfig, RoverConfig
from firmware_host.runtime.loop import FakeClock

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
    from drivers.outland.framecodec import load_protocol
    from firmware_host.devtools.rov_sim import RovPlant, RovSimServer, serve_pty
    from firmware_host.rov.config import SimConfig

    proto = load_protocol(ROOT / "config" / "protocols" / "outland1000.toml")
    link = tmp_path / "rovlink"
    cfg_file = tmp_path / "rov.toml"
    cfg_file.write_text(
        "[rov]\nperiod_s = 0.05\ndropout_hold_s = 0.1\n[rov.link]\nwiring = \"rs232\"\n"
        f"protocol = \"{ROOT / 'config' / 'protocols' / 'outland1000.toml'}\"\n"
        "reconnect_max_s = 0.2\n[rov.link.port]\n"
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


# --------------------------------------------------------------------------- MAVLink serial links


def _heartbeats(data: bytes, src: tuple[int, int]) -> int:
    """HEARTBEATs from ``src`` (system, component) in a MAVLink byte stream."""
    from drivers.mavlink.framer import MavFramer

    n = 0
    for frame in MavFramer().feed(data):
        if frame.msgid == 0 and (frame.sysid, frame.compid) == src:
            n += 1
    return n


def test_router_serial_link_survives_autopilot_reboot(tmp_path: Path) -> None:
    """The autopilot's USB port vanishes (a reboot) and comes back under the same path: the
    router keeps serving the ground station, drops and counts what it cannot deliver, reopens
    the path by itself, and packets flow both ways again."""
    from drivers.mavlink.io import MavEndpoint, MavPacker
    from firmware_host.mavlink.router import EndpointConfig, MavlinkConfig, Router

    link = tmp_path / "ttyACM0"
    pty = PtyPair(link=link, baudrate=115200)
    cfg = MavlinkConfig(autopilot=EndpointConfig(str(link), baud=115200),
                        gcs=(EndpointConfig("udpin:127.0.0.1:0"),), reconnect_max_s=0.2)
    router = Router(cfg)
    router.start()
    addr = router.endpoints[1].link.local_address
    assert addr is not None
    gcs = MavEndpoint(f"udpout:127.0.0.1:{addr[1]}", source_system=255, source_component=190)
    autopilot = MavPacker(source_system=1, source_component=1)
    serial_link = router.endpoints[0].link
    got: list[int] = []

    def autopilot_heartbeat_reaches_gcs(p: PtyPair) -> bool:
        p.write(autopilot.send_heartbeat())
        msg = gcs.recv(timeout_s=0.02)
        while msg is not None:
            if (msg.get_srcSystem(), msg.get_srcComponent()) == (1, 1):
                got.append(1)
                return True
            msg = gcs.recv(0.0)
        return False

    pty2: PtyPair | None = None
    try:
        gcs.send_heartbeat()
        wait_for(lambda: autopilot_heartbeat_reaches_gcs(pty), what="autopilot -> gcs")
        pty.close()  # the autopilot reboots: its USB device node goes away
        assert not link.exists()
        wait_for(lambda: serial_link.port.losses == 1, what="loss detected")
        before = serial_link.port.tx_dropped
        wait_for(lambda: (gcs.send_heartbeat(), serial_link.port.tx_dropped > before)[1],
                 what="gcs packets dropped and counted while the autopilot is away")
        assert router._thread is not None and router._thread.is_alive()
        pty2 = PtyPair(link=link, baudrate=115200)  # ... and is back
        wait_for(lambda: serial_link.port.up, what="reopened")
        p2 = pty2
        wait_for(lambda: autopilot_heartbeat_reaches_gcs(p2), what="autopilot -> gcs again")
        seen = bytearray()

        def gcs_heartbeat_reaches_autopilot() -> bool:
            gcs.send_heartbeat()
            seen.extend(p2.read(0.02))
            return _heartbeats(bytes(seen), (255, 190)) > 0

        wait_for(gcs_heartbeat_reaches_autopilot, what="gcs -> autopilot again")
        assert serial_link.port.losses == 1 and serial_link.port.reopens == 1
        assert router.endpoints[0].link.errors >= 1  # the loss, in the router's link statistics
    finally:
        router.close()
        gcs.close()
        pty.close()
        if pty2 is not None:
            pty2.close()


def test_rover_serial_mavlink_output_survives_autopilot_reboot(tmp_path: Path) -> None:
    """``rover.output.mavlink_url`` is a serial device: GPS_INPUT stops while it is gone (counted
    as dropped), and resumes on the same path without a restart."""
    from drivers.mavlink.framer import MavFramer

    gps_link, ap_link = tmp_path / "gps", tmp_path / "ttyACM0"
    gps = PtyPair(link=gps_link, baudrate=9600)
    ap = PtyPair(link=ap_link, baudrate=57600)
    settings = SerialSettings(url=str(gps_link), baudrate=9600, timeout_s=0.02)
    out = BridgeConfig().rover.output
    from dataclasses import replace

    cfg = BridgeConfig(rover=RoverConfig(
        port=settings, reconnect_max_s=0.2,
        output=replace(out, mavlink_url=str(ap_link), hold_on_alarm=False)))
    bridge = RoverBridge(cfg)
    stop = threading.Event()
    thread = threading.Thread(target=bridge.run, args=(stop.is_set,), daemon=True)
    thread.start()
    epochs = _epochs(200, seed=5)
    gps_input_id = 232

    def gps_inputs(p: PtyPair, buf: bytearray) -> int:
        buf.extend(p.read(0.01))
        return sum(1 for f in MavFramer().feed(bytes(buf)) if f.msgid
                   == gps_input_id)

    ap2: PtyPair | None = None
    try:
        buf = bytearray()
        _feed(gps, epochs[:60])
        wait_for(lambda: gps_inputs(ap, buf) >= 50, what="GPS_INPUT on the serial line")
        ap.close()
        assert bridge.mav_out is not None
        mav_port = bridge.mav_out.port
        wait_for(lambda: mav_port.losses == 1, what="loss of the autopilot's port")
        _feed(gps, epochs[60:100])
        wait_for(lambda: bridge.pipeline.epochs >= 99, what="epochs while away")
        assert mav_port.tx_dropped > 0
        assert thread.is_alive()
        ap2 = PtyPair(link=ap_link, baudrate=57600)
        wait_for(lambda: mav_port.up, what="reopened")
        buf2 = bytearray()
        _feed(gps, epochs[100:])
        p2 = ap2
        wait_for(lambda: gps_inputs(p2, buf2) >= 80, what="GPS_INPUT again")
        s = bridge.summary()
        assert s["mavlink_out"]["losses"] == 1 and s["mavlink_out"]["reopens"] == 1
        assert s["output_errors"] == 0  # the sink never saw an exception
    finally:
        stop.set()
        thread.join(5.0)
        bridge.close()
        gps.close()
        ap.close()
        if ap2 is not None:
            ap2.close()


def test_replay_nmea_output_survives_adapter_unplugged(tmp_path: Path) -> None:
    """Hardware-in-the-loop replay into a serial line (``replay --nmea-out /dev/ttyUSB1``): the
    adapter is unplugged and plugged back; the output reopens the same path by itself."""
    from firmware_host.rover.outputs import NmeaSink
    from firmware_host.rover.pipeline import RoverPipeline

    link = tmp_path / "ttyUSB1"
    pty = PtyPair(link=link, baudrate=9600)
    sink = NmeaSink(str(link), 9600, backoff_max_s=0.2)
    pipe = RoverPipeline(RoverConfig(), sinks=[sink])
    epochs = iter(_epochs(400, seed=6))
    pty2: PtyPair | None = None
    try:
        for _ in range(30):
            pipe.feed(next(epochs))
        got = bytearray()
        wait_for(lambda: (got.extend(pty.read(0.01)), got.count(b"GGA,") >= 29)[1],
                 what="corrected NMEA on the line")
        pty.close()  # unplugged
        for _ in range(30):
            pipe.feed(next(epochs))
        port = sink.writer.port
        assert port is not None and port.losses == 1 and sink.writer.dropped_bytes > 0
        pty2 = PtyPair(link=link, baudrate=9600)  # plugged back
        p2 = pty2
        wait_for(lambda: (pipe.feed(next(epochs)), port.up)[1], what="reopened")
        got2 = bytearray()
        for _ in range(20):
            pipe.feed(next(epochs))
        wait_for(lambda: (got2.extend(p2.read(0.01)), got2.count(b"GGA,") >= 20)[1],
                 what="corrected NMEA again")
        assert port.reopens == 1 and pipe.summary()["output_errors"] == 0
        assert sink.stats()["port"]["losses"] == 1
    finally:
        pipe.finish()
        pty.close()
        if pty2 is not None:
            pty2.close()
