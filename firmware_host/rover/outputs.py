"""Where the rover's corrected fixes go: an NMEA port (or pty) and a MAVLink GPS_INPUT stream.

* :class:`NmeaSink` writes GGA, RMC and VTG with valid checksums per epoch, so any NMEA consumer
  (an autosteer unit, gpsd) gets corrected data. A replaced fix is sent with GGA quality 6
  ("estimated") and RMC/VTG mode ``E``; an epoch with nothing valid to pass on (alarm, no fix)
  is sent as a no-fix (GGA quality 0, empty position; RMC status ``V``), never as a guess.
* :class:`MavlinkGpsSink` sends GPS_INPUT (for an autopilot set to a MAVLink GPS, ArduPilot
  ``GPS1_TYPE = 14``) with fix type, GPS week and milliseconds, and horizontal/speed accuracy
  raised on replaced fixes; on an alarm it sends STATUSTEXT and asks for HOLD, and says so again
  on recovery; a heartbeat once a second of fix time.
"""

from __future__ import annotations

import calendar
import contextlib
import errno
import math
import os
import time
from collections.abc import Callable
from typing import Any

from drivers.gps.nmea import format_date, format_lat, format_lon, format_time, with_checksum
from drivers.mavlink.io import GpsInputFix
from drivers.ptypair import PtyPair
from drivers.resilient import Opener, ResilientPort
from drivers.transport import SerialSettings, open_port_nonblocking
from firmware_host.rover.pipeline import EpochOutcome
from firmware_host.runtime.config import RoverConfig
from firmware_host.runtime.mavout import MavlinkOutput, open_mavlink_output

KNOT_MPS = 1852.0 / 3600.0
GPS_EPOCH_UNIX = 315964800  # 1980-01-06T00:00:00Z
# (first UTC day it applies, GPS - UTC seconds); IERS Bulletin C.
_LEAPS = [
    (calendar.timegm((1981, 7, 1, 0, 0, 0)), 1),
    (calendar.timegm((1982, 7, 1, 0, 0, 0)), 2),
    (calendar.timegm((1983, 7, 1, 0, 0, 0)), 3),
    (calendar.timegm((1985, 7, 1, 0, 0, 0)), 4),
    (calendar.timegm((1988, 1, 1, 0, 0, 0)), 5),
    (calendar.timegm((1990, 1, 1, 0, 0, 0)), 6),
    (calendar.timegm((1991, 1, 1, 0, 0, 0)), 7),
    (calendar.timegm((1992, 7, 1, 0, 0, 0)), 8),
    (calendar.timegm((1993, 7, 1, 0, 0, 0)), 9),
    (calendar.timegm((1994, 7, 1, 0, 0, 0)), 10),
    (calendar.timegm((1996, 1, 1, 0, 0, 0)), 11),
    (calendar.timegm((1997, 7, 1, 0, 0, 0)), 12),
    (calendar.timegm((1999, 1, 1, 0, 0, 0)), 13),
    (calendar.timegm((2006, 1, 1, 0, 0, 0)), 14),
    (calendar.timegm((2009, 1, 1, 0, 0, 0)), 15),
    (calendar.timegm((2012, 7, 1, 0, 0, 0)), 16),
    (calendar.timegm((2015, 7, 1, 0, 0, 0)), 17),
    (calendar.timegm((2017, 1, 1, 0, 0, 0)), 18),
]


def unix_time(date: tuple[int, int, int], utc_s: float) -> float:
    y, m, d = date
    return calendar.timegm((y, m, d, 0, 0, 0)) + utc_s


def gps_week_ms(unix_s: float) -> tuple[int, int]:
    """UTC (Unix seconds) -> (GPS week, milliseconds of week), leap seconds applied."""
    leap = 0
    for start, value in _LEAPS:
        if unix_s >= start:
            leap = value
    gps_s = unix_s - GPS_EPOCH_UNIX + leap
    week = int(gps_s // 604800)
    ms = round((gps_s - week * 604800) * 1000.0)
    if ms >= 604800000:
        week, ms = week + 1, ms - 604800000
    return week, ms


class _PortWriter:
    """A pyserial URL, or ``pty:PATH`` for a new pty whose slave is linked at PATH.

    Writing never blocks the detectors: when the consumer does not keep up (or nobody has the
    pty open), what does not fit is dropped and counted in ``dropped_bytes``. A URL is a
    :class:`~drivers.resilient.ResilientPort` opened non-blocking: a device that goes away (a
    USB adapter unplugged in the middle of a hardware-in-the-loop replay) is reported once,
    what is written meanwhile is dropped and counted, and the same URL is reopened with backoff.
    ``tap`` sees every byte written (the flight recorder).
    """

    def __init__(self, url: str, baudrate: int, *, clock: Callable[[], float] = time.monotonic,
                 backoff_max_s: float = 5.0, opener: Opener | None = None,
                 tap: Callable[[bytes], None] | None = None) -> None:
        self.pty: PtyPair | None = None
        self.port: ResilientPort | None = None
        self.tap = tap
        self._dropped = 0
        if url.startswith("pty:"):
            self.pty = PtyPair(link=url[4:] or None, baudrate=baudrate)
            os.set_blocking(self.pty.master_fd, False)
        else:
            self.port = ResilientPort(SerialSettings(url=url, baudrate=baudrate, timeout_s=0.0),
                                      name="nmea out", backoff_max_s=backoff_max_s, clock=clock,
                                      opener=opener or open_port_nonblocking, on_tx=tap)

    @property
    def url(self) -> str:
        return self.pty.url if self.pty is not None else str(self.port.port if self.port else "")

    @property
    def dropped_bytes(self) -> int:
        return self._dropped + (self.port.tx_dropped if self.port is not None else 0)

    def write(self, data: bytes) -> None:
        if self.port is not None:
            n = self.port.write(data) or 0
            if self.port.up:  # a partial write on a full line (a loss counts in tx_dropped)
                self._dropped += len(data) - n
            return
        assert self.pty is not None
        with contextlib.suppress(OSError):  # drain what the consumer wrote back (probes)
            os.read(self.pty.master_fd, 4096)
        try:
            n = os.write(self.pty.master_fd, data)
        except OSError as err:
            if err.errno not in (errno.EAGAIN, errno.EIO):
                raise
            n = 0  # nobody reading (EAGAIN) or nobody has the slave open (EIO)
        self._dropped += len(data) - n
        if n and self.tap is not None:
            self.tap(data[:n])

    def close(self) -> None:
        if self.pty is not None:
            self.pty.close()
        if self.port is not None:
            self.port.close()


def encode_nmea(out: EpochOutcome) -> bytes:
    """GGA + RMC + VTG for one epoch's output (see the module docstring)."""
    e = out.epoch
    d = out.decision
    ts = format_time(e.utc_s) if e.utc_s is not None else ""
    date = format_date(e.date) if e.date is not None else ""
    talker = "GP"
    sats = f"{e.num_sats:02d}" if e.num_sats is not None else ""
    hdop = f"{e.hdop:.1f}" if e.hdop is not None else ""
    speed_kn = "" if e.speed_mps is None else f"{e.speed_mps / KNOT_MPS:.3f}"
    speed_kmh = "" if e.speed_mps is None else f"{e.speed_mps * 3.6:.3f}"
    course = "" if e.course_deg is None else f"{e.course_deg:.1f}"
    if out.lat is None or out.lon is None:
        gga = f"{talker}GGA,{ts},,,,,0,{sats},,,M,,M,,"
        rmc = f"{talker}RMC,{ts},V,,,,,,,{date},,,N"
        vtg = f"{talker}VTG,,T,,M,,N,,K,N"
        return with_checksum(gga) + with_checksum(rmc) + with_checksum(vtg)
    la, ns = format_lat(out.lat)
    lo, ew = format_lon(out.lon)
    replaced = d.action != "accept"
    quality = 6 if replaced else e.quality
    mode = "E" if replaced else ("D" if e.quality == 2 else "A")
    alt = "" if out.alt is None else f"{out.alt:.3f}"
    sep = "" if e.geoid_sep_m is None else f"{e.geoid_sep_m:.3f}"
    age = "" if e.dgps_age_s is None or replaced else f"{e.dgps_age_s:.1f}"
    gga = f"{talker}GGA,{ts},{la},{ns},{lo},{ew},{quality},{sats},{hdop},{alt},M,{sep},M,{age},"
    rmc = f"{talker}RMC,{ts},A,{la},{ns},{lo},{ew},{speed_kn},{course},{date},,,{mode}"
    vtg = f"{talker}VTG,{course},T,,M,{speed_kn},N,{speed_kmh},K,{mode}"
    return with_checksum(gga) + with_checksum(rmc) + with_checksum(vtg)


class NmeaSink:
    """EpochSink: corrected NMEA (:func:`encode_nmea`) to a URL or ``pty:PATH`` (see
    :class:`_PortWriter`: never blocks, a lost device is reopened)."""

    def __init__(self, url: str, baudrate: int = 9600, *,
                 clock: Callable[[], float] = time.monotonic, backoff_max_s: float = 5.0,
                 opener: Opener | None = None, tap: Callable[[bytes], None] | None = None
                 ) -> None:
        self.writer = _PortWriter(url, baudrate, clock=clock, backoff_max_s=backoff_max_s,
                                  opener=opener, tap=tap)
        self.bytes_out = 0

    @property
    def url(self) -> str:
        return self.writer.url

    def emit(self, out: EpochOutcome) -> None:
        data = encode_nmea(out)
        self.writer.write(data)
        self.bytes_out += len(data)

    def stats(self) -> dict[str, Any]:
        out: dict[str, Any] = {"bytes_out": self.bytes_out,
                               "dropped_bytes": self.writer.dropped_bytes}
        if self.writer.port is not None:
            out["port"] = self.writer.port.counters()
        return out

    def close(self) -> None:
        self.writer.close()


_FIX_TYPE = {1: 3, 2: 4, 3: 3, 4: 6, 5: 5, 6: 3, 7: 3, 8: 3, 9: 4}


class MavlinkGpsSink:
    """GPS_INPUT per epoch; STATUSTEXT and HOLD on alarm; heartbeat at 1 Hz of fix time."""

    def __init__(self, cfg: RoverConfig, endpoint: MavlinkOutput | None = None) -> None:
        self._fix_cls = GpsInputFix
        o = cfg.output
        self.cfg = cfg
        self.endpoint: MavlinkOutput = endpoint or open_mavlink_output(
            o.mavlink_url, source_system=o.mavlink_system, source_component=o.mavlink_component,
            baudrate=o.mavlink_baudrate, backoff_max_s=cfg.reconnect_max_s)
        self.sent = 0
        self.no_date = 0
        self._next_heartbeat: float | None = None
        self._was_alarm = False

    def emit(self, out: EpochOutcome) -> None:
        e, d = out.epoch, out.decision
        o = self.cfg.output
        due = self._next_heartbeat
        if out.t_s is not None and (due is None or out.t_s >= due):
            self.endpoint.send_heartbeat()
            self._next_heartbeat = math.floor(out.t_s) + 1.0
        if d.alarm_raised:
            self.endpoint.send_statustext(
                2, f"FDI GPS: {self.cfg.detector.max_consecutive}+ faults in a row, auto-nav stop"
            )
            if o.hold_on_alarm:
                self.endpoint.request_mode(o.target_system, "HOLD", o.vehicle)
        elif self._was_alarm and not d.alarm:
            self.endpoint.send_statustext(5, "FDI GPS: fixes consistent again, alarm cleared")
        self._was_alarm = d.alarm
        if e.date is None or e.utc_s is None:
            self.no_date += 1
            return
        unix_s = unix_time(e.date, e.utc_s)
        week, ms = gps_week_ms(unix_s)
        replaced = d.action != "accept"
        if e.sd_lat_m is not None and e.sd_lon_m is not None:
            h_acc = math.hypot(e.sd_lat_m, e.sd_lon_m)
            v_acc = e.sd_alt_m if e.sd_alt_m is not None else 2.0 * h_acc
        else:
            h_acc = self.cfg.detector.sigma_m * math.sqrt(2.0) * max(1.0, e.hdop or 1.0)
            v_acc = self.cfg.detector.sigma_up_m * max(1.0, e.hdop or 1.0)
        s_acc = 0.1
        factor = o.replaced_accuracy_factor if replaced else 1.0
        valid = out.lat is not None and out.lon is not None
        vn = ve = None
        if e.speed_mps is not None and e.course_deg is not None:
            c = math.radians(e.course_deg)
            vn, ve = e.speed_mps * math.cos(c), e.speed_mps * math.sin(c)
        fix = self._fix_cls(
            time_usec=round(unix_s * 1e6),
            gps_week=week,
            gps_week_ms=ms,
            fix_type=(3 if replaced else _FIX_TYPE.get(e.quality, 3)) if valid else 1,
            lat_deg=out.lat if out.lat is not None else 0.0,
            lon_deg=out.lon if out.lon is not None else 0.0,
            alt_m=(out.alt or 0.0) if valid else 0.0,
            hdop=e.hdop if e.hdop is not None else 99.99,
            vdop=e.vdop,
            vn_mps=vn,
            ve_mps=ve,
            vd_mps=None,
            speed_accuracy_mps=s_acc * factor,
            horiz_accuracy_m=h_acc * factor,
            vert_accuracy_m=v_acc * factor,
            satellites_visible=e.num_sats or 0,
        )
        self.endpoint.send_gps_input(fix)
        self.sent += 1

    def stats(self) -> dict[str, int]:
        return {"gps_input_sent": self.sent, "no_date": self.no_date}

    def close(self) -> None:
        self.endpoint.close()
