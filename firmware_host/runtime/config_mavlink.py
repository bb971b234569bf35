"""Schema of the ``[mavlink]`` table: the router's links and its own component.

Schema only (frozen dataclasses, loaded by :func:`firmware_host.runtime.config.load_bridge_file`);
the router that uses it is :mod:`firmware_host.mavlink.router`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from drivers.mavlink import io as mio

# The default unsigned pass-list of a signing link: ArduPilot's own (a telemetry radio's link
# statistics, which the radio cannot sign). Names of the dialect (checked by a test, not at each
# import, so that loading a file without [mavlink] does not import pymavlink). HEARTBEAT is not
# in it: an unsigned heartbeat from anyone on the network would hold off the autopilot's GCS
# failsafe.
DEFAULT_ALLOW_UNSIGNED = ("RADIO_STATUS", "RADIO")


@dataclass(frozen=True)
class EndpointConfig:
    """One link: ``url`` in the mavutil spelling (see :mod:`drivers.mavlink.links`)."""

    url: str = field(metadata={"url": "mavlink"})
    baud: int = field(default=115200, metadata={"gt": 0, "doc": "serial links only"})
    signing: bool = field(
        default=False, metadata={"doc": "GCS links: only correctly signed packets pass"}
    )
    name: str = ""
    # Unsigned messages a signing link still passes (they command nothing; they teach no route).
    allow_unsigned: tuple[str, ...] = field(
        default=DEFAULT_ALLOW_UNSIGNED,
        metadata={"doc": "signing links: message names passed unsigned (never teach a route)"})
    peer_timeout_s: float = field(
        default=0.0, metadata={"ge": 0.0, "le": 86400.0,
                                "doc": "udpin: forget a peer silent this long; 0 never"}
    )
    accept_any: bool = field(
        default=False, metadata={"doc": "udpout: take datagrams from any sender"}
    )
    # Per-endpoint message filters (names): what it may send us, what we send it.
    block_in: tuple[str, ...] = ()
    allow_out: tuple[str, ...] = ()  # empty: everything not in block_out
    block_out: tuple[str, ...] = ()
    max_out_pps: float = field(
        default=0.0, metadata={"ge": 0.0, "le": 1e6,
                                "doc": "packets/s towards this endpoint; 0 = no cap"}
    )

    def __post_init__(self) -> None:
        for key in ("allow_unsigned", "block_in", "allow_out", "block_out"):
            names = getattr(self, key)
            if names == DEFAULT_ALLOW_UNSIGNED:
                continue
            for name in names:
                try:
                    mio.message_id(name)
                except (KeyError, AttributeError):
                    raise ValueError(f"{key}: {name!r} is not a message of the "
                                     f"{mio.DIALECT} dialect") from None

    def ids(self, key: str) -> frozenset[int]:
        return frozenset(mio.message_id(n) for n in getattr(self, key))


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
    heartbeat_hz: float = field(default=1.0, metadata={"ge": 0.1, "le": 50.0})
    stats_hz: float = field(default=2.0, metadata={"ge": 0.0, "le": 50.0})
    statustext_per_s: float = field(default=5.0, metadata={"ge": 0.1, "le": 50.0})
    queue_packets: int = field(default=2000, metadata={"ge": 16})
    read_burst: int = field(default=64, metadata={"ge": 1})
    tlog_dir: str = ""
    tlog_max_bytes: int = field(default=64 * 1024 * 1024, metadata={"ge": 4096})
    tlog_dir_max_bytes: int = field(
        default=1024 * 1024 * 1024, metadata={"ge": 4096, "doc": "oldest .tlog deleted beyond"}
    )
    tlog_min_free_bytes: int = field(
        default=200 * 1024 * 1024, metadata={"ge": 0, "doc": "stop the tlog below this free"}
    )
    param_file: str = ""
    signing_key_file: str = ""
    signing_state_file: str = field(
        default="", metadata={"doc": "last signing timestamps; default <signing_key_file>.state"}
    )
    command_retries: int = field(default=5, metadata={"ge": 1, "le": 20})
    command_retry_s: float = field(default=1.0, metadata={"ge": 0.05, "le": 60.0})
    report_stats_s: float = field(
        default=0.0,
        metadata={"ge": 0.0, "le": 86400.0, "doc": "log the counters this often; 0 = off"}
    )
    reconnect_max_s: float = field(
        default=5.0, metadata={"ge": 0.1, "le": 3600.0,
                                "doc": "serial links: longest wait between reopens"}
    )
    route_timeout_s: float = field(
        default=10.0, metadata={"ge": 0.0, "le": 3600.0,
                                 "doc": "forget a (system, component) route silent "
                                        "this long, s; 0 = never"})

    def __post_init__(self) -> None:
        if any(g.signing for g in self.gcs) and not self.signing_key_file:
            raise ValueError("signing is on for a GCS link but signing_key_file is empty")
