"""Group NMEA sentences into receiver epochs (one fix each), gpsd style.

A receiver sends a burst of sentences per fix (GGA, RMC, VTG, GSA, GST, ZDA ...), each timed
ones carrying the same fix time. :class:`EpochAssembler` collects a burst into one
:class:`GpsEpoch`. An epoch ends when a sentence with a *different* fix time arrives, or, once
learned, as soon as the sentence type that ends the receiver's bursts arrives (the "cycle ender":
the last type seen before the time changed, two epochs in a row), so an epoch is processed
without waiting for the next one's first sentence.

True heading (HDT, THS) carries no time: it belongs to the epoch that is open when it
arrives, as GSA does. It is not among an epoch's ``sentences`` and never opens an epoch, so an
epoch holds the same sentences with and without the receiver's heading sentences. Its one part
in grouping: a heading that is the last sentence of the bursts (GGA, RMC, HDT) is learned as
the cycle ender like any other type, so the epoch waits for it instead of closing on the RMC
and handing the heading to the next epoch; once learned, an epoch whose heading is missing
closes when the time changes. A heading before the first epoch goes to that epoch. Limit:
without a time, "last of burst N" and "first of burst N+1" are the same position in the
stream, so a receiver that sends its heading first (gpsd's hemi.log order) has it assigned to
the epoch before (one epoch period old). A THS whose mode is not A (autonomous) means "no
heading" for its epoch, whatever an HDT of the same epoch said.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import NamedTuple

from drivers.gps.nmea import Gga, Gll, Gsa, Gst, Hdt, NmeaMessage, Rmc, Ths, Vtg, Zda

TIME_EPS_S = 1e-3
_new = tuple.__new__


class GpsEpoch(NamedTuple):
    """Everything the receiver said about one fix. ``valid``: it claims a position fix.

    Immutable; a NamedTuple rather than a frozen dataclass because it is built once an epoch
    (a frozen dataclass's ``__init__`` is several times slower)."""

    utc_s: float | None
    date: tuple[int, int, int] | None
    valid: bool
    lat_deg: float | None
    lon_deg: float | None
    alt_msl_m: float | None
    geoid_sep_m: float | None
    quality: int
    num_sats: int | None
    hdop: float | None
    vdop: float | None
    dgps_age_s: float | None
    speed_mps: float | None
    course_deg: float | None
    sd_lat_m: float | None
    sd_lon_m: float | None
    sd_alt_m: float | None
    talker: str
    sentences: tuple[str, ...]
    heading_deg: float | None = None  # true heading (HDT, or THS in mode A) of this epoch


class _Pending:
    """The epoch being assembled. A plain class whose absent messages are the class's None
    (one is made an epoch: its __init__ sets the three attributes that differ, not 13)."""

    gga: Gga | None = None
    rmc: Rmc | None = None
    gll: Gll | None = None
    vtg: Vtg | None = None
    gsa: Gsa | None = None
    gst: Gst | None = None
    zda: Zda | None = None
    heading_deg: float | None = None
    heading_refused: bool = False  # a THS of this epoch said its heading is not valid
    trailing: str | None = None  # the heading type when it is the last sentence so far

    def __init__(self, utc_s: float | None = None) -> None:
        self.utc_s = utc_s
        self.types: list[str] = []
        self.heading_kinds: list[str] = []  # HDT/THS, in order

    def add_heading(self, msg: Hdt | Ths) -> None:
        if isinstance(msg, Ths) and not msg.valid:
            self.heading_refused = True
        elif self.heading_deg is None and msg.heading_deg is not None:
            self.heading_deg = msg.heading_deg  # the first heading of the epoch

    def build(self, last_date: tuple[int, int, int] | None) -> GpsEpoch:
        gga, rmc, gll = self.gga, self.rmc, self.gll
        lat = lon = alt = sep = age = hdop = None
        quality, sats, talker = 0, None, ""
        valid = False
        if gga is not None:
            talker = gga.talker
            quality, sats, hdop, age = gga.quality, gga.num_sats, gga.hdop, gga.dgps_age_s
            alt, sep = gga.alt_msl_m, gga.geoid_sep_m
            valid = gga.quality > 0 and gga.lat_deg is not None and gga.lon_deg is not None
            if valid:
                lat, lon = gga.lat_deg, gga.lon_deg
            # A GGA that says "fix" while the RMC of the same time says "void" is not a fix.
            if rmc is not None and not rmc.valid:
                valid = False
                lat = lon = None
        elif rmc is not None:
            talker = rmc.talker
            valid = rmc.valid and rmc.lat_deg is not None and rmc.lon_deg is not None
            quality = 1 if valid else 0
            if valid:
                lat, lon = rmc.lat_deg, rmc.lon_deg
        elif gll is not None:
            talker = gll.talker
            valid = gll.valid and gll.lat_deg is not None and gll.lon_deg is not None
            quality = 1 if valid else 0
            if valid:
                lat, lon = gll.lat_deg, gll.lon_deg
        speed = course = None
        if rmc is not None and rmc.valid:
            speed, course = rmc.speed_mps, rmc.course_deg
        vtg = self.vtg
        if vtg is not None and vtg.speed_mps is not None:
            speed, course = vtg.speed_mps, vtg.course_deg
        date = None
        zda = self.zda
        if rmc is not None and rmc.date is not None:
            date = rmc.date
        elif zda is not None and zda.date is not None:
            date = zda.date
        else:
            date = last_date
        gsa = self.gsa
        if gsa is not None and gsa.hdop is not None and hdop is None:
            hdop = gsa.hdop
        gst = self.gst
        # The tuple of the fields, in GpsEpoch's order (this runs once an epoch: the
        # NamedTuple's own __new__ would bind 20 arguments in Python first).
        return _new(GpsEpoch, (
            self.utc_s,
            date,
            valid,
            lat,
            lon,
            alt if valid else None,  # alt_msl_m
            sep,  # geoid_sep_m
            quality if valid else 0,  # quality
            sats,  # num_sats
            hdop,
            gsa.vdop if gsa is not None else None,  # vdop
            age,  # dgps_age_s
            speed,  # speed_mps
            course,  # course_deg
            gst.sd_lat_m if gst is not None else None,  # sd_lat_m
            gst.sd_lon_m if gst is not None else None,  # sd_lon_m
            gst.sd_alt_m if gst is not None else None,  # sd_alt_m
            talker,
            tuple(self.types),  # sentences
            None if self.heading_refused else self.heading_deg,  # heading_deg
        ))


_TIMED = (Gga, Rmc, Gll, Gst, Zda)
_TIMED_NAMES = frozenset(t.__name__.upper() for t in _TIMED)
# message class -> (sentence type, _Pending slot, carries a fix time)
_KINDS: dict[type, tuple[str, str, bool]] = {
    t: (t.__name__.upper(), t.__name__.lower(), t in _TIMED)
    for t in (Gga, Rmc, Gll, Gst, Zda, Vtg, Gsa)
}


_HEADING_NAMES = frozenset({"HDT", "THS"})


class EpochAssembler:
    """Feed typed messages; iterate complete :class:`GpsEpoch` objects."""

    def __init__(self) -> None:
        self._cur: _Pending | None = None
        self._last_date: tuple[int, int, int] | None = None
        self._ender: str | None = None
        self._ender_votes: tuple[str | None, int] = (None, 0)
        self.duplicates = 0
        self.orphans = 0
        self.late = 0
        self._last_closed: float | None = None
        self._last_closed_types: tuple[str, ...] = ()
        self._banned: set[str] = set()
        self._heading_trails = False  # a heading type was learned as the ender
        self._early_heading: list[Hdt | Ths] = []  # arrived between epochs: the next one's

    @property
    def ender(self) -> str | None:
        """The learned sentence type that ends the receiver's bursts, if known."""
        return self._ender

    def feed(self, msg: NmeaMessage) -> Iterator[GpsEpoch]:
        yield from self.push(msg)

    def push(self, msg: NmeaMessage) -> tuple[GpsEpoch, ...]:
        """:meth:`feed` without the generator: the epochs ``msg`` completes (usually none)."""
        if isinstance(msg, (Hdt, Ths)):
            cur = self._cur
            if cur is None:
                if len(self._early_heading) < 4:
                    self._early_heading.append(msg)
                return ()
            heading_kind = "HDT" if isinstance(msg, Hdt) else "THS"
            cur.add_heading(msg)
            cur.heading_kinds.append(heading_kind)
            cur.trailing = heading_kind
            if self._ender == heading_kind and cur.utc_s is not None:
                return (self._close(),)
            return ()
        kind, slot, timed = _KINDS[type(msg)]
        msg_time: float | None = getattr(msg, "time_s", None) if timed else None
        cur = self._cur
        if (
            timed
            and msg_time is not None
            and cur is None
            and self._last_closed is not None
            and abs(msg_time - self._last_closed) <= TIME_EPS_S
        ):
            # A sentence of an epoch already closed on the learned ender: the ender was wrong
            # for this receiver (e.g. 10 Hz GGA with RMC/ZDA once a second after it). Stop
            # trusting it; from now on epochs close when the fix time changes.
            if kind in self._last_closed_types:
                self.duplicates += 1  # e.g. GPGGA after the GNGGA that closed the epoch
                return ()
            self.late += 1
            if self._ender is not None:
                self._banned.add(self._ender)
                self._ender = None
                self._ender_votes = (None, 0)
            return ()
        closed: tuple[GpsEpoch, ...] = ()
        if cur is not None and timed:
            new_time = (
                msg_time is not None
                and cur.utc_s is not None
                and abs(msg_time - cur.utc_s) > TIME_EPS_S
            )
            untimed_repeat = (msg_time is None or cur.utc_s is None) and kind in cur.types
            timed_after_untimed = msg_time is not None and cur.utc_s is None and bool(cur.types)
            if new_time or untimed_repeat or timed_after_untimed:
                trailing = cur.trailing
                if new_time and trailing is not None:
                    if cur.heading_kinds.count(trailing) == 1:
                        self._vote_ender(trailing)
                elif new_time and cur.types and cur.types.count(cur.types[-1]) == 1:
                    self._vote_ender(cur.types[-1])
                if cur.utc_s is None and not any(t in _TIMED_NAMES for t in cur.types):
                    self.orphans += len(cur.types)  # VTG/GSA with no fix of their own
                    self._cur = None
                else:
                    closed = (self._close(),)
                cur = None
        if cur is None:
            cur = self._cur = _Pending(msg_time)
            if self._early_heading:
                for heading in self._early_heading:
                    cur.add_heading(heading)
                self._early_heading.clear()
        elif cur.utc_s is None and msg_time is not None:
            cur.utc_s = msg_time
        if getattr(cur, slot) is not None:
            self.duplicates += 1  # e.g. GNGGA and GPGGA of the same fix: keep the first
        else:
            setattr(cur, slot, msg)
        cur.types.append(kind)
        cur.trailing = None
        if self._ender is not None and kind == self._ender and cur.utc_s is not None:
            return (*closed, self._close())
        return closed

    def flush(self) -> Iterator[GpsEpoch]:
        cur = self._cur
        if cur is not None and cur.types:
            if any(t in _TIMED_NAMES for t in cur.types):
                yield self._close()
            else:
                self.orphans += len(cur.types)
                self._cur = None

    def _close(self) -> GpsEpoch:
        assert self._cur is not None
        epoch = self._cur.build(self._last_date)
        self._last_closed = epoch.utc_s
        self._last_closed_types = epoch.sentences  # its sentence types
        if epoch.date is not None:
            self._last_date = epoch.date
        self._cur = None
        return epoch

    def _vote_ender(self, kind: str) -> None:
        if kind in self._banned:
            return
        if self._heading_trails and kind not in _HEADING_NAMES:
            # The receiver's heading ends its bursts: an epoch without one (an intermittent
            # heading) closes when the time changes, never on the sentence before the heading.
            return
        candidate, votes = self._ender_votes
        votes = votes + 1 if candidate == kind else 1
        self._ender_votes = (kind, votes)
        if votes >= 2:
            self._ender = kind
            self._heading_trails = self._heading_trails or kind in _HEADING_NAMES
