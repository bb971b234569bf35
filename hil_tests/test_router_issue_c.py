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
from pathlib import Path

import pytest

from drivers.mavlink import io as mio
from fdi.errors import EndpointError
from firmware_host.mavlink.router import EndpointConfig, MavlinkConfig, Router

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
