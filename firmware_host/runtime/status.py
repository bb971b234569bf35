"""What a running bridge says about itself: the start banner and the live status.

The :class:`~firmware_host.runtime.runner.Runner` does not print (library code): it hands a
:class:`StatusSink` (given by the command) a :class:`Banner` once the ports and outputs are
open, and a :class:`Snapshot` every ``status_period_s`` while it runs. The command decides how
they look (``firmware_host.commands.live``: one refreshing line on a terminal, as ``gpsmon`` and
MAVProxy show theirs, a log line once a minute for the journal otherwise).

The texts are the command's (``firmware_host.commands.live``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol


@dataclass(frozen=True)
class PortInfo:
    """A port as the banner names it."""

    name: str
    url: str
    baudrate: int


@dataclass(frozen=True)
class Banner:
    """What the runner opened: the vehicle, its ports, its outputs, the recorder, the router."""

    vehicle: str
    ports: tuple[PortInfo, ...] = ()
    outputs: tuple[str, ...] = ()
    recorder: str | None = None
    router: tuple[str, ...] = ()
    out_dir: str | None = None
    duration_s: float | None = None


@dataclass(frozen=True)
class PortStatus:
    """One port now: up or waiting (and since when), bytes per second both ways."""

    name: str
    up: bool
    rx_bps: float
    tx_bps: float
    down_s: float | None = None
    losses: int = 0


@dataclass(frozen=True)
class AutopilotView:
    """The autopilot at the other end of the MAVLink output now
    (:mod:`firmware_host.runtime.autopilot_echo`): its HEARTBEAT's age (None: none heard), its
    last GPS_RAW_INT (its own view of the fix we sent: fix type, satellites; None: none heard)
    and that message's age (s)."""

    heartbeat_age_s: float | None
    gps_fix_type: int | None = None
    gps_sats: int | None = None
    gps_age_s: float | None = None


@dataclass(frozen=True)
class Snapshot:
    """The live status (one line): counters since the start, port states, the last record's
    age (the last fix, for the rover)."""

    elapsed_s: float
    epochs: int
    faults: int | None = None
    alarms: int | None = None
    ports: tuple[PortStatus, ...] = ()
    last_record_age_s: float | None = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    # The vehicle's state in words, after the ports (the rover: its fix, its output, its
    # receiver's sentences), one section each.
    detail: tuple[str, ...] = ()
    # With a MAVLink output that reads: whether the autopilot is there and its echo of our fix.
    autopilot: AutopilotView | None = None


class StatusSink(Protocol):
    """Where the runner's banner and live status go (the command's view)."""

    def banner(self, banner: Banner) -> None: ...

    def update(self, snapshot: Snapshot) -> None: ...
