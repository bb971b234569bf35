"""The MAVLink configuration: the example file stays valid, bad files fail with the key."""

from __future__ import annotations

from pathlib import Path

import pytest

from fdi.errors import ConfigError
from firmware_host.mavlink.router import (
    EndpointConfig,
    MavlinkConfig,
    TlogWriter,
    load_mavlink_config,
    load_vehicle_config,
)
from firmware_host.rover.pipeline import RoverPipeline
from firmware_host.runtime.config import BridgeConfig

EXAMPLE = Path(__file__).resolve().parents[1] / "config" / "mavlink-example.toml"


def test_example_config_loads_both_tables() -> None:
    cfg = load_mavlink_config(EXAMPLE)
    assert cfg.autopilot == EndpointConfig("/dev/ttyAMA0", 921600, False, "autopilot")
    assert [g.url for g in cfg.gcs] == ["udpin:127.0.0.1:14550", "udpout:127.0.0.1:14551"]
    text = EXAMPLE.read_text()
    live = [line.split("#", 1)[0] for line in text.splitlines()]
    addresses = [w for line in live for w in line.replace('"', " ").split()
                 if w.startswith(("udpin:", "udpout:", "tcp:", "tcpin:"))]
    assert addresses and all(":127.0.0.1:" in a for a in addresses)  # loopback only
    assert (cfg.system_id, cfg.component_id, cfg.pilot_system_id) == (1, 191, 255)
    assert cfg.tlog_max_bytes == 64 * 1024 * 1024 and cfg.stats_hz == 2.0
    bridge = load_vehicle_config(EXAMPLE)
    assert isinstance(bridge, BridgeConfig)
    assert bridge.rover.port.url == "/dev/ttyUSB0" and bridge.rover.detector.window == 12
    RoverPipeline(bridge.rover)  # the rover half builds


def test_defaults_bind_servers_to_localhost() -> None:
    cfg = MavlinkConfig()
    assert cfg.autopilot.url.startswith("udpin:127.0.0.1:")
    assert all(g.url.startswith("udpin:127.0.0.1:") for g in cfg.gcs)


def test_bad_values_name_the_key(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text('[mavlink]\nsystem_id = 300\n')
    with pytest.raises(ConfigError, match=r"mavlink\.system_id"):
        load_mavlink_config(bad)
    bad.write_text('[mavlink]\n[[mavlink.gcs]]\nurl = "udpin:14550"\nsigning = true\n')
    with pytest.raises(ConfigError, match="signing_key_file"):
        load_mavlink_config(bad)
    bad.write_text('[mavlink]\nheartbeat = 1\n')
    with pytest.raises(ConfigError, match=r"mavlink\.heartbeat"):
        load_mavlink_config(bad)
    with pytest.raises(ConfigError, match=r"did you mean 'heartbeat_hz'"):
        load_vehicle_config(bad)  # one loader: the whole file is checked, whichever view
    bad.write_text('[mavlink]\nheartbeat_hz = 1\n')
    assert load_vehicle_config(bad) is None  # no [rover]: the router alone


def test_tlog_rotates_by_size_and_keeps_every_packet(tmp_path: Path) -> None:
    t = [1_700_000_000.0]
    w = TlogWriter(tmp_path, max_bytes=4096, wall_clock=lambda: t[0])
    packets = [bytes([0xFD, 9]) + bytes([i % 256]) * 19 for i in range(600)]  # 21 bytes each
    for p in packets:
        w.write(p)
        t[0] += 0.001
    w.close()
    per_file = 4096 // 29  # whole records: a record never straddles two files
    assert [f.stat().st_size for f in w.files[:-1]] == [per_file * 29] * (len(w.files) - 1)
    assert len(w.files) == -(-600 // per_file)
    data = b"".join(f.read_bytes() for f in w.files)
    recs = [data[i : i + 29] for i in range(0, len(data), 29)]
    assert [r[8:] for r in recs] == packets
    stamps = [int.from_bytes(r[:8], "big") for r in recs]
    assert stamps[0] == 1_700_000_000_000_000 and stamps == sorted(stamps)
