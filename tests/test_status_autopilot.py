"""The status line says whether the autopilot is there and what it made of our fix (issue 45):
its HEARTBEAT's age and its GPS_RAW_INT (fix type, satellites), as mavlink-routerd's stats and
cgps would show them. Real parts: the receiver on a pty, GPS_INPUT over UDP on 127.0.0.1 to a
simulated autopilot (a socket that answers each GPS_INPUT with a HEARTBEAT and a GPS_RAW_INT
of what it received, as ArduPilot's AP_GPS_MAV does), and over the router's autopilot link."""

from __future__ import annotations

import os
import socket
import time
from dataclasses import replace
from pathlib import Path

from drivers.mavlink.framer import MavFramer
from drivers.mavlink.io import MAV_TYPE_GCS, MavPacker, decode_packet
from drivers.ptypair import PtyPair
from drivers.transport import SerialSettings
from firmware_host.commands.live import autopilot_text, status_line
from firmware_host.commands.run import RoverBridge
from firmware_host.devtools.rover_sim import RoverScenario, generate
from firmware_host.runtime.config import BridgeConfig, RoverConfig
from firmware_host.runtime.status import AutopilotView

MAV_TYPE_GROUND_ROVER = 10
ROOT = Path(__file__).resolve().parents[1]


class Autopilot:
    """A UDP socket on 127.0.0.1 that answers GPS_INPUT with its HEARTBEAT and GPS_RAW_INT
    (the fix type and satellites it was given); ``silent`` stops the answers."""

    def __init__(self) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.setblocking(False)
        self.port = self.sock.getsockname()[1]
        self.packer = MavPacker(source_system=1, source_component=1)
        self.gcs = MavPacker(source_system=255, source_component=190)
        self.silent = False
        self.got = 0

    def serve(self) -> None:
        while True:
            try:
                data, peer = self.sock.recvfrom(4096)
            except BlockingIOError:
                return
            for frame in MavFramer().feed(data):
                msg = decode_packet(frame.raw)
                if msg is None or msg.get_type() != "GPS_INPUT" or self.silent:
                    continue
                self.got += 1
                self.sock.sendto(self.gcs.send_vehicle_heartbeat(MAV_TYPE_GCS, 0, 0), peer)
                self.sock.sendto(self.packer.send_vehicle_heartbeat(MAV_TYPE_GROUND_ROVER, 0, 0)
                                 + self.packer.send_gps_raw_int(
                                     0, int(msg.fix_type), msg.lat * 1e-7, msg.lon * 1e-7,
                                     msg.alt, int(msg.satellites_visible)), peer)

    def close(self) -> None:
        self.sock.close()


def _run(tmp_path: Path, ap: Autopilot, seconds: float, silent_after: float | None = None
         ) -> tuple[str, int]:
    sc = RoverScenario(rate_hz=10.0, duration_s=seconds + 2.0, seed=2, kinds=())
    epochs = [data for _t, data, _truth in generate(sc)]
    pty = PtyPair(link=tmp_path / "gps")
    rc = RoverConfig()
    cfg = BridgeConfig(rover=replace(
        rc, port=SerialSettings(url=pty.url, baudrate=38400, timeout_s=0.02),
        output=replace(rc.output, mavlink_url=f"udpout:127.0.0.1:{ap.port}")))
    bridge = RoverBridge(cfg)
    try:
        t0 = time.monotonic()
        sent = 0
        next_status = t0 + 1.0
        while time.monotonic() - t0 < seconds:
            if time.monotonic() >= next_status:  # as the runner's status sink, once a second
                next_status += 1.0
                status_line(bridge.runner.snapshot())
            if silent_after is not None and time.monotonic() - t0 > silent_after:
                ap.silent = True
            if sent < len(epochs) and sent < (time.monotonic() - t0) * 10.0:  # 10 Hz
                os.write(pty.master_fd, epochs[sent])
                sent += 1
            bridge.step()
            ap.serve()
        line = status_line(bridge.runner.snapshot())
        sats = bridge.pipeline.last_outcome.epoch.num_sats  # type: ignore[union-attr]
    finally:
        bridge.close()
        pty.close()
    return line, int(sats or 0)


def test_the_status_line_shows_the_autopilot_and_its_echo_of_our_fix(tmp_path: Path) -> None:
    ap = Autopilot()
    try:
        line, sats = _run(tmp_path, ap, 3.0)
    finally:
        ap.close()
    assert ap.got >= 10
    last = line.split(" | ")[-1]
    assert last.startswith("autopilot hb "), line
    age = float(last.split()[2])
    assert age < 1.5, line
    assert last.endswith(f" echo DGPS {sats}sv"), line  # GGA quality 2 -> GPS_INPUT fix 4


def test_a_silent_autopilot_is_said(tmp_path: Path) -> None:
    ap = Autopilot()
    try:
        line, sats = _run(tmp_path, ap, 6.0, silent_after=1.5)
    finally:
        ap.close()
    last = line.split(" | ")[-1]
    assert last.startswith("autopilot SILENT "), line
    assert float(last.split()[2]) >= 3.0
    assert f"echo DGPS {sats}sv" in last and last.endswith(" s ago"), line


def test_no_autopilot_at_all() -> None:
    assert autopilot_text(AutopilotView(None)) == "autopilot no heartbeat"
    assert autopilot_text(AutopilotView(0.4)) == "autopilot hb 0.4 s no GPS_RAW_INT"
    assert autopilot_text(AutopilotView(0.4, 3, 12, 0.4)) == "autopilot hb 0.4 s echo 3D 12sv"
    assert autopilot_text(AutopilotView(9.0, 1, 0, 9.0)) == \
        "autopilot SILENT 9 s echo no fix 0sv 9 s ago"


def test_through_the_router_the_autopilot_link_is_watched() -> None:
    """With ``[mavlink]`` the echo listens on the router's autopilot link (its thread keeps
    times and raw packets; the status decodes them): a ground station's heartbeat on the other
    link is not the autopilot's."""
    from firmware_host.mavlink.router import EndpointConfig, MavlinkConfig, Router
    from firmware_host.runtime.autopilot_echo import attach
    from firmware_host.runtime.mavout import router_output

    router = Router(MavlinkConfig(autopilot=EndpointConfig("udpin:127.0.0.1:0"),
                                  gcs=(EndpointConfig("udpin:127.0.0.1:0"),)))
    echo = attach(router_output(router), router)
    assert echo is not None
    router.start()
    ports = [ep.link.local_address[1] for ep in router.endpoints]  # type: ignore[index]
    ap, gcs = MavPacker(1, 1), MavPacker(255, 190)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        try:
            for frame in MavFramer().feed(ap.send_vehicle_heartbeat(MAV_TYPE_GCS, 0, 0)):
                echo.on_frame(frame)  # a GCS-type heartbeat on the autopilot link
            assert echo.view().heartbeat_age_s is None  # is not the autopilot's
            s.sendto(gcs.send_vehicle_heartbeat(MAV_TYPE_GCS, 0, 0), ("127.0.0.1", ports[1]))
            deadline = time.monotonic() + 5.0
            s.sendto(ap.send_vehicle_heartbeat(MAV_TYPE_GROUND_ROVER, 0, 0)
                     + ap.send_gps_raw_int(0, 3, 47.0, 8.0, 400.0, 11), ("127.0.0.1", ports[0]))
            view = echo.view()
            while time.monotonic() < deadline and view.gps_fix_type is None:
                time.sleep(0.01)
                view = echo.view()
        finally:
            router.close()
    assert view.heartbeat_age_s is not None and view.heartbeat_age_s < 1.0
    assert (view.gps_fix_type, view.gps_sats) == (3, 11)


def test_fdi_bridge_run_on_a_terminal_shows_the_autopilot(tmp_path: Path) -> None:
    """``fdi-bridge run`` as a subprocess, its stderr on a real terminal (a pty), the receiver
    on another pty at 10 Hz, GPS_INPUT to the simulated autopilot: the refreshing status line
    ends with the autopilot's heartbeat age and its echo of our fix."""
    import re
    import threading

    from tests.ptyrun import cli_under_pty

    sc = RoverScenario(rate_hz=10.0, duration_s=30.0, seed=2, kinds=())
    epochs = [data for _t, data, _truth in generate(sc)]
    ap = Autopilot()
    halt = threading.Event()
    with PtyPair(link=tmp_path / "gps", baudrate=38400) as gps:
        cfg = tmp_path / "bridge.toml"
        cfg.write_text(f'[rover.port]\nurl = "{gps.url}"\nbaudrate = 38400\n'
                       f'[rover.output]\nmavlink_url = "udpout:127.0.0.1:{ap.port}"\n')

        def feed() -> None:
            for chunk in epochs:
                if halt.is_set():
                    return
                gps.write(chunk)
                gps.read(0.0)
                ap.serve()
                halt.wait(0.1)

        thread = threading.Thread(target=feed, daemon=True)
        thread.start()
        try:
            rc, text = cli_under_pty(["run", "--config", str(cfg), "--duration", "4"],
                                     tmp_path, timeout=30.0,
                                     env=dict(os.environ, PYTHONPATH=str(ROOT), COLUMNS="250"))
        finally:
            halt.set()
            thread.join(5.0)
            ap.close()
    assert rc == 0, text
    lines = [x.removesuffix("\x1b[K") for x in text.split("\r") if "| gps up" in x]
    assert len(lines) >= 3, text
    assert re.search(r"\| autopilot hb \d+\.\d s echo DGPS 9sv$", lines[-1]), lines[-1]
