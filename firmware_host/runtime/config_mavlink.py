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

    url: str = field(metadata={
        "url": "mavlink", "doc": "the link, in the mavutil spelling (udpin:HOST:PORT, "
                                 "udpout:HOST:PORT, tcp:HOST:PORT, a serial device)"})
    baud: int = field(default=115200, metadata={
        "gt": 0, "doc": "serial links only", "unit": "baud"})
    signing: bool = field(
        default=False, metadata={"doc": "GCS links: only correctly signed packets pass"}
    )
    name: str = field(default="", metadata={
        "range": "any text",
        "doc": "the endpoint's name in the logs and counters (empty: autopilot, gcs0, ...)"})
    # Unsigned messages a signing link still passes (they command nothing; they teach no route).
    allow_unsigned: tuple[str, ...] = field(default=DEFAULT_ALLOW_UNSIGNED, metadata={
        "doc": "signing links: message names passed unsigned (never teach a route)",
        "range": "MAVLink message names"})
    peer_timeout_s: float = field(default=0.0, metadata={
        "ge": 0.0, "le": 86400.0, "doc": "udpin: forget a peer silent this long; 0 never",
        "unit": "s"})
    accept_any: bool = field(
        default=False, metadata={"doc": "udpout: take datagrams from any sender"}
    )
    # Per-endpoint message filters (names): what it may send us, what we send it.
    block_in: tuple[str, ...] = field(default=(), metadata={
        "range": "MAVLink message names",
        "doc": "messages from this endpoint that are dropped"})
    allow_out: tuple[str, ...] = field(default=(), metadata={
        "range": "MAVLink message names",
        "doc": "only these messages are sent to it (empty: everything not in block_out)"})
    block_out: tuple[str, ...] = field(default=(), metadata={
        "range": "MAVLink message names", "doc": "messages never sent to it"})
    max_out_pps: float = field(default=0.0, metadata={
        "ge": 0.0, "le": 1e6, "doc": "packets/s towards this endpoint; 0 = no cap",
        "unit": "packets/s"})

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
    system_id: int = field(default=1, metadata={
        "ge": 1, "le": 255, "unit": "-", "doc": "the bridge's own MAVLink system id"})
    component_id: int = field(default=191, metadata={
        "ge": 1, "le": 255, "unit": "-", "doc": "the bridge's own MAVLink component id"})
    pilot_system_id: int = field(default=255, metadata={
        "ge": 1, "le": 255, "doc": "GCS id for MANUAL_CONTROL", "unit": "-"})
    heartbeat_hz: float = field(default=1.0, metadata={
        "ge": 0.1, "le": 50.0, "unit": "Hz", "doc": "the bridge's HEARTBEAT rate"})
    stats_hz: float = field(default=2.0, metadata={
        "ge": 0.0, "le": 50.0, "unit": "Hz",
        "doc": "rate of the detector statistics sent as NAMED_VALUE_FLOAT (0: none)"})
    statustext_per_s: float = field(default=5.0, metadata={
        "ge": 0.1, "le": 50.0, "unit": "1/s",
        "doc": "at most this many STATUSTEXT a second (oldest dropped when the queue is full)"})
    queue_packets: int = field(default=2000, metadata={
        "ge": 16, "unit": "packets", "doc": "each destination's queue of packets the kernel did "
                                            "not yet take (oldest dropped when full)"})
    read_burst: int = field(default=64, metadata={
        "ge": 1, "unit": "packets", "doc": "packets read from one endpoint per round (a flood on "
                                           "one link stalls no other)"})
    tlog_dir: str = field(default="", metadata={
        "range": "a directory path, or \"\"",
        "doc": "write a telemetry log (.tlog) of the traffic here; empty: none"})
    tlog_max_bytes: int = field(default=64 * 1024 * 1024, metadata={
        "ge": 4096, "unit": "bytes", "doc": "a new .tlog file beyond this size"})
    tlog_dir_max_bytes: int = field(default=1024 * 1024 * 1024, metadata={
        "ge": 4096, "doc": "oldest .tlog deleted beyond", "unit": "bytes"})
    tlog_min_free_bytes: int = field(default=200 * 1024 * 1024, metadata={
        "ge": 0, "doc": "stop the tlog below this free", "unit": "bytes"})
    param_file: str = field(default="", metadata={
        "range": "a file path, or \"\"",
        "doc": "where parameters set by a ground station are kept across starts (TOML); empty: "
               "they last until the bridge stops"})
    signing_key_file: str = field(default="", metadata={
        "range": "a file path, or \"\"",
        "doc": "the MAVLink 2 signing key; needed when a GCS link has signing = true"})
    signing_state_file: str = field(default="", metadata={
        "doc": "last signing timestamps; default <signing_key_file>.state",
        "range": "a file path, or \"\""})
    command_retries: int = field(default=5, metadata={
        "ge": 1, "le": 20, "unit": "attempts",
        "doc": "a COMMAND_LONG without COMMAND_ACK is sent this many times"})
    command_retry_s: float = field(default=1.0, metadata={
        "ge": 0.05, "le": 60.0, "unit": "s",
        "doc": "wait this long for a COMMAND_ACK before sending again"})
    report_stats_s: float = field(default=0.0, metadata={
        "ge": 0.0, "le": 86400.0, "doc": "log the counters this often; 0 = off", "unit": "s"})
    reconnect_max_s: float = field(default=5.0, metadata={
        "ge": 0.1, "le": 3600.0, "doc": "serial links: longest wait between reopens", "unit": "s"})
    route_timeout_s: float = field(default=10.0, metadata={
        "ge": 0.0, "le": 3600.0, "doc": "forget a (system, component) route silent this long, s; "
                                        "0 = never", "unit": "s"})

    def __post_init__(self) -> None:
        if any(g.signing for g in self.gcs) and not self.signing_key_file:
            raise ValueError("signing is on for a GCS link but signing_key_file is empty")
