"""Schema of the ``[mavlink]`` table: the router's links and its own component.

Schema only (frozen dataclasses, loaded by :func:`firmware_host.runtime.config.load_bridge_file`);
the router that uses it is :mod:`firmware_host.mavlink.router`.
"""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True)
class EndpointConfig:
    """One link: ``url`` in the mavutil spelling (see :mod:`drivers.mavlink.links`)."""

    url: str
    baud: int = field(default=115200, metadata={"gt": 0, "doc": "serial links only"})
    signing: bool = field(default=False, metadata={"doc": "require signed commands (GCS only)"})
    name: str = ""


@dataclass(frozen=True)
class MavlinkConfig:
    """The ``[mavlink]`` table of a vehicle's TOML file."""

    autopilot: EndpointConfig = EndpointConfig("udpin:127.0.0.1:14555")
    gcs: tuple[EndpointConfig, ...] = (EndpointConfig("udpin:127.0.0.1:14550"),)
    system_id: int = field(default=1, metadata={"ge": 1, "le": 255})
    component_id: int = field(default=191, metadata={"ge": 1, "le": 255})
    pilot_system_id: int = field(
        default=255, metadata={"ge": 1, "le": 255, "doc": "GCS id for MANUAL_CONTROL"}
    )
    heartbeat_hz: float = field(default=1.0, metadata={"gt": 0.0, "le": 50.0})
    stats_hz: float = field(default=2.0, metadata={"ge": 0.0, "le": 50.0})
    statustext_per_s: float = field(default=5.0, metadata={"gt": 0.0, "le": 50.0})
    queue_packets: int = field(default=2000, metadata={"ge": 16})
    read_burst: int = field(default=64, metadata={"ge": 1})
    tlog_dir: str = ""
    tlog_max_bytes: int = field(default=64 * 1024 * 1024, metadata={"ge": 4096})
    param_file: str = ""
    signing_key_file: str = ""
    reconnect_max_s: float = field(
        default=5.0, metadata={"gt": 0.0, "doc": "serial links: longest wait between reopens"}
    )

    def __post_init__(self) -> None:
        if any(g.signing for g in self.gcs) and not self.signing_key_file:
            raise ValueError("signing is on for a GCS link but signing_key_file is empty")
