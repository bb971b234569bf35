"""The one MAVLink output of a vehicle: a typed :class:`MavlinkOutput`, built in one place.

What the rover and the ROV send to an autopilot or a ground station -- GPS_INPUT, STATUSTEXT,
the heartbeat, the mode command (HOLD), NAMED_VALUE_FLOAT statistics, MANUAL_CONTROL (with a
pilot's extension fields: :class:`~drivers.mavlink.io.ManualControlExt`) -- goes through a
:class:`MavlinkOutput`. There are two kinds, and one factory each:

* :func:`open_mavlink_output` (a URL): ``udpout:``/``udpin:``/``tcp:`` through a pymavlink
  connection, a serial device through a :class:`~drivers.resilient.ResilientPort` (a lost
  autopilot port is reported once and reopened with backoff; what is sent meanwhile is dropped
  and counted). ``run``, ``replay`` and the soak use it; ``tap`` sees every packet sent (the
  flight recorder's ``mavlink tx`` channel).
* :func:`router_output` (a :class:`RouterPort`, the runtime's view of
  :class:`firmware_host.mavlink.router.Router`): the packets go through the router's
  thread-safe, non-blocking API; the router's own component sends the heartbeat and paces
  STATUSTEXT and NAMED_VALUE_FLOAT.

The runtime knows the router only as :class:`RouterPort`: the router (a layer above) is built
by whoever starts a run (``open_router`` handed to the
:class:`~firmware_host.runtime.runner.Runner`), so a replay never imports it.

An output never raises on a send: a transport error is counted (``send_errors``) and logged
rate-limited, so an unplugged autopilot never stops the detectors or the failsafes.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from typing import Any, Protocol

from drivers.mavlink import io as mio
from drivers.mavlink.framer import MavFrame
from drivers.mavlink.io import GpsInputFix, ManualControlExt, MavEndpoint, MavPacker, PortEndpoint
from drivers.mavlink.links import is_network_url
from drivers.ratelog import RateLimitedLog
from drivers.resilient import Opener, ResilientPort
from drivers.transport import SerialSettings, open_port_nonblocking
from fdi.errors import FdiBridgeError
from firmware_host.runtime.config_mavlink import MavlinkConfig

log = logging.getLogger("fdi_bridge.mavout")

Tap = Callable[[bytes], None]

# The severities a vehicle uses (MAV_SEVERITY of the MAVLink common set).
SEVERITY_ALERT = mio.MAV_SEVERITY_ALERT
SEVERITY_CRITICAL = mio.MAV_SEVERITY_CRITICAL
SEVERITY_WARNING = mio.MAV_SEVERITY_WARNING
SEVERITY_NOTICE = mio.MAV_SEVERITY_NOTICE
SEVERITY_INFO = mio.MAV_SEVERITY_INFO


class MavlinkOutput(Protocol):
    """What a vehicle sends over MAVLink (see the module docstring). Sends never raise."""

    def send_heartbeat(self) -> None: ...

    def send_statustext(self, severity: int, text: str) -> None: ...

    def request_mode(self, target_system: int, mode: str, vehicle: str = "rover") -> None: ...

    def send_gps_input(self, fix: GpsInputFix) -> None: ...

    def send_named_value(self, name: str, value: float) -> None: ...

    def send_manual_control(
        self, target_system: int, x: int, y: int, z: int, r: int, buttons: int = 0,
        ext: ManualControlExt | None = None,
    ) -> None: ...

    def counters(self) -> dict[str, int]: ...

    def close(self) -> None: ...


class EncoderOutput:
    """A :class:`MavlinkOutput` over the encoders of :mod:`drivers.mavlink.io`.

    ``encoder`` is a :class:`~drivers.mavlink.io.MavEndpoint` (network), a
    :class:`~drivers.mavlink.io.PortEndpoint` (serial) or a :class:`~drivers.mavlink.io.MavPacker`
    (encoded, recorded, not sent: the soak's autopilot). ``port`` is the serial line's
    :class:`ResilientPort` when there is one (its counters go to the summary).
    """

    def __init__(
        self,
        encoder: MavPacker | MavEndpoint,
        *,
        url: str = "",
        tap: Tap | None = None,
        port: ResilientPort | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.encoder = encoder
        self.url = url
        self.tap = tap
        self.port = port
        self.clock = clock
        self._t0 = clock()
        self.packets = 0
        self.send_errors = 0
        self._ratelog = RateLimitedLog(log)

    def _sent(self, send: Callable[[], bytes]) -> None:
        try:
            data = send()
        except FdiBridgeError as err:  # PortError: a UDP peer refusing, a socket gone
            self.send_errors += 1
            self._ratelog.warning(f"mavlink output {self.url}", str(err))
            return
        self.packets += 1
        if self.tap is not None and data:
            self.tap(bytes(data))

    def send_heartbeat(self) -> None:
        self._sent(self.encoder.send_heartbeat)

    def send_statustext(self, severity: int, text: str) -> None:
        self._sent(lambda: self.encoder.send_statustext(severity, text))

    def request_mode(self, target_system: int, mode: str, vehicle: str = "rover") -> None:
        self._sent(lambda: self.encoder.request_mode(target_system, mode, vehicle))

    def send_gps_input(self, fix: GpsInputFix) -> None:
        self._sent(lambda: self.encoder.send_gps_input(fix))

    def send_named_value(self, name: str, value: float) -> None:
        t_ms = int((self.clock() - self._t0) * 1000)
        self._sent(lambda: self.encoder.send_named_value_float(name, value, t_ms))

    def send_manual_control(
        self, target_system: int, x: int, y: int, z: int, r: int, buttons: int = 0,
        ext: ManualControlExt | None = None,
    ) -> None:
        self._sent(lambda: self.encoder.send_manual_control(target_system, x, y, z, r, buttons,
                                                            ext))

    @property
    def command_stats(self) -> dict[str, int] | None:
        """The encoder's command acknowledgement counters, when it keeps them."""
        stats = getattr(self.encoder, "command_stats", None)
        return stats if isinstance(stats, dict) else None

    def counters(self) -> dict[str, int]:
        out = {"packets": self.packets, "send_errors": self.send_errors}
        if self.port is not None:
            out.update(self.port.counters())
        if isinstance(self.encoder, PortEndpoint):
            out["partial_bytes"] = self.encoder.partial_bytes
        return out

    def close(self) -> None:
        if isinstance(self.encoder, MavEndpoint | PortEndpoint):
            self.encoder.close()


class RouterPort(Protocol):
    """What the runtime and the vehicles use of the MAVLink router
    (:class:`firmware_host.mavlink.router.Router` implements it): its life (``start``,
    ``close``, ``summary``), the bridge's own messages through its non-blocking API, and the
    autopilot's and ground stations' frames (``listen``, ``intercept``)."""

    @property
    def cfg(self) -> MavlinkConfig: ...

    def start(self) -> object: ...

    def close(self) -> None: ...

    def summary(self) -> dict[str, Any]: ...

    def send_gps_input(self, fix: GpsInputFix) -> bytes: ...

    def send_manual_control(
        self, x: int, y: int, z: int, r: int, buttons: int = 0, target_system: int | None = None,
        ext: ManualControlExt | None = None,
    ) -> bytes: ...

    def send_rc_channels_override(self, channels: tuple[int, ...],
                                  target_system: int | None = None) -> bytes: ...

    def request_mode(
        self, mode: str, vehicle: str = "rover", target_system: int | None = None
    ) -> bytes: ...

    def post_statustext(self, severity: int, text: str) -> None: ...

    def set_named_value(self, name: str, value: float) -> None: ...

    def listen(self, message: str, callback: Callable[[MavFrame], None]) -> None: ...

    def intercept(self, message: str, callback: Callable[[MavFrame], bool]) -> None: ...


class RouterOutput:
    """A :class:`MavlinkOutput` through a :class:`RouterPort` (its owner closes the router)."""

    def __init__(self, router: RouterPort) -> None:
        self.router = router
        self.packets = 0

    def send_heartbeat(self) -> None:
        """Nothing: the router's component sends its heartbeat at ``heartbeat_hz``."""

    def send_statustext(self, severity: int, text: str) -> None:
        self.packets += 1
        self.router.post_statustext(severity, text)

    def request_mode(self, target_system: int, mode: str, vehicle: str = "rover") -> None:
        self.packets += 1
        self.router.request_mode(mode, vehicle, target_system=target_system)

    def send_gps_input(self, fix: GpsInputFix) -> None:
        self.packets += 1
        self.router.send_gps_input(fix)

    def send_named_value(self, name: str, value: float) -> None:
        self.router.set_named_value(name, value)  # sent at the router's stats_hz

    def send_manual_control(
        self, target_system: int, x: int, y: int, z: int, r: int, buttons: int = 0,
        ext: ManualControlExt | None = None,
    ) -> None:
        self.packets += 1
        self.router.send_manual_control(x, y, z, r, buttons, target_system=target_system,
                                        ext=ext)

    def counters(self) -> dict[str, int]:
        return {"packets": self.packets}

    def close(self) -> None:
        """Nothing: the router belongs to whoever made it."""


def open_mavlink_output(
    url: str,
    *,
    source_system: int = 1,
    source_component: int = 191,
    baudrate: int = 57600,
    backoff_max_s: float = 5.0,
    clock: Callable[[], float] = time.monotonic,
    opener: Opener = open_port_nonblocking,
    tap: Tap | None = None,
) -> EncoderOutput:
    """The output for ``url``: a network URL through pymavlink, a serial device through a
    non-blocking :class:`ResilientPort` (reopened when the autopilot reboots)."""
    if is_network_url(url):
        ep = MavEndpoint(url, source_system=source_system, source_component=source_component)
        return EncoderOutput(ep, url=url, tap=tap, clock=clock)
    port = ResilientPort(SerialSettings(url=url, baudrate=baudrate, timeout_s=0.0),
                         name="mavlink out", backoff_max_s=backoff_max_s, clock=clock,
                         opener=opener)
    pe = PortEndpoint(port, source_system=source_system, source_component=source_component)
    return EncoderOutput(pe, url=url, tap=tap, port=port, clock=clock)


def packer_output(source_system: int = 1, source_component: int = 191, *,
                  tap: Tap | None = None,
                  clock: Callable[[], float] = time.monotonic) -> EncoderOutput:
    """Packets encoded (and tapped) but sent nowhere: the soak's simulated autopilot link."""
    return EncoderOutput(MavPacker(source_system, source_component), url="packer", tap=tap,
                         clock=clock)


def router_output(router: RouterPort) -> RouterOutput:
    return RouterOutput(router)
