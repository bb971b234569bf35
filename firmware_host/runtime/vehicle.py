"""What a vehicle is to the runtime: the :class:`Vehicle` protocol and what the runner hands it.

A vehicle (the rover, the ROV on the Outland link, the ROV through an ArduSub autopilot, a live
INS/GNSS) says

* which ports it needs (:class:`PortSpec`: URL and line settings, the reopen backoff cap, which
  directions the flight recorder keeps), without a router where its own MAVLink output goes
  (:class:`MavlinkSpec`), and its other outputs as the start banner names them (``outputs``);
* how it is paced: ``"period"`` (a fixed-rate step every ``period_s`` on absolute deadlines,
  the ROV at 5 Hz) or ``"data"`` (a step whenever input arrives, the rover by its receiver's
  epochs; ``step`` blocks at most the port's timeout);
* how its inputs become typed records and outputs (``step``), what it does when its input
  goes silent (``check``, run every iteration: its own failsafe, on the
  :class:`~firmware_host.runtime.failsafe.SilenceWatchdog`), what it does at shutdown
  (``finish``: records completed, nothing stale sent) and its summary.

Everything else -- signals, ``--duration``, the clock, opening and reopening the ports, the
recorder's taps, ``epochs.jsonl`` and ``summary.json``, the MAVLink router -- is the
:class:`~firmware_host.runtime.runner.Runner`'s, once, for every vehicle. The runtime knows the
vehicles only by this protocol and the router only as
:class:`~firmware_host.runtime.mavout.RouterPort` (``Context.router``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Literal, Protocol

from drivers.resilient import Opener, ResilientPort
from drivers.transport import SerialSettings, open_port
from firmware_host.runtime.mavout import MavlinkOutput, RouterPort
from firmware_host.runtime.records import EpochLog

Pacing = Literal["period", "data"]
Clock = Callable[[], float]
Tap = Callable[[bytes], None]


@dataclass(frozen=True)
class PortSpec:
    """A port the vehicle reads (and maybe writes). ``name`` names it in the log and, with
    ``rx``/``tx``, the recorder's channels (``"gps rx"``, ``"rov link tx"``)."""

    name: str
    settings: SerialSettings
    backoff_max_s: float = 5.0
    record_rx: bool = True
    record_tx: bool = False
    opener: Opener = field(default=open_port, compare=False)


@dataclass(frozen=True)
class MavlinkSpec:
    """The vehicle's own MAVLink output when no ``[mavlink]`` router is attached."""

    url: str
    baudrate: int = 57600
    source_system: int = 1
    source_component: int = 191
    backoff_max_s: float = 5.0


@dataclass
class Context:
    """What the runner hands a vehicle at :meth:`Vehicle.start`."""

    clock: Clock
    ports: dict[str, ResilientPort]
    epochs: EpochLog
    mavlink: MavlinkOutput | None = None
    router: RouterPort | None = None
    tap: Callable[[str, str, int, Literal["rx", "tx"]], Tap | None] = (
        lambda name, url, baud, direction: None)
    """A recorder tap for an output the vehicle opens itself (``tap("nmea tx", url, baud,
    "tx")``); None without a recorder."""


class Vehicle(Protocol):
    """See the module docstring."""

    @property
    def name(self) -> str:
        """``rover``, ``rov``, ``rov-ardusub`` (the summary's ``vehicle``)."""
        ...

    @property
    def pacing(self) -> Pacing: ...

    @property
    def period_s(self) -> float:
        """"period": the step period; "data": the longest wait while a port is down."""
        ...

    def ports(self) -> list[PortSpec]: ...

    def mavlink(self) -> MavlinkSpec | None: ...

    def outputs(self) -> tuple[str, ...]:
        """The vehicle's own outputs besides MAVLink, as the start banner names them
        (``("NMEA pty:/tmp/gps",)``); empty when it has none."""
        ...

    def status_fields(self) -> dict[str, Any]:
        """Counters the status line adds after the epochs, faults and alarms (the
        :class:`~firmware_host.runtime.status.Snapshot`'s ``extra``); empty for none."""
        ...

    def status_detail(self) -> tuple[str, ...]:
        """Compact items the status line shows after the ports (the Snapshot's ``detail``,
        the rover's last fix and what was sent); empty for none."""
        ...

    def start(self, ctx: Context) -> None: ...

    def step(self, t: float) -> int:
        """One step at ``t`` (the deadline for "period", the clock for "data"); returns how
        many records it produced."""
        ...

    def check(self, now: float) -> None:
        """Silence watchdogs and failsafes; every iteration of the loop."""
        ...

    def idle_s(self) -> float:
        """"data" pacing: how long the runner may wait before the next step because nothing
        can block in ``step`` (its port is down); 0 when ``step`` waits for input itself."""
        ...

    def finish(self) -> None:
        """Shutdown: complete the records; send nothing older than what was sent before."""
        ...

    def summary(self) -> dict[str, Any]: ...
