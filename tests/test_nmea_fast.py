"""The codec's fast paths (issue 19: replay throughput) give what the checked paths give.

* the checksum's integer fold is the byte loop's XOR, on every length;
* GGA, RMC and VTG convert the usual sentence at once and hand anything unusual to their
  checked decoders: on random fields near the usual shape, the same message or the same
  rejection (reason and detail) as the checked decoder alone; and the fast path is the one
  the usual sentence takes;
* a sentence is padded only when it is shorter than the fields its decoder reads
  (``_NEED``): a decoder given exactly ``_NEED`` fields reads no further.
"""

from __future__ import annotations

import random
from collections.abc import Callable
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers.gps import nmea
from drivers.gps.nmea import checksum, parse_sentence, with_checksum
from fdi.errors import DecodeError


def _loop_xor(data: bytes) -> int:
    value = 0
    for c in data:
        value ^= c
    return value


def test_checksum_fold_is_the_byte_loop_on_every_length() -> None:
    rng = random.Random(19)
    for n in range(300):
        for _ in range(10):
            data = bytes(rng.randrange(256) for _ in range(n))
            assert checksum(data) == _loop_xor(data), n
    assert checksum("GPGGA,1") == _loop_xor(b"GPGGA,1")


def _outcome(fn: Callable[[str, list[str], int], Any], fields: list[str]) -> Any:
    try:
        return fn("GP", fields + nmea._PAD, len(fields))
    except DecodeError as err:
        return ("DecodeError", err.reason, err.detail)


# Field texts near the usual ones: empty, numbers of every sign and size, non-finite, junk.
TEXTS = ["", "0", "2", "09", "0.9", "-0.0", "-1.5", "9.360", "1e3", "inf", "nan", "-inf",
         "1_0", " 3", "x", "360.0", "360.1", "99", "100", "3201.23598917", "11851.47998684",
         "N", "S", "E", "W", "A", "V", "D", "N ", "M", "K", "T", "100000.00", "235959.99",
         "246000", "120510", "320510", "0133", "9", "-0.5", "5e-324", "1e400"]
field = st.sampled_from(TEXTS)
DECODERS = [(nmea._gga, nmea._gga_checked), (nmea._rmc, nmea._rmc_checked),
            (nmea._vtg, nmea._vtg_checked)]
USUAL = [
    "GPGGA,100000.00,3201.23598917,N,11851.47998684,E,2,09,0.9,9.360,M,3.000,M,1.0,0133",
    "GPRMC,100000.00,A,3201.23598917,N,11851.47998684,E,3.820,0.2,120510,,,D",
    "GPVTG,0.2,T,,M,3.820,N,7.075,K,D",
]


@st.composite
def near_usual(draw: st.DrawFn) -> tuple[int, list[str]]:
    """A usual sentence's fields with a few of them replaced, and perhaps cut short."""
    which = draw(st.sampled_from(range(len(DECODERS))))
    d = USUAL[which].split(",")[1:]
    for _ in range(draw(st.integers(0, 3))):
        d[draw(st.integers(0, len(d) - 1))] = draw(field)
    return which, d[: draw(st.integers(0, len(d)))] if draw(st.booleans()) else d


@settings(max_examples=6000, deadline=None)
@given(near_usual())
def test_fast_decoders_give_what_the_checked_ones_give(case: tuple[int, list[str]]) -> None:
    which, d = case
    fast, checked = DECODERS[which]
    assert _outcome(fast, d) == _outcome(checked, d), d



@pytest.mark.parametrize("which", range(len(DECODERS)))
def test_every_single_field_change_and_cut_alike(which: int) -> None:
    """Every field of the usual sentence replaced by every text above, and every cut."""
    fast, checked = DECODERS[which]
    usual = USUAL[which].split(",")[1:]
    for i in range(len(usual)):
        for text in TEXTS:
            d = list(usual)
            d[i] = text
            assert _outcome(fast, d) == _outcome(checked, d), d
    for n in range(len(usual) + 1):
        assert _outcome(fast, usual[:n]) == _outcome(checked, usual[:n]), n


@pytest.mark.parametrize("body", USUAL)
def test_the_usual_sentence_takes_the_fast_path(body: str,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    kind = body[2:5].lower()
    checked = getattr(nmea, f"_{kind}_checked")
    expected = checked("GP", body.split(",")[1:] + nmea._PAD, len(body.split(",")) - 1)

    def never(*args: Any) -> Any:
        raise AssertionError("the checked decoder was called")

    monkeypatch.setattr(nmea, f"_{kind}_checked", never)
    assert parse_sentence(with_checksum(body).rstrip(b"\r\n")) == expected


def test_decoders_read_no_field_beyond_need() -> None:
    """Each decoder given exactly ``_NEED[kind]`` fields (no padding) decodes as padded."""
    samples = {
        "GGA": USUAL[0], "RMC": USUAL[1], "VTG": USUAL[2],
        "GSA": "GPGSA,A,3,01,02,03,04,05,06,07,08,09,10,11,12,1.5,0.9,1.2",
        "GST": "GPGST,100000.00,0.5,0.3,0.2,10.0,0.3,0.2,0.6",
        "ZDA": "GPZDA,100000.00,12,05,2010,00,00",
        "GLL": "GPGLL,3201.23598917,N,11851.47998684,E,100000.00,A,D",
        "HDT": "GPHDT,123.4,T", "THS": "GPTHS,123.4,A",
    }
    assert set(samples) == set(nmea._NEED) == set(nmea._DECODERS)
    for kind, body in samples.items():
        need = nmea._NEED[kind]
        d = (body.split(",")[1:] + nmea._PAD)[:need]
        decoder = nmea._DECODERS[kind]
        assert decoder("GP", list(d), len(d)) == decoder("GP", d + nmea._PAD, len(d)), kind


def _pos_outcome(fn: Callable[..., Any], *args: str) -> Any:
    try:
        return fn(*args)
    except DecodeError as err:
        return ("DecodeError", err.reason, err.detail)


def _slow_position(lat: str, ns: str, lon: str, ew: str) -> Any:
    return nmea._latlon_of(lat, ns, True), nmea._latlon_of(lon, ew, False)


POSITION_TEXTS = ["3201.23598917", "9000.0000", "9000.0001", "8959.9999999", "0000.0000",
                  "9100.0000", "3260.0000", "3259.99999999", "32a1.2359", "3201", "320.123",
                  "3201.2e-1", "3201.2_3", "3201.nan", "3201.", "-201.2359", "+201.2359",
                  "11851.47998684", "18000.0000", "18000.0001", "17959.999999", "00000.0003",
                  "19000.0000", "11860.0000", "1185.147998", "11851", "1185a.4799", "", " 3201.5"]


def test_position_fast_path_is_the_checked_conversion() -> None:
    """:func:`nmea._position` (GGA and RMC's fast paths) gives what two _latlon give, value
    or rejection, on every pair of the texts above and every hemisphere letter."""
    hemis = ["N", "S", "E", "W", "", "n", "X"]
    for lat in POSITION_TEXTS:
        for lon in POSITION_TEXTS:
            for ns in hemis:
                for ew in ("E", "W", "N", ""):
                    args = (lat, ns, lon, ew)
                    fast = _pos_outcome(nmea._position.__wrapped__, *args)
                    assert fast == _pos_outcome(_slow_position, *args), args
