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
from collections import deque
from collections.abc import Callable
from typing import Any

from drivers.gps.epochs import GpsEpoch
from drivers.gps.nmea import format_date, format_lat, format_lon, format_time, with_checksum
from drivers.mavlink.io import GpsInputFix
from drivers.mavlink.modes import alarm_mode
from drivers.ptypair import PtyPair
from drivers.resilient import Opener, ResilientPort
from drivers.transport import SerialSettings, open_port_nonblocking
from fdi.rover import RoverDetectorParams
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


# GGA quality -> GPS_FIX_TYPE. 6 (dead reckoning), 7 (manual input) and 8 (simulator) are not
# here: we send them as no fix, because none is a measured position the EKF should fuse.
# ArduPilot's own NMEA driver (AP_GPS_NMEA) is laxer: it treats only 0 and 6 as no fix and
# takes 7 and 8 (its switch's default) as a 3D fix.
_FIX_TYPE = {1: 3, 2: 4, 3: 3, 4: 6, 5: 5, 9: 4}
NO_FIX_QUALITIES = frozenset({6, 7, 8})

ALT_HOLD_S = 10.0
"""A 2D epoch (RMC only, or its GGA lost to a bad checksum) keeps the last good altitude this
long, as a 3D fix whose vertical accuracy grows by :data:`ALT_DRIFT_MPS` per second of age;
after that it goes out as a 2D fix (fix type 2, ``GPS_INPUT_IGNORE_FLAG_ALT``)."""
ALT_DRIFT_MPS = 0.5
VEL_HOLD_S = 1.5
"""Without Doppler (speed and course) in an epoch, the last Doppler velocity is held this long,
its speed accuracy raised by :data:`ACCEL_MPS2` per second of age; after that the velocity is
the difference of the output positions over :data:`VEL_BASELINE_S`."""
ACCEL_MPS2 = 1.0
VEL_BASELINE_S = (0.5, 3.0)
DOPPLER_ACC_MPS = 0.1
UNKNOWN_SPEED_ACC_MPS = 50.0
"""Speed accuracy sent with a zero velocity when no velocity is known (first epochs, after a
gap): GPS_INPUT has no "velocity unknown" that ArduPilot honours (an ignored velocity keeps
the previous one), so the value is sent with an accuracy the EKF gives no weight."""
_EARTH_R = 6378137.0


def _date_from_clock(utc_s: float, now_unix: float) -> tuple[int, int, int] | None:
    """The UTC date on which time of day ``utc_s`` is nearest to ``now_unix``; None when the
    system clock is not plausibly set (before 2020)."""
    if now_unix < 1577836800.0:  # 2020-01-01
        return None
    day = math.floor(now_unix / 86400.0)
    best = min((day - 1, day, day + 1), key=lambda d: abs(d * 86400.0 + utc_s - now_unix))
    y, m, d = time.gmtime(best * 86400)[:3]
    return y, m, d


def receiver_accuracy(e: GpsEpoch, detector: RoverDetectorParams) -> tuple[float, float]:
    """The receiver's own horizontal and vertical accuracy of epoch ``e`` (m): its GST
    standard deviations, else the detector's σ (``sigma_m`` √2, ``sigma_up_m``) times the HDOP
    (at least 1)."""
    if e.sd_lat_m is not None and e.sd_lon_m is not None:
        h_acc = math.hypot(e.sd_lat_m, e.sd_lon_m)
        return h_acc, (e.sd_alt_m if e.sd_alt_m is not None else 2.0 * h_acc)
    dop = max(1.0, e.hdop or 1.0)
    return detector.sigma_m * math.sqrt(2.0) * dop, detector.sigma_up_m * dop


class MavlinkGpsSink:
    """GPS_INPUT per epoch; STATUSTEXT and the alarm mode on alarm; heartbeat at 1 Hz of fix time.

    What the autopilot fuses (ArduPilot ``AP_GPS_MAV``), field by field:

    * **fix type**: from the receiver's GGA quality (DGPS 4, RTK float 5, fixed 6); a replaced
      fix is 3 (3D); quality 6/7/8 (dead reckoning, manual, simulator) and the alarm are no fix
      (type 1, position 0, ``satellites_visible`` 0: GPS_RAW_INT must not show "no fix, 10
      satellites"); ArduPilot's NMEA driver treats only 0 and 6 as no fix, 7 and 8 as 3D, but
      neither is a measurement;
    * **altitude**: the fix's; an epoch without one (RMC-only, a lost GGA) holds the last good
      altitude for :data:`ALT_HOLD_S` with a growing vertical accuracy, then goes out as a 2D
      fix with the ALT ignore flag -- never 0 m as a 3D fix;
    * **velocity**: the epoch's Doppler; else the last Doppler held for :data:`VEL_HOLD_S`
      (accuracy grows with its age); else from the output positions; else zero with an accuracy
      of :data:`UNKNOWN_SPEED_ACC_MPS` m/s. Never the ignore flag on a fix (AP_GPS_MAV would keep
      a stale velocity);
    * **time**: GPS week and ms from the epoch's date (RMC, ZDA, or the last one seen); with no
      date at all, from the system clock's date when it is set (after 2020), else week 0 and
      the UTC time of day in ``time_week_ms`` (ArduPilot accepts week 0; it then skips its
      jitter correction);
    * ``gps_id`` from ``[rover.output] gps_id`` (1 feeds GPS2);
    * **yaw**: the receiver's true heading of this epoch (HDT, or THS in mode A), in
      centidegrees with north as 36000; 0 ("not available", AP_GPS_MAV's ``have_yaw``) when
      the receiver gave none in this epoch, when its THS said not valid, and on a no-fix
      message. A replaced fix keeps the epoch's heading; an earlier heading is never held.
    """

    wall_clock: Callable[[], float] = staticmethod(time.time)

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
        self._gps = _GpsInputState()
        self.last_fix: Any | None = None  # the last GPS_INPUT sent (the status line shows it)

    def emit(self, out: EpochOutcome) -> None:
        d = out.decision
        o = self.cfg.output
        due = self._next_heartbeat
        if out.t_s is not None and (due is None or out.t_s >= due):
            self.endpoint.send_heartbeat()
            self._next_heartbeat = math.floor(out.t_s) + 1.0
        fix = self.build_fix(out)
        if fix is not None:
            self.endpoint.send_gps_input(fix)
            self.sent += 1
            self.last_fix = fix
        if d.alarm_raised:
            self.endpoint.send_statustext(
                2, f"FDI GPS: {self.cfg.detector.max_consecutive}+ faults in a row, auto-nav stop"
            )
            if o.hold_on_alarm:
                self.endpoint.request_mode(o.target_system, alarm_mode(o.vehicle, o.alarm_mode),
                                           o.vehicle)
        elif self._was_alarm and not d.alarm:
            self.endpoint.send_statustext(5, "FDI GPS: fixes consistent again, alarm cleared")
        self._was_alarm = d.alarm

    def build_fix(self, out: EpochOutcome) -> Any | None:
        """The GPS_INPUT fields of one epoch (see the class docstring); None without a time."""
        e, d = out.epoch, out.decision
        st = self._gps
        if e.utc_s is None:
            self.no_date += 1
            return None
        date = e.date
        if date is None:
            date = _date_from_clock(e.utc_s, self.wall_clock())
            st.date_from_clock += date is not None
        if date is not None:
            unix_s = unix_time(date, e.utc_s)
            week, ms = gps_week_ms(unix_s)
            time_usec = round(unix_s * 1e6)
        else:
            self.no_date += 1
            week, ms = 0, round(e.utc_s * 1000.0) % 86_400_000
            time_usec = round(self.wall_clock() * 1e6)
        t = out.t_s if out.t_s is not None else e.utc_s
        replaced = d.action != "accept"
        h_acc, v_acc = receiver_accuracy(e, self.cfg.detector)
        factor = self.cfg.output.replaced_accuracy_factor if replaced else 1.0
        h_acc *= factor
        v_acc *= factor
        valid = out.lat is not None and out.lon is not None
        if valid and not replaced and e.quality in NO_FIX_QUALITIES:
            valid = False
            st.estimated_no_fix += 1
        fix_type = (3 if replaced else _FIX_TYPE.get(e.quality, 3)) if valid else 1
        lat = out.lat if valid and out.lat is not None else 0.0
        lon = out.lon if valid and out.lon is not None else 0.0
        alt: float | None = 0.0
        vn: float | None = None
        ve: float | None = None
        s_acc = DOPPLER_ACC_MPS * factor
        if not valid:
            st.forget()
        else:
            alt, v_acc, fix_type = st.altitude(out.alt, v_acc, t, fix_type)
            vn, ve, s_acc = st.velocity(e.speed_mps, e.course_deg, lat, lon, h_acc, t, factor)
        return self._fix_cls(
            time_usec=time_usec,
            gps_week=week,
            gps_week_ms=ms,
            fix_type=fix_type,
            lat_deg=lat,
            lon_deg=lon,
            alt_m=alt,
            hdop=e.hdop if e.hdop is not None else 99.99,
            vdop=e.vdop,
            vn_mps=vn,
            ve_mps=ve,
            vd_mps=None,
            speed_accuracy_mps=s_acc,
            horiz_accuracy_m=h_acc,
            vert_accuracy_m=v_acc,
            satellites_visible=(e.num_sats or 0) if valid else 0,
            gps_id=self.cfg.output.gps_id,
            yaw_deg=out.heading_deg if valid else None,
        )

    def stats(self) -> dict[str, int]:
        st = self._gps
        commands = getattr(self.endpoint, "command_stats", None)  # a direct MavEndpoint's
        extra = dict(commands) if isinstance(commands, dict) else {}
        return {**extra, "gps_input_sent": self.sent, "no_date": self.no_date,
                "date_from_clock": st.date_from_clock, "alt_held": st.alt_held,
                "alt_unknown_2d": st.alt_unknown, "velocity_held": st.vel_held,
                "velocity_from_positions": st.vel_from_positions,
                "velocity_unknown": st.vel_unknown, "estimated_no_fix": st.estimated_no_fix}

    def close(self) -> None:
        self.endpoint.close()


class _GpsInputState:
    """What one GPS_INPUT stream remembers between epochs (altitude, Doppler, positions)."""

    def __init__(self) -> None:
        self.last_alt: tuple[float, float, float] | None = None  # (t, alt, v_acc)
        self.last_doppler: tuple[float, float, float] | None = None  # (t, vn, ve)
        self.positions: deque[tuple[float, float, float]] = deque(maxlen=64)  # (t, lat, lon)
        self.date_from_clock = 0
        self.alt_held = 0
        self.alt_unknown = 0
        self.vel_held = 0
        self.vel_from_positions = 0
        self.vel_unknown = 0
        self.estimated_no_fix = 0

    def forget(self) -> None:
        """No fix: positions before the gap do not make a velocity after it."""
        self.positions.clear()

    def altitude(self, alt: float | None, v_acc: float, t: float,
                 fix_type: int) -> tuple[float | None, float, int]:
        if alt is not None:
            self.last_alt = (t, alt, v_acc)
            return alt, v_acc, fix_type
        last = self.last_alt
        if last is not None and 0.0 <= t - last[0] <= ALT_HOLD_S:
            self.alt_held += 1
            age = t - last[0]
            return last[1], max(v_acc, last[2]) + ALT_DRIFT_MPS * age, fix_type
        self.alt_unknown += 1
        return None, v_acc, 2

    def velocity(self, speed: float | None, course: float | None, lat: float, lon: float,
                 h_acc: float, t: float, factor: float) -> tuple[float, float, float]:
        positions = self.positions
        while positions and positions[0][0] > t:  # time went backwards (a new day, a replay)
            positions.popleft()
        positions.append((t, lat, lon))
        if speed is not None and course is not None:
            c = math.radians(course)
            vn, ve = speed * math.cos(c), speed * math.sin(c)
            self.last_doppler = (t, vn, ve)
            return vn, ve, DOPPLER_ACC_MPS * factor
        last = self.last_doppler
        if last is not None and 0.0 <= t - last[0] <= VEL_HOLD_S:
            self.vel_held += 1
            return last[1], last[2], (DOPPLER_ACC_MPS + ACCEL_MPS2 * (t - last[0])) * factor
        lo, hi = VEL_BASELINE_S
        for t0, lat0, lon0 in positions:
            dt = t - t0
            if lo <= dt <= hi:
                north = math.radians(lat - lat0) * _EARTH_R
                east = math.radians(lon - lon0) * _EARTH_R * math.cos(math.radians(lat))
                self.vel_from_positions += 1
                # Two position errors over the baseline, plus what an acceleration changes
                # between the middle of the baseline (where the difference is exact) and now.
                acc = math.sqrt(2.0) * h_acc / dt + ACCEL_MPS2 * dt / 2.0
                return north / dt, east / dt, acc
        self.vel_unknown += 1
        return 0.0, 0.0, UNKNOWN_SPEED_ACC_MPS
