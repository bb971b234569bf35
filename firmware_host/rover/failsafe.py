"""The rover's failsafe: what the bridge tells the autopilot when the receiver goes silent.

:class:`RoverFailsafe` (an epoch sink of the rover pipeline plus a ``check()`` for the loop):
when the receiver has been silent (no epoch with a valid fix) for ``rover.silence_s`` it tells
the autopilot: a STATUSTEXT (critical) and a **no-fix GPS_INPUT**, repeated every ``repeat_s``
with a heartbeat while the silence lasts, so the autopilot's EKF stops using the MAVLink GPS at
once instead of waiting for its own timeout; when a valid fix comes back, a STATUSTEXT (notice)
and the pipeline's normal GPS_INPUT stream resumes. The silence itself is a
:class:`~firmware_host.runtime.failsafe.SilenceWatchdog`.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable

from drivers.mavlink.io import GpsInputFix
from firmware_host.rover.outputs import gps_week_ms, unix_time
from firmware_host.rover.pipeline import EpochOutcome
from firmware_host.runtime.config import RoverConfig
from firmware_host.runtime.failsafe import SilenceWatchdog
from firmware_host.runtime.mavout import SEVERITY_CRITICAL, SEVERITY_NOTICE, MavlinkOutput

log = logging.getLogger("fdi_bridge.failsafe")


class RoverFailsafe:
    """No-fix GPS_INPUT + STATUSTEXT after ``silence_s`` without a valid fix (see module doc).

    ``endpoint`` is the vehicle's :class:`~firmware_host.runtime.mavout.MavlinkOutput`; None
    logs only.
    """

    def __init__(
        self,
        cfg: RoverConfig,
        endpoint: MavlinkOutput | None = None,
        *,
        clock: Callable[[], float] = time.monotonic,
        repeat_s: float = 1.0,
    ) -> None:
        self.cfg = cfg
        self.endpoint = endpoint
        self.clock = clock
        self.repeat_s = repeat_s
        self.watchdog = SilenceWatchdog(cfg.silence_s, clock)
        self._next_repeat = 0.0
        self._last_unix: float | None = None  # fix time of the last valid epoch (UTC, s)
        self._last_valid_t = clock()
        self.no_fix_sent = 0
        self.statustexts = 0

    # An EpochSink: every epoch the pipeline processes.
    def emit(self, out: EpochOutcome) -> None:
        e = out.epoch
        if not e.valid:
            return
        if e.date is not None and e.utc_s is not None:
            self._last_unix = unix_time(e.date, e.utc_s)
        self._last_valid_t = self.clock()
        if self.watchdog.valid() == "back":
            log.warning("GPS: valid fixes again; GPS_INPUT resumes")
            self._statustext(SEVERITY_NOTICE, "FDI GPS: data back, fixes valid again")

    def close(self) -> None:
        """The endpoint belongs to the MAVLink sink, which closes it."""

    def check(self) -> None:
        """Call every loop iteration."""
        now = self.clock()
        if self.watchdog.check() == "silent":
            log.warning("GPS: no valid fix for %.1f s; sending no-fix to the autopilot",
                        self.cfg.silence_s)
            self._statustext(SEVERITY_CRITICAL,
                             f"FDI GPS: no valid data for {self.cfg.silence_s:g} s, no fix")
            self._next_repeat = now
        if self.watchdog.silent and now >= self._next_repeat:
            self._send_no_fix(now)
            self._next_repeat = now + self.repeat_s

    @property
    def silent(self) -> bool:
        return self.watchdog.silent

    def _statustext(self, severity: int, text: str) -> None:
        self.statustexts += 1
        if self.endpoint is not None:
            self.endpoint.send_statustext(severity, text)

    def _send_no_fix(self, now: float) -> None:
        if self.endpoint is None:
            return
        week = ms = 0
        time_usec = 0
        if self._last_unix is not None:
            unix_s = self._last_unix + (now - self._last_valid_t)
            week, ms = gps_week_ms(unix_s)
            time_usec = round(unix_s * 1e6)
        fix = GpsInputFix(
            time_usec=time_usec, gps_week=week, gps_week_ms=ms, fix_type=1,
            lat_deg=0.0, lon_deg=0.0, alt_m=0.0, hdop=99.99, vdop=None,
            vn_mps=None, ve_mps=None, vd_mps=None, speed_accuracy_mps=99.0,
            horiz_accuracy_m=9999.0, vert_accuracy_m=9999.0, satellites_visible=0,
            gps_id=self.cfg.output.gps_id,  # the same GPS instance as the fixes (GPS2: 1)
        )
        self.endpoint.send_heartbeat()
        self.endpoint.send_gps_input(fix)
        self.no_fix_sent += 1
