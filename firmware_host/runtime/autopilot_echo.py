"""Whether the autopilot is there, and what it made of the fix we sent (the status line).

mavlink-routerd's statistics say whether a link is alive; cgps says what the receiver reports.
The bridge's operator wants both of the autopilot at the other end of the MAVLink output: its
HEARTBEAT's age (is it there) and its GPS_RAW_INT (its own view of the GPS it was given: fix
type and satellites, the echo of our GPS_INPUT when ``GPS1_TYPE = 14``).

:class:`AutopilotEcho` keeps the last of each, fed by whichever output the vehicle has
(:func:`attach`):

* the router (``[mavlink]``): :meth:`Router.listen
  <firmware_host.mavlink.router.Router.listen>` on the autopilot link, in the router's thread:
  only the arrival time and the raw packet are kept there, decoded at :meth:`view` (the
  caller's thread; the decoder is not shared between threads);
* a network URL (``udpout:``/``udpin:``/``tcp:``): the pymavlink connection's incoming
  messages, read without blocking at each :meth:`view`
  (:meth:`~drivers.mavlink.io.MavEndpoint.drain`, which still hands a pending mode command its
  COMMAND_ACK);
* a serial line: the bytes the autopilot sends back, framed (:class:`MavFramer`) at each
  :meth:`view`.

Heartbeats of ground stations and onboard controllers on the same link are not the autopilot's.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from drivers.mavlink import io as mio
from drivers.mavlink.framer import MavFrame, MavFramer
from drivers.mavlink.io import MavEndpoint, PortEndpoint
from firmware_host.runtime.status import AutopilotView

if TYPE_CHECKING:
    from firmware_host.runtime.mavout import RouterPort

HEARTBEAT_ID = mio.message_id("HEARTBEAT")
GPS_RAW_INT_ID = mio.message_id("GPS_RAW_INT")
_NOT_AUTOPILOT = (mio.MAV_TYPE_GCS, mio.MAV_TYPE_ONBOARD_CONTROLLER)


class AutopilotEcho:
    """The last HEARTBEAT and GPS_RAW_INT from the autopilot (module docstring)."""

    def __init__(self, clock: Callable[[], float] = time.monotonic) -> None:
        self.clock = clock
        self._hb_t: float | None = None
        self._gps: tuple[int, int] | None = None
        self._gps_t: float | None = None
        self._gps_raw: tuple[bytes, float] | None = None  # from the router's thread
        self._poll: Callable[[], None] | None = None

    # -- the router's thread: times and raw bytes only
    def on_frame(self, frame: MavFrame) -> None:
        if frame.msgid == HEARTBEAT_ID:
            at = frame.header_len + 4  # HEARTBEAT's payload: custom_mode u32, then type u8
            if len(frame.raw) > at and frame.raw[at] in _NOT_AUTOPILOT:
                return
            self._hb_t = self.clock()
        elif frame.msgid == GPS_RAW_INT_ID:
            self._gps_raw = (frame.raw, self.clock())

    # -- a decoded message (the caller's thread)
    def on_message(self, msg: Any, at: float | None = None) -> None:
        kind = msg.get_type()
        t = self.clock() if at is None else at
        if kind == "HEARTBEAT":
            if int(msg.type) not in _NOT_AUTOPILOT:
                self._hb_t = t
        elif kind == "GPS_RAW_INT":
            self._gps = (int(msg.fix_type), int(msg.satellites_visible))
            self._gps_t = t

    def view(self, now: float | None = None) -> AutopilotView:
        """What has arrived, read now (see the module docstring), as an :class:`AutopilotView`."""
        if self._poll is not None:
            self._poll()
        raw, self._gps_raw = self._gps_raw, None
        if raw is not None:
            msg = mio.decode_packet(raw[0])
            if msg is not None:
                self.on_message(msg, raw[1])
        now = self.clock() if now is None else now
        return AutopilotView(
            heartbeat_age_s=None if self._hb_t is None else max(0.0, now - self._hb_t),
            gps_fix_type=None if self._gps is None else self._gps[0],
            gps_sats=None if self._gps is None else self._gps[1],
            gps_age_s=None if self._gps_t is None else max(0.0, now - self._gps_t))


def attach(output: Any, router: RouterPort | None,
           clock: Callable[[], float] = time.monotonic) -> AutopilotEcho | None:
    """An :class:`AutopilotEcho` on the vehicle's MAVLink output: the router when there is
    one, else the output's endpoint (a network URL or a serial line); None without a MAVLink
    output that reads (the soak's encoder)."""
    echo = AutopilotEcho(clock)
    if router is not None:
        router.listen("HEARTBEAT", echo.on_frame)
        router.listen("GPS_RAW_INT", echo.on_frame)
        return echo
    encoder = getattr(output, "encoder", None)
    if isinstance(encoder, MavEndpoint):
        endpoint = encoder
        endpoint.on_message = echo.on_message

        def drain() -> None:
            endpoint.drain()

        echo._poll = drain
        return echo
    if isinstance(encoder, PortEndpoint):
        framer = MavFramer()
        port = encoder.port

        def poll() -> None:
            for _ in range(64):
                try:
                    data = port.read_some()
                except Exception:  # a lost port is the output's to report
                    return
                if not data:
                    return
                for frame in framer.feed(data):
                    if frame.msgid in (HEARTBEAT_ID, GPS_RAW_INT_ID):
                        msg = mio.decode_packet(frame.raw)
                        if msg is not None:
                            echo.on_message(msg)

        echo._poll = poll
        return echo
    return None
