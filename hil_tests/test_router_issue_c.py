"""Issue C (router): nothing a peer sends or the laptop does may stop the router.

Real sockets on 127.0.0.1, real pymavlink peers, the real command in a subprocess: a busy or
invalid endpoint is a clean start-up error (exit 2, the URL and the port's holder named); signing
links pass only RADIO_STATUS / RADIO unsigned and refuse group-readable keys; the framer resyncs
after stray bytes at a TCP link's start; routes expire; one PARAM_VALUE per peer; the bridge's
own packets go ahead of forwarded ones and drops are counted per endpoint.
"""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import pytest

from drivers.mavlink import io as mio
from drivers.mavlink.framer import MavFrame, MavFramer
from fdi.errors import ConfigError, EndpointError
from firmware_host.mavlink.router import (
    EndpointConfig,
    MavlinkConfig,
    Router,
    load_signing_key,
)

ROOT = Path(__file__).resolve().parents[1]


def _cli(*argv: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.run([sys.executable, "-m", "firmware_host.cli", *argv], cwd=cwd,
                          capture_output=True, text=True, timeout=60, env=env,
                          stdin=subprocess.DEVNULL)


# ---------------------------------------------------------------------------------------------
# Item 4: a busy or invalid endpoint


@pytest.fixture()
def qgc_on_a_port() -> tuple[int, mio.MavEndpoint]:
    """A ground station already listening (pymavlink's udpin, which sets SO_REUSEADDR as
    MAVProxy's does) on a free port of 127.0.0.1."""
    holder = mio.MavEndpoint("udpin:127.0.0.1:0", source_system=255, source_component=190)
    addr = holder.local_address
    assert addr is not None
    return addr[1], holder


def _rover_file(tmp_path: Path, gcs_url: str) -> Path:
    path = tmp_path / "bridge.toml"
    path.write_text(
        "[mavlink]\nstats_hz = 0.0\n[mavlink.autopilot]\nurl = \"udpin:127.0.0.1:0\"\n"
        f"[[mavlink.gcs]]\nurl = \"{gcs_url}\"\n"
        f"[rover.port]\nurl = \"{tmp_path / 'no-receiver'}\"\n", encoding="utf-8")
    return path


@pytest.mark.parametrize("command", ["mavlink", "run"])
def test_a_busy_udp_port_is_a_start_up_error_naming_its_holder(
        tmp_path: Path, qgc_on_a_port: tuple[int, mio.MavEndpoint], command: str) -> None:
    port, holder = qgc_on_a_port
    url = f"udpin:127.0.0.1:{port}"
    try:
        if command == "mavlink":
            proc = _cli("mavlink", "--autopilot", "udpin:127.0.0.1:0", "--gcs", url,
                        "--seconds", "1", cwd=tmp_path)
        else:
            proc = _cli("run", "--config", str(_rover_file(tmp_path, url)), "--duration", "1",
                        cwd=tmp_path)
    finally:
        holder.close()
    # Before: both sockets bound (SO_REUSEADDR on both) and shared the datagrams silently, or
    # "internal error: AttributeError: 'Router' object has no attribute '_stop'".
    assert proc.returncode == 2, proc.stderr
    assert "internal error" not in proc.stderr and "Traceback" not in proc.stderr
    line = proc.stderr.strip().splitlines()[-1]
    assert url in line
    assert f"in use by pid {os.getpid()} (" in line  # this test's process holds it


@pytest.mark.parametrize(("url", "text"), [
    ("udpin:300.1.1.1:14550", "'300.1.1.1' is not an IPv4 address"),
    ("udpin:300.1.1.1", "the port must be a number"),
    ("udpout:127.0.0.1:99999", "the port must be 0-65535, found 99999"),
    ("tcpin:127.0.0.1:70000", "the port must be 0-65535"),
])
def test_an_invalid_endpoint_is_a_start_up_error_naming_it(tmp_path: Path, url: str,
                                                           text: str) -> None:
    cfg = MavlinkConfig(autopilot=EndpointConfig("udpin:127.0.0.1:0"),
                        gcs=(EndpointConfig(url),))
    with pytest.raises(EndpointError) as err:
        Router(cfg)
    assert str(err.value).startswith(f"{url}: ") and text in str(err.value)
    proc = _cli("run", "--config", str(_rover_file(tmp_path, url)), "--duration", "1",
                cwd=tmp_path)
    assert proc.returncode == 2, proc.stderr
    assert "internal error" not in proc.stderr and url in proc.stderr and text in proc.stderr


def test_a_busy_tcp_port_names_its_holder_and_closes_what_was_opened() -> None:
    listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    listener.bind(("127.0.0.1", 0))
    listener.listen(1)
    port = listener.getsockname()[1]
    gcs = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    gcs.bind(("127.0.0.1", 0))
    free = gcs.getsockname()[1]
    gcs.close()
    cfg = MavlinkConfig(autopilot=EndpointConfig(f"udpin:127.0.0.1:{free}"),
                        gcs=(EndpointConfig(f"tcpin:127.0.0.1:{port}"),))
    try:
        with pytest.raises(EndpointError, match=rf"TCP port {port} is already in use by pid "
                                                rf"{os.getpid()} "):
            Router(cfg)
    finally:
        listener.close()
    # The autopilot's link, opened before the failing one, was closed: its port is free again.
    again = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        again.bind(("127.0.0.1", free))
    finally:
        again.close()


# ---------------------------------------------------------------------------------------------
# Item 8: signing links


def _wait(cond: Callable[[], bool], what: str, deadline_s: float = 10.0) -> None:
    end = time.monotonic() + deadline_s
    while not cond():
        if time.monotonic() > end:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0)  # yield to the router thread; the deadline bounds the wait


def _udp() -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    s.settimeout(0.01)
    return s


def _port(router: Router, i: int) -> int:
    addr = router.endpoints[i].link.local_address
    assert addr is not None
    return addr[1]


def _frames(sock: socket.socket) -> list[MavFrame]:
    """Every packet waiting on ``sock`` (one framer per datagram, as the router frames)."""
    out: list[MavFrame] = []
    while True:
        try:
            data = sock.recv(65535)
        except (TimeoutError, BlockingIOError):
            return out
        out += MavFramer().feed(data, boundary=True)


def _key_file(key_dir: Path, key: bytes, mode: int = 0o600) -> Path:
    path = key_dir / "signing.key"
    path.write_text(key.hex() + "\n")
    os.chmod(path, mode)
    return path


@pytest.mark.parametrize("allow", [None, ("HEARTBEAT",)])
def test_unsigned_heartbeat_neither_passes_nor_teaches_a_route_on_a_signing_link(
        key_dir: Path, allow: tuple[str, ...] | None) -> None:
    key = bytes(range(7, 39))
    gcs_cfg = EndpointConfig("udpin:127.0.0.1:0", signing=True)
    if allow is not None:
        gcs_cfg = replace(gcs_cfg, allow_unsigned=allow)
    cfg = MavlinkConfig(autopilot=EndpointConfig("udpin:127.0.0.1:0"), gcs=(gcs_cfg,),
                        signing_key_file=str(_key_file(key_dir, key)), stats_hz=0.0)
    router = Router(cfg)
    router.start()
    ap, gcs = _udp(), _udp()
    ap_pack, gcs_pack = mio.MavPacker(1, 1), mio.MavPacker(255, 190)
    try:
        ap.sendto(ap_pack.send_heartbeat(), ("127.0.0.1", _port(router, 0)))
        _wait(lambda: router.autopilot.link.has_peer(), "the autopilot to be seen")
        dest = ("127.0.0.1", _port(router, 1))
        gcs.sendto(gcs_pack.send_heartbeat(), dest)  # unsigned
        radio = gcs_pack._mav.radio_status_encode(200, 190, 100, 90, 50, 0, 0)
        gcs.sendto(gcs_pack._emit(radio), dest)  # unsigned, in ArduPilot's accept list
        # The default (ArduPilot's list) passes RADIO_STATUS, refuses HEARTBEAT; configured
        # to pass HEARTBEAT (a GCS that cannot sign), RADIO_STATUS is refused instead.
        passed = _RADIO_STATUS if allow is None else 0
        got: list[MavFrame] = []
        _wait(lambda: router.stats.refused_unsigned == 1 and any(
            f.msgid == passed and f.sysid == 255 for f in _extend(got, ap)),
            "one packet refused, the other at the autopilot")
        assert [f.msgid for f in got if f.sysid == 255] == [passed]
        assert router.stats.unsigned_allowed == 1
        peer = router.endpoints[-1]
        assert peer.parent is not None  # the GCS's peer endpoint
        # Nothing unsigned taught a route: a command targeted at (255, 190) has nowhere to go.
        assert peer.seen == set() and peer.seen_sys == set()
        # A signed heartbeat does teach it.
        gcs_pack.setup_signing(key, link_id=3)
        gcs.sendto(gcs_pack.send_heartbeat(), dest)
        _wait(lambda: (255, 190) in peer.seen, "the signed heartbeat's route")
    finally:
        router.close()
        ap.close()
        gcs.close()


def _extend(got: list[MavFrame], sock: socket.socket) -> list[MavFrame]:
    got += _frames(sock)
    return got


_RADIO_STATUS = mio.message_id("RADIO_STATUS")


@pytest.mark.parametrize("mode", [0o640, 0o660, 0o644, 0o604, 0o610])
def test_a_key_file_open_to_its_group_or_others_is_refused(key_dir: Path, mode: int) -> None:
    path = _key_file(key_dir, bytes(32), mode)
    with pytest.raises(ConfigError) as err:
        load_signing_key(path)
    assert f"mode {mode:04o}" in str(err.value) and "chmod 600" in str(err.value)
    assert str(path) in str(err.value)


@pytest.mark.parametrize("mode", [0o600, 0o400])
def test_an_owner_only_key_file_is_accepted(key_dir: Path, mode: int) -> None:
    assert load_signing_key(_key_file(key_dir, bytes(range(32)), mode)) == bytes(range(32))


def test_a_group_readable_key_stops_the_command_at_start(key_dir: Path, tmp_path: Path) -> None:
    path = _key_file(key_dir, bytes(32), 0o640)
    cfg = tmp_path / "m.toml"
    cfg.write_text(f"[mavlink]\nsigning_key_file = \"{path}\"\n[mavlink.autopilot]\n"
                   "url = \"udpin:127.0.0.1:0\"\n[[mavlink.gcs]]\nurl = \"udpin:127.0.0.1:0\"\n"
                   "signing = true\n", encoding="utf-8")
    proc = _cli("mavlink", "--config", str(cfg), "--seconds", "1", cwd=tmp_path)
    assert proc.returncode == 2, proc.stderr
    assert "mode 0640" in proc.stderr and "internal error" not in proc.stderr
