"""NMEA 0183: the framer (bytes -> lines) and the codec (line -> typed message).

Two layers, kept apart (pynmeagps style):

* :class:`NmeaFramer` turns an arbitrary byte stream into candidate sentences. It resyncs on
  ``$``, caps a line's length *before* collecting more of it, and reports every rejected piece
  with a reason (``garbage``, ``too_long``, ``truncated``, ``bad_chars``).
* :func:`parse_sentence` is a pure function from one line to an immutable message (:class:`Gga`,
  :class:`Rmc`, :class:`Vtg`, :class:`Gsa`, :class:`Gst`, :class:`Zda`, :class:`Gll`, and the
  true headings :class:`Hdt` and :class:`Ths`). It requires a valid checksum, uses pynmea2
  (``check=True``) only to split and identify the sentence (HDT and THS are split here:
  pynmea2 does not know THS; so is the usual well-formed sentence, exactly as pynmea2 splits
  it, for speed), and converts every field itself with range checks: pynmea2
  coerces bad fields silently, so none of its conversions reach the estimators. A bad sentence
  raises :class:`~fdi.errors.DecodeError` with a short reason; proprietary (``$P...``) and
  unknown sentences raise :class:`Ignored` so the caller counts them without calling them
  errors.

Units are in the field names: degrees, metres, metres per second, seconds of day (UTC).

Numbers are taken as NMEA 0183 writes them (``x.x``: decimal digits with an optional sign
and decimal point) and nothing else: exponent notation (``1e308``), ``nan``, ``inf``, blanks
and ``_`` (all of which Python's ``float`` takes) are a ``bad_field``, in every numeric field,
read or not (issue 43: a checksum-valid ``1e308`` reached the detector). Every field the
bridge reads has a range (the ``MAX_*``/``*_M`` constants below); a field it does not read
(magnetic variation and course, the GST error ellipse, GSA's satellite numbers, ZDA's local
zone) is checked for form only: one receiver in the corpus sends magnetic variation 999.9.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from functools import lru_cache
from typing import NamedTuple

from fdi.errors import DecodeError

KNOT_MPS = 1852.0 / 3600.0
KMH_MPS = 1000.0 / 3600.0
MAX_LINE = 120  # NMEA 0183 says 82 characters; receivers in the wild send a little more

# The ranges of the numeric fields the bridge reads (a value outside is a ``bad_field``): wide
# enough for any receiver's real output, narrow enough that no value reaches a math error.
MAX_SPEED_KN = 1000.0  # the CoCom limit: a civil receiver gives no fix above 1 000 knots
MAX_SPEED_KMH = MAX_SPEED_KN * 1.852
MAX_SIGMA_M = 100_000.0  # GST error estimates (rms, sigma lat/lon/alt)
MAX_DOP = 1000.0  # receivers without a fix send 99.9 or 99.99
ALT_MIN_M, ALT_MAX_M = -12_000.0, 100_000.0  # below the deepest ocean .. the Karman line
MAX_GEOID_SEP_M = 200.0  # the geoid is within -107 .. +86 m of the ellipsoid
MAX_DGPS_AGE_S = 86_400.0
MAX_STATION_ID = 1023  # GGA's differential station: 0000-1023
MAX_SATS = 99
_DECIMAL = "0123456789.+-"  # the characters of an NMEA number (``float`` checks its form)

SUPPORTED = frozenset({"GGA", "RMC", "VTG", "GSA", "GST", "ZDA", "GLL", "HDT", "THS"})
# Sentences pynmea2 does not know (THS) are split here; so is HDT, to keep the two alike.
_OWN_SPLIT = frozenset({"HDT", "THS"})
_LINE_STOP = re.compile(rb"[\r\n$]")
_LINE_END = re.compile(rb"[\r\n]")
_NON_PRINTABLE = re.compile(rb"[^\x20-\x7e]")
_BLANKS = b" \t\x00"
_CLEAN_LINES: dict[int, re.Pattern[bytes]] = {}  # max_line -> pattern of _clean_line_re


def _clean_line_re(max_line: int) -> re.Pattern[bytes] | None:
    """Optional blanks and line ends, then a whole line the framer passes on unchanged: ``$``,
    at most ``max_line - 2`` printable characters other than ``$``, and its CR or LF."""
    if max_line < 2:
        return None
    pattern = _CLEAN_LINES.get(max_line)
    if pattern is None:
        body = rb"\$[\x20-\x23\x25-\x7e]{0,%d}" % (max_line - 2)
        pattern = _CLEAN_LINES[max_line] = re.compile(rb"[\r\n \t\x00]*(" + body + rb")[\r\n]")
    return pattern


class Ignored(Exception):
    """A well-formed sentence this codec does not use (proprietary or unknown type)."""

    def __init__(self, reason: str, sentence_type: str) -> None:
        self.reason = reason
        self.sentence_type = sentence_type
        super().__init__(f"{reason}: {sentence_type}")


# --------------------------------------------------------------------------- framer


@dataclass(frozen=True, slots=True)
class Rejected:
    """A piece of the byte stream the framer threw away, and why."""

    reason: str
    data: bytes


class NmeaFramer:
    """Bytes in, lines out. ``feed`` yields ``bytes`` (a complete line, no CR/LF) or ``Rejected``.

    A line starts at ``$`` and ends at CR or LF. A ``$`` inside a line means the previous
    sentence was cut short (a packet collision): the partial line is rejected as ``truncated``
    and a new line starts. A line that reaches ``max_line`` characters without an end is
    rejected as ``too_long`` and the framer waits for the next ``$``. Bytes between lines are
    ``garbage`` (CR/LF and blanks excepted).
    """

    def __init__(self, max_line: int = MAX_LINE) -> None:
        self.max_line = max_line
        self._buf = bytearray()
        self._in_line = False
        self._garbage = bytearray()
        self._skipping = False  # after too_long: drop until the next '$'

    def feed(self, data: bytes) -> Iterator[bytes | Rejected]:
        # Scans with ``re``/``bytes.find`` rather than byte by byte: the framer is the hot
        # path of an offline replay (tens of thousands of epochs a second).
        buf = self._buf
        clean = _clean_line_re(self.max_line)
        i, n = 0, len(data)
        while i < n:
            if clean is not None and not self._in_line and not self._garbage:
                # Fast path: whole, clean lines (the usual case) in one regex match each.
                # Exactly what the general path below does with them: the blanks and line
                # ends before the '$' are not garbage, and the line is yielded as it is.
                m = clean.match(data, i)
                if m is not None:
                    self._skipping = False
                    while m is not None:
                        yield m.group(1)
                        i = m.end()
                        m = clean.match(data, i)
                    continue
            if self._in_line:
                m = _LINE_STOP.search(data, i)
                end = m.start() if m is not None else n
                room = self.max_line - len(buf)
                if end - i >= room:
                    buf += data[i : i + room]
                    yield Rejected("too_long", bytes(buf))
                    buf.clear()
                    self._in_line = False
                    self._skipping = True
                    i += room
                    continue
                buf += data[i:end]
                if m is None:
                    return
                i = end + 1
                if data[end] == 0x24:  # '$' inside a line: the line was cut short
                    yield Rejected("truncated", bytes(buf))
                    buf.clear()
                    buf.append(0x24)
                    continue
                line = bytes(buf)
                buf.clear()
                self._in_line = False
                yield Rejected("bad_chars", line) if _NON_PRINTABLE.search(line) else line
            else:
                j = data.find(b"$", i)
                stop = n if j < 0 else j
                if stop > i:
                    yield from self._between_lines(data[i:stop])
                if j < 0:
                    return
                if self._garbage:
                    yield Rejected("garbage", bytes(self._garbage))
                    self._garbage.clear()
                buf.clear()
                buf.append(0x24)
                self._in_line = True
                self._skipping = False
                i = j + 1

    def _between_lines(self, seg: bytes) -> Iterator[Rejected]:
        """Bytes outside any line: garbage (blanks and line ends excepted)."""
        parts = _LINE_END.split(seg)
        for k, part in enumerate(parts):
            if not self._skipping:
                junk = part.translate(None, _BLANKS)
                if junk:
                    self._garbage += junk
                    while len(self._garbage) >= self.max_line:
                        yield Rejected("garbage", bytes(self._garbage[: self.max_line]))
                        del self._garbage[: self.max_line]
            if k < len(parts) - 1:  # a line end follows this part
                if self._garbage:
                    yield Rejected("garbage", bytes(self._garbage))
                    self._garbage.clear()
                self._skipping = False

    def flush(self) -> Iterator[Rejected]:
        """End of stream: whatever is pending is a truncated line (or garbage)."""
        if self._in_line and self._buf:
            yield Rejected("truncated", bytes(self._buf))
        if self._garbage:
            yield Rejected("garbage", bytes(self._garbage))
        self._buf.clear()
        self._garbage.clear()
        self._in_line = False


# --------------------------------------------------------------------------- messages
# Immutable and typed as NamedTuples rather than frozen dataclasses: a frozen dataclass sets each
# field through object.__setattr__, several times slower to build, and a replay builds three or
# more of these per epoch.


class Gga(NamedTuple):
    talker: str
    time_s: float | None
    lat_deg: float | None
    lon_deg: float | None
    quality: int
    num_sats: int | None
    hdop: float | None
    alt_msl_m: float | None
    geoid_sep_m: float | None
    dgps_age_s: float | None
    dgps_station: str | None


class Rmc(NamedTuple):
    talker: str
    time_s: float | None
    valid: bool
    lat_deg: float | None
    lon_deg: float | None
    speed_mps: float | None
    course_deg: float | None
    date: tuple[int, int, int] | None  # (year, month, day)
    mode: str | None


class Vtg(NamedTuple):
    talker: str
    course_deg: float | None
    speed_mps: float | None
    mode: str | None


class Gsa(NamedTuple):
    talker: str
    fix_mode: int | None  # 1 none, 2 2D, 3 3D
    pdop: float | None
    hdop: float | None
    vdop: float | None


class Gst(NamedTuple):
    talker: str
    time_s: float | None
    rms_m: float | None
    sd_lat_m: float | None
    sd_lon_m: float | None
    sd_alt_m: float | None


class Zda(NamedTuple):
    talker: str
    time_s: float | None
    date: tuple[int, int, int] | None


class Gll(NamedTuple):
    talker: str
    time_s: float | None
    valid: bool
    lat_deg: float | None
    lon_deg: float | None


class Hdt(NamedTuple):
    """True heading (a dual-antenna or gyro receiver); ``heading_deg`` None when not known."""

    talker: str
    heading_deg: float | None


class Ths(NamedTuple):
    """True heading with its mode (A autonomous, E estimated, M manual, S simulator, V not
    valid). ``heading_deg`` is kept as sent; only mode A is a heading to use (:attr:`valid`)."""

    talker: str
    heading_deg: float | None
    mode: str | None

    @property
    def valid(self) -> bool:
        return self.mode == "A" and self.heading_deg is not None


NmeaMessage = Gga | Rmc | Vtg | Gsa | Gst | Zda | Gll | Hdt | Ths


# --------------------------------------------------------------------------- field helpers


def checksum(body: bytes | str) -> int:
    """XOR of the characters between ``$`` and ``*``."""
    data = body.encode("ascii") if isinstance(body, str) else body
    if len(data) <= 128:
        return _xor128(data)
    value = 0
    for c in data:
        value ^= c
    return value


def _xor128(data: bytes) -> int:
    """The XOR of up to 128 bytes: the bytes read as one integer and folded onto themselves
    (``x ^= x >> 8k``: byte ``i`` now also holds byte ``i + k``), halving the span each time
    down to the lowest byte. The same value as a loop over the bytes in a few integer
    operations (a replay checks three sentences an epoch; tested against the loop on every
    length)."""
    x = int.from_bytes(data, "little")
    n = len(data)
    if n > 64:
        x ^= x >> 512
    if n > 32:
        x ^= x >> 256
    if n > 16:
        x ^= x >> 128
    x ^= x >> 64
    x ^= x >> 32
    x ^= x >> 16
    x ^= x >> 8
    return x & 0xFF


def _float(text: str, name: str) -> float | None:
    """A plain decimal number (NMEA's ``x.x``), or None for an empty field; DecodeError for
    anything else: exponent notation, ``nan``, ``inf``, blanks, ``_`` (module doc)."""
    if text == "":
        return None
    if text.strip(_DECIMAL):  # a character other than digits, sign and point
        raise DecodeError("bad_field", f"{name}={text!r}")
    try:
        return float(text)  # only digits, sign and point: a number (over 308 digits, inf:
        # the ranges refuse it; MAX_LINE keeps a field far shorter), or a ValueError
    except ValueError as err:
        raise DecodeError("bad_field", f"{name}={text!r}") from err


def _ranged(text: str, name: str, lo: float, hi: float) -> float | None:
    """:func:`_float` within ``[lo, hi]``."""
    value = _float(text, name)
    if value is not None and not lo <= value <= hi:
        raise DecodeError("bad_field", f"{name}={text!r}")
    return value


def _nonneg(text: str, name: str, hi: float) -> float | None:
    """:func:`_float` within ``[0, hi]``, ``-0`` read as 0 (a speed of "-0.000" is not passed
    on)."""
    value = _ranged(text, name, 0.0, hi)
    return None if value is None else value + 0.0  # -0.0 + 0.0 is 0.0; nothing else changes


def _int(text: str, name: str) -> int | None:
    """A plain integer (digits, perhaps a sign), or None for an empty field."""
    if text == "":
        return None
    if text.strip(_DECIMAL):
        raise DecodeError("bad_field", f"{name}={text!r}")
    try:
        return int(text)
    except ValueError as err:
        raise DecodeError("bad_field", f"{name}={text!r}") from err


def _form(text: str, name: str) -> None:
    """A field the bridge does not read: a plain decimal number or empty (module doc)."""
    if text:
        _float(text, name)


def _station(text: str) -> str | None:
    """GGA's differential station id, kept as text: digits, 0000-1023."""
    if text == "":
        return None
    if not text.isdigit() or int(text) > MAX_STATION_ID:
        raise DecodeError("bad_field", f"dgps_station={text!r}")
    return text


# The time, date and position conversions are pure and a receiver repeats their fields within
# an epoch (GGA and RMC carry the same time and position), so their results are cached (errors
# are not: a bad field raises every time).


@lru_cache(maxsize=32)
def _time(text: str) -> float | None:
    """hhmmss[.sss] -> seconds of day."""
    if text == "":
        return None
    if len(text) < 6 or not text[:6].isdigit():
        raise DecodeError("bad_field", f"time={text!r}")
    frac = text[6:]  # "" or "." and digits (no exponent: "100000.5e-1" is not 10:00:00.05)
    if frac and not (frac[0] == "." and (len(frac) == 1 or frac[1:].isdigit())):
        raise DecodeError("bad_field", f"time={text!r}")
    hh, mm = int(text[0:2]), int(text[2:4])
    try:
        ss = float(text[4:])
    except ValueError as err:
        raise DecodeError("bad_field", f"time={text!r}") from err
    if hh > 23 or mm > 59 or not 0.0 <= ss < 61.0:
        raise DecodeError("bad_field", f"time={text!r}")
    return hh * 3600 + mm * 60 + ss


@lru_cache(maxsize=32)
def _date(ddmmyy: str) -> tuple[int, int, int] | None:
    if ddmmyy == "":
        return None
    if len(ddmmyy) != 6 or not ddmmyy.isdigit():
        raise DecodeError("bad_field", f"date={ddmmyy!r}")
    d, m, y = int(ddmmyy[0:2]), int(ddmmyy[2:4]), int(ddmmyy[4:6])
    if not (1 <= d <= 31 and 1 <= m <= 12):
        raise DecodeError("bad_field", f"date={ddmmyy!r}")
    # NMEA's two-digit year: 80..99 -> 19xx, else 20xx (as gpsd does around its pivot).
    return (1900 + y if y >= 80 else 2000 + y, m, d)


def _latlon_of(value: str, hemi: str, is_lat: bool) -> float | None:
    """ddmm.mmmm / dddmm.mmmm with hemisphere -> signed degrees, strictly range-checked."""
    if value == "" and hemi == "":
        return None
    name = "lat" if is_lat else "lon"
    if value == "" or hemi == "":
        raise DecodeError("bad_field", f"{name}={value!r},{hemi!r}")
    deg_digits = 2 if is_lat else 3
    head, _, decimals = value.partition(".")
    if len(head) != deg_digits + 2 or not head.isdigit() or (
            decimals and not decimals.isdigit()):  # "3201.5e-1" is not 32 deg 0.15'
        raise DecodeError("bad_field", f"{name}={value!r}")
    try:
        degrees = int(value[:deg_digits])
        minutes = float(value[deg_digits:])
    except ValueError as err:
        raise DecodeError("bad_field", f"{name}={value!r}") from err
    limit = 90 if is_lat else 180
    if not 0.0 <= minutes < 60.0 or degrees > limit:
        raise DecodeError("bad_field", f"{name}={value!r}")
    result = degrees + minutes / 60.0
    if result > limit:
        raise DecodeError("bad_field", f"{name}={value!r}")
    valid_hemi = ("N", "S") if is_lat else ("E", "W")
    if hemi not in valid_hemi:
        raise DecodeError("bad_field", f"{name} hemisphere={hemi!r}")
    return -result if hemi in ("S", "W") else result


_latlon = lru_cache(maxsize=32)(_latlon_of)


@lru_cache(maxsize=32)
def _position(lat: str, ns: str, lon: str, ew: str) -> tuple[float | None, float | None]:
    """``(_latlon(lat, ns, True), _latlon(lon, ew, False))`` with one cache look-up (the fast
    paths: GGA and RMC of an epoch carry the same four fields); DecodeError as _latlon.

    The usual ``ddmm.mmmm,N,dddmm.mmmm,E`` is converted here with the same operations as
    :func:`_latlon_of` (tested against it); anything else goes to it."""
    if (lat[4:5] == "." and lon[5:6] == "." and ns in _NS and ew in _EW
            and lat[:4].isdigit() and lon[:5].isdigit() and lat[5:].isdigit()
            and lon[6:].isdigit()):
        try:
            lat_min, lon_min = float(lat[2:]), float(lon[3:])
        except ValueError:
            lat_min = lon_min = -1.0  # not minutes: the checked conversion says why
        if 0.0 <= lat_min < 60.0 and 0.0 <= lon_min < 60.0:
            la = int(lat[:2]) + lat_min / 60.0
            lo = int(lon[:3]) + lon_min / 60.0
            if la <= 90 and lo <= 180:
                return -la if ns == "S" else la, -lo if ew == "W" else lo
    return _latlon_of(lat, ns, True), _latlon_of(lon, ew, False)


_NS, _EW = ("N", "S"), ("E", "W")


_HEX = frozenset("0123456789ABCDEFabcdef")  # pynmea2's checksum pattern, [A-F0-9] ignoring case
_PAD = [""] * 20  # decoders index fields directly; a short sentence reads empty fields
# "HH" -> its value, for the checksum's two hexadecimal digits (either case, as pynmea2)
_HEX_PAIRS = {a + b: int(a + b, 16) for a in _HEX for b in _HEX}


def _given(line: bytes, star: int) -> int:
    """The checksum the sentence carries (``*HH``); DecodeError when it is not hex."""
    try:
        return int(line[star + 1 :], 16)
    except ValueError as err:
        raise DecodeError("no_checksum", line[star:].decode("ascii", "replace")) from err


# --------------------------------------------------------------------------- codec


def parse_sentence(line: bytes) -> NmeaMessage:
    """One framed line (``$...*HH``, no CR/LF) -> a typed message.

    Raises :class:`DecodeError` (reasons ``no_checksum``, ``bad_checksum``, ``parse_error``,
    ``bad_field``, ``short``) or :class:`Ignored` (``proprietary``, ``unknown_sentence``).
    """
    if not line.isascii():
        raise DecodeError("parse_error", "non-ASCII bytes")
    star = len(line) - 3
    if star < 1 or line[star] != 0x2A:  # '*' followed by two characters ends every sentence
        raise DecodeError("no_checksum", line[:20].decode("ascii", "replace"))
    text = line.decode("ascii")
    comma = text.find(",", 1, star)
    address = text[1 : comma if comma > 0 else star]
    kind = address[2:]
    decoder = _DECODERS.get(kind)
    if decoder is None or address[:1] == "P":
        if checksum(line[1:star]) != _given(line, star):
            raise DecodeError("bad_checksum", line[:20].decode("ascii", "replace"))
        if address.startswith("P"):
            raise Ignored("proprietary", address)
        if len(address) != 5 or not address.isalpha():
            raise DecodeError("parse_error", f"address {address!r}")
        raise Ignored("unknown_sentence", address)
    talker = address[:2]
    if not talker.isalpha():
        raise DecodeError("parse_error", f"address {address!r}")
    if kind in _OWN_SPLIT:
        if checksum(line[1:star]) != _given(line, star):
            raise DecodeError("bad_checksum", line[:20].decode("ascii", "replace"))
        fields = text[comma + 1 : star].split(",") if comma > 0 else []
        return decoder(talker, fields + _PAD, len(fields))
    data = _split_usual(line, text, comma, star)
    if data is None:
        data = _split_pynmea2(line, text, star)
    n = len(data)
    if n < _NEED[kind]:  # the decoder reads no field beyond _NEED[kind]: pad only then
        data = data + _PAD
    return decoder(talker, data, n)


def _split_usual(line: bytes, text: str, comma: int, star: int) -> list[str] | None:
    """The fields of the usual sentence, split here exactly as pynmea2 would split them; None
    for anything else (:func:`_split_pynmea2` then). pynmea2's pattern takes ``$``, a talker
    sentence's address (not ``P...``) and a comma, fields without ``*``, then ``*HH`` with HH
    hexadecimal, and checks the XOR of everything between ``$`` and ``*``; its per-sentence
    objects cost about a third of an offline replay's parsing."""
    if comma > 0 and text[0] == "$" and text[1] not in "pP" and text.find("*", comma, star) < 0:
        given = _HEX_PAIRS.get(text[star + 1 :])  # both characters hexadecimal: their value
        if given is not None:
            body = line[1:star]
            if (_xor128(body) if len(body) <= 128 else checksum(body)) != given:
                raise DecodeError("bad_checksum", line[:20].decode("ascii", "replace"))
            return text[comma + 1 : star].split(",")
    return None


def _split_pynmea2(line: bytes, text: str, star: int) -> list[str]:
    """pynmea2 splits the sentence and, with check=True, verifies the checksum (once: it is
    not computed again on this path), so unusual sentences are classified as they always
    were. Its field conversions are not used. pynmea2 is imported on the first unusual
    sentence, not with this module (issue 19: start-up; the usual ones never need it)."""
    import pynmea2

    try:
        msg = pynmea2.parse(text, check=True)
    except pynmea2.ChecksumError as err:
        raise DecodeError("bad_checksum", line[:20].decode("ascii", "replace")) from err
    except (pynmea2.ParseError, ValueError, AttributeError, TypeError) as err:
        if checksum(line[1:star]) != _given(line, star):  # classify by what is wrong first
            raise DecodeError("bad_checksum", line[:20].decode("ascii", "replace")) from err
        raise DecodeError("parse_error", str(err)[:60]) from err
    data: list[str] = msg.data
    return data


# The decoders build the frozen messages with positional arguments, in field order (and so in
# the order the fields are checked).


# A message built from the tuple of its fields, in field order: what the NamedTuple's own
# ``__new__`` does after binding its arguments in Python (the fast paths build three a fix).
_new = tuple.__new__


def _gga(talker: str, d: list[str], n: int) -> Gga:
    """GGA: the usual sentence converted with the builtins the checked path uses (the same
    values), everything checked at once (the numbers' form in one ``strip`` of their joined
    texts, then the ranges); anything unusual goes to :func:`_gga_checked`, which raises the
    first error in field order. So do RMC and VTG."""
    if n >= 9:
        try:
            q, s, h, a, g, age, st = d[5], d[6], d[7], d[8], d[10], d[12], d[13]
            if not "".join((q, s, h, a, g, age)).strip(_DECIMAL):
                quality = int(q) if q else 0
                sats = int(s) if s else None
                hdop = float(h) + 0.0 if h else None
                alt = float(a) if a else None
                sep = float(g) if g else None
                dage = float(age) + 0.0 if age else None
                if (0 <= quality <= 9 and (sats is None or 0 <= sats <= MAX_SATS)
                        and (hdop is None or 0.0 <= hdop <= MAX_DOP)
                        and (alt is None or ALT_MIN_M <= alt <= ALT_MAX_M)
                        and (sep is None or -MAX_GEOID_SEP_M <= sep <= MAX_GEOID_SEP_M)
                        and (dage is None or 0.0 <= dage <= MAX_DGPS_AGE_S)
                        and (not st or (st.isdigit() and (len(st) < 4 or st <= "1023")))):
                    lat, lon = _position(d[1], d[2], d[3], d[4])
                    return _new(Gga, (talker, _time(d[0]), lat, lon, quality, sats, hdop, alt,
                                      sep, dage, st or None))
        except (ValueError, DecodeError):
            pass
    return _gga_checked(talker, d, n)


def _gga_checked(talker: str, d: list[str], n: int) -> Gga:
    if n < 9:
        raise DecodeError("short", f"GGA has {n} fields")
    quality = _int(d[5], "quality")
    if quality is None:
        quality = 0
    if not 0 <= quality <= 9:
        raise DecodeError("bad_field", f"quality={quality}")
    sats = _int(d[6], "sats")
    if sats is not None and not 0 <= sats <= MAX_SATS:
        raise DecodeError("bad_field", f"sats={sats}")
    return Gga(
        talker,
        _time(d[0]),  # time_s
        _latlon(d[1], d[2], True),  # lat_deg
        _latlon(d[3], d[4], False),  # lon_deg
        quality,
        sats,  # num_sats
        _nonneg(d[7], "hdop", MAX_DOP),
        _ranged(d[8], "alt", ALT_MIN_M, ALT_MAX_M),  # alt_msl_m
        _ranged(d[10], "geoid_sep", -MAX_GEOID_SEP_M, MAX_GEOID_SEP_M),
        _nonneg(d[12], "dgps_age", MAX_DGPS_AGE_S),
        _station(d[13]),  # dgps_station
    )


def _rmc(talker: str, d: list[str], n: int) -> Rmc:
    """RMC, the usual sentence: see :func:`_gga`."""
    status = d[1]
    if n >= 9 and status == "A":
        try:
            mode = d[11] or None
            sp, co, mv = d[6], d[7], d[9]
            if not "".join((sp, co, mv)).strip(_DECIMAL):
                speed_kn = float(sp) + 0.0 if sp else None
                course = float(co) + 0.0 if co else None
                if mv:
                    float(mv)  # magnetic variation: not read, its form checked
                if ((speed_kn is None or 0.0 <= speed_kn <= MAX_SPEED_KN)
                        and (course is None or 0.0 <= course <= 360.0)):
                    lat, lon = _position(d[2], d[3], d[4], d[5])
                    return _new(Rmc, (
                        talker,
                        _time(d[0]),
                        mode != "N",  # valid
                        lat,
                        lon,
                        None if speed_kn is None else speed_kn * KNOT_MPS,
                        course,
                        _date(d[8]) if mode != "N" else _safe_date(d[8]),
                        mode,
                    ))
        except (ValueError, DecodeError):
            pass
    return _rmc_checked(talker, d, n)


def _rmc_checked(talker: str, d: list[str], n: int) -> Rmc:
    if n < 9:
        raise DecodeError("short", f"RMC has {n} fields")
    status = d[1]
    if status not in ("A", "V", ""):
        raise DecodeError("bad_field", f"status={status!r}")
    mode = d[11] or None
    valid = status == "A" and mode != "N"
    speed_kn = _nonneg(d[6], "speed", MAX_SPEED_KN)
    course = _nonneg(d[7], "course", 360.0)
    _form(d[9], "mag_var")
    try:
        lat = _latlon(d[2], d[3], True)
        lon = _latlon(d[4], d[5], False)
    except DecodeError:
        if valid:
            raise
        lat = lon = None  # void RMC with junk placeholders (seen: lat "36000.0000")
    return Rmc(
        talker,
        _time(d[0]),  # time_s
        valid,
        lat,
        lon,
        None if speed_kn is None else speed_kn * KNOT_MPS,  # speed_mps
        course,
        _date(d[8]) if valid else _safe_date(d[8]),  # date
        mode,
    )


def _safe_date(text: str) -> tuple[int, int, int] | None:
    try:
        return _date(text)
    except DecodeError:
        return None


def _vtg(talker: str, d: list[str], n: int) -> Vtg:
    """VTG, the usual sentence (course and speed in km/h): see :func:`_gga`."""
    try:
        c, cm, kn, k, mode = d[0], d[2], d[4], d[6], d[8] or None
        if k and mode != "N" and not "".join((c, cm, kn, k)).strip(_DECIMAL):
            course = float(c) + 0.0 if c else None
            speed_kmh = float(k) + 0.0
            speed_kn = float(kn) if kn else None  # read and checked, not used
            if cm:
                float(cm)  # magnetic course: not read, its form checked
            if ((course is None or 0.0 <= course <= 360.0)
                    and 0.0 <= speed_kmh <= MAX_SPEED_KMH
                    and (speed_kn is None or 0.0 <= speed_kn <= MAX_SPEED_KN)):
                return _new(Vtg, (talker, course, speed_kmh * KMH_MPS, mode))
    except ValueError:
        pass
    return _vtg_checked(talker, d, n)


def _vtg_checked(talker: str, d: list[str], n: int) -> Vtg:
    # Modern form: course,T,course_m,M,speed_kn,N,speed_kmh,K[,mode]
    course = _nonneg(d[0], "course", 360.0)
    _form(d[2], "course_m")
    speed_kmh = _nonneg(d[6], "speed_kmh", MAX_SPEED_KMH)
    speed_kn = _nonneg(d[4], "speed_kn", MAX_SPEED_KN)
    speed: float | None
    if speed_kmh is not None:
        speed = speed_kmh * KMH_MPS
    elif speed_kn is not None:
        speed = speed_kn * KNOT_MPS
    else:
        speed = None
    mode = d[8] or None
    if mode == "N":
        course = speed = None
    return Vtg(talker, course, speed, mode)


def _gsa(talker: str, d: list[str], n: int) -> Gsa:
    if n < 17:
        raise DecodeError("short", f"GSA has {n} fields")
    fix = _int(d[1], "fix_mode")
    for k in range(2, 14):
        _int(d[k], "prn")  # the satellites' numbers: not read, their form checked
    return Gsa(
        talker=talker,
        fix_mode=fix,
        pdop=_nonneg(d[14], "pdop", MAX_DOP),
        hdop=_nonneg(d[15], "hdop", MAX_DOP),
        vdop=_nonneg(d[16], "vdop", MAX_DOP),
    )


def _gst(talker: str, d: list[str], n: int) -> Gst:
    """GST, the usual sentence: see :func:`_gga`."""
    if n >= 8 and not "".join(d[1:8]).strip(_DECIMAL):
        try:
            rms, sd_lat, sd_lon, sd_alt = d[1], d[5], d[6], d[7]
            for k in (2, 3, 4):
                if d[k]:
                    float(d[k])  # the error ellipse: not read, its form checked
            rms_m = float(rms) + 0.0 if rms else None
            sd_lat_m = float(sd_lat) + 0.0 if sd_lat else None
            sd_lon_m = float(sd_lon) + 0.0 if sd_lon else None
            sd_alt_m = float(sd_alt) + 0.0 if sd_alt else None
            if ((rms_m is None or 0.0 <= rms_m <= MAX_SIGMA_M)
                    and (sd_lat_m is None or 0.0 <= sd_lat_m <= MAX_SIGMA_M)
                    and (sd_lon_m is None or 0.0 <= sd_lon_m <= MAX_SIGMA_M)
                    and (sd_alt_m is None or 0.0 <= sd_alt_m <= MAX_SIGMA_M)):
                return _new(Gst, (talker, _time(d[0]), rms_m, sd_lat_m, sd_lon_m, sd_alt_m))
        except (ValueError, DecodeError):
            pass
    return _gst_checked(talker, d, n)


def _gst_checked(talker: str, d: list[str], n: int) -> Gst:
    if n < 8:
        raise DecodeError("short", f"GST has {n} fields")
    time_s = _time(d[0])
    rms_m = _nonneg(d[1], "rms", MAX_SIGMA_M)
    _form(d[2], "semi_major")  # the error ellipse: not read, its form checked
    _form(d[3], "semi_minor")
    _form(d[4], "orientation")
    return Gst(
        talker=talker,
        time_s=time_s,
        rms_m=rms_m,
        sd_lat_m=_nonneg(d[5], "sd_lat", MAX_SIGMA_M),
        sd_lon_m=_nonneg(d[6], "sd_lon", MAX_SIGMA_M),
        sd_alt_m=_nonneg(d[7], "sd_alt", MAX_SIGMA_M),
    )


def _zda(talker: str, d: list[str], n: int) -> Zda:
    if n < 4:
        raise DecodeError("short", f"ZDA has {n} fields")
    day, month, year = _int(d[1], "day"), _int(d[2], "month"), _int(
        d[3], "year"
    )
    if d[4] or d[5]:  # the local zone: not read, its form checked
        _int(d[4], "zone_h")
        _int(d[5], "zone_min")
    date: tuple[int, int, int] | None = None
    if day is not None and month is not None and year is not None:
        if not (1 <= day <= 31 and 1 <= month <= 12 and 1980 <= year <= 2200):
            raise DecodeError("bad_field", f"date={day}/{month}/{year}")
        date = (year, month, day)
    return Zda(talker=talker, time_s=_time(d[0]), date=date)


def _gll(talker: str, d: list[str], n: int) -> Gll:
    if n < 6:
        raise DecodeError("short", f"GLL has {n} fields")
    status = d[5]
    mode = d[6] or None
    valid = status == "A" and mode != "N"
    try:
        lat = _latlon(d[0], d[1], True)
        lon = _latlon(d[2], d[3], False)
    except DecodeError:
        if valid:
            raise
        lat = lon = None
    return Gll(talker=talker, time_s=_time(d[4]), valid=valid, lat_deg=lat, lon_deg=lon)


def _heading(text: str) -> float | None:
    return _nonneg(text, "heading", 360.0)


def _hdt(talker: str, d: list[str], n: int) -> Hdt:
    # $--HDT,x.x,T*hh
    if n < 2:
        raise DecodeError("short", f"HDT has {n} fields")
    if d[1] not in ("T", ""):
        raise DecodeError("bad_field", f"HDT reference={d[1]!r}")
    return Hdt(talker, _heading(d[0]))


_THS_MODES = frozenset("AEMSV")


def _ths(talker: str, d: list[str], n: int) -> Ths:
    # $--THS,x.x,a*hh (NMEA 0183 4.x): heading, mode indicator
    if n < 2:
        raise DecodeError("short", f"THS has {n} fields")
    mode = d[1] or None
    if mode is not None and mode not in _THS_MODES:
        raise DecodeError("bad_field", f"THS mode={mode!r}")
    return Ths(talker, _heading(d[0]), mode)


_DECODERS: dict[str, Callable[[str, list[str], int], NmeaMessage]] = {
    "GGA": _gga,
    "RMC": _rmc,
    "VTG": _vtg,
    "GSA": _gsa,
    "GST": _gst,
    "ZDA": _zda,
    "GLL": _gll,
    "HDT": _hdt,
    "THS": _ths,
}
# The fields each decoder reads: indices below this (a shorter sentence is padded with _PAD).
_NEED = {"GGA": 14, "RMC": 12, "VTG": 9, "GSA": 17, "GST": 8, "ZDA": 6, "GLL": 7, "HDT": 2,
         "THS": 2}


# --------------------------------------------------------------------------- encoder


def with_checksum(body: str) -> bytes:
    """``"GPGGA,..."`` -> ``b"$GPGGA,...*HH\\r\\n"``."""
    return f"${body}*{checksum(body):02X}\r\n".encode("ascii")


def _format_angle(value: float, deg_digits: int, hemis: str) -> tuple[str, str]:
    """Degrees -> (``d..dmm.mmmmmmmm``, hemisphere letter), minutes to 8 decimals."""
    hemi = hemis[0] if value >= 0 else hemis[1]
    a = abs(value)
    d = int(a)
    m = (a - d) * 60.0
    if round(m, 8) >= 60.0:
        d, m = d + 1, 0.0
    return f"{d:0{deg_digits}d}{m:011.8f}", hemi


def format_lat(lat_deg: float) -> tuple[str, str]:
    return _format_angle(lat_deg, 2, "NS")


def format_lon(lon_deg: float) -> tuple[str, str]:
    return _format_angle(lon_deg, 3, "EW")


def format_time(time_s: float) -> str:
    t = round(time_s, 2) % 86400.0
    hh = int(t // 3600)
    mm = int((t - hh * 3600) // 60)
    ss = t - hh * 3600 - mm * 60
    return f"{hh:02d}{mm:02d}{ss:05.2f}"


def format_date(date: tuple[int, int, int]) -> str:
    y, m, d = date
    return f"{d:02d}{m:02d}{y % 100:02d}"
