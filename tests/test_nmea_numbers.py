"""Numbers from the wire are checked where they enter (issue 43, item 2).

* the two checksum-valid sentences of the issue (VTG km/h ``1e308``, GST sigma ``1e308``)
  through ``fdi-bridge replay`` (a real process, a real pty): exit 0, every epoch processed,
  the sentence counted as ``bad_field`` and named in the log -- before, "internal error:
  StopIteration" and "internal error: OverflowError";
* NMEA numbers are plain decimals: exponent notation, ``nan``, ``inf``, blanks and ``_``
  (which Python's ``float`` takes) are a ``bad_field`` in every numeric field of every
  supported sentence, read or not;
* the ranges of the fields the bridge reads, at their boundaries; ``-0`` read as 0;
* the GST decoder's fast path gives what its checked path gives.
"""

from __future__ import annotations

import json
import math
import os
import random
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from drivers.gps import nmea
from drivers.gps.nmea import parse_sentence, with_checksum
from fdi.errors import DecodeError
from firmware_host.devtools.rover_sim import RoverScenario, generate

ROOT = Path(__file__).resolve().parents[1]
ENV = dict(os.environ, PYTHONPATH=str(ROOT))


def _line(body: str) -> bytes:
    return with_checksum(body).rstrip(b"\r\n")


def _reason(body: str) -> str:
    try:
        parse_sentence(_line(body))
    except DecodeError as err:
        return err.reason
    return "accepted"


# --------------------------------------------------------------------------- the issue's two


def _session_with(kind: str, field: int, value: str, at: int) -> bytes:
    """A generated 5 Hz session (GST on) whose ``at``-th ``kind`` sentence has ``field``
    (index after the address) replaced by ``value``, the checksum recomputed."""
    sc = RoverScenario(rate_hz=5.0, duration_s=30.0, seed=4, gst=True, zda=True)
    out = []
    seen = 0
    for _, data, _ in generate(sc):
        for line in data.split(b"\r\n"):
            if not line:
                continue
            if line[3:6] == kind.encode():
                seen += 1
                if seen == at:
                    fields = line[1 : line.rindex(b"*")].decode().split(",")
                    fields[field + 1] = value
                    line = _line(",".join(fields))
            out.append(line + b"\r\n")
    assert seen >= at
    return b"".join(out)


@pytest.mark.parametrize(("kind", "field", "name"), [
    ("VTG", 6, "speed_kmh"),  # was: StopIteration at fdi/drift.py (the drift test's reference)
    ("GST", 5, "sd_lat"),  # was: OverflowError at fdi/rover.py (the GST sigma squared)
])
def test_the_issues_sentences_through_replay(kind: str, field: int, name: str,
                                              tmp_path: Path) -> None:
    log = tmp_path / "in.nmea"
    log.write_bytes(_session_with(kind, field, "1e308", at=60))  # 12 s in: drift test running
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, "-m", "firmware_host.cli", "replay", str(log),
                           "--out", str(out)], capture_output=True, text=True, timeout=300,
                          env=ENV, stdin=subprocess.DEVNULL, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "internal error" not in proc.stderr
    assert f"nmea bad_field: '$GP{kind}" in proc.stderr and f"{name}='1e308'" in proc.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["input"]["rejected"] == {"bad_field": 1}
    assert summary["epochs"] == 150  # 30 s at 5 Hz: none lost
    records = (out / "epochs.jsonl").read_text().splitlines()
    assert len(records) == 150
    assert "NaN" not in records[-1] and "Infinity" not in records[-1]


# --------------------------------------------------------------------------- plain decimals

USUAL = {
    "GGA": "GPGGA,100000.00,3201.23598917,N,11851.47998684,E,2,09,0.9,9.360,M,3.000,M,1.0,0133",
    "RMC": "GPRMC,100000.00,A,3201.23598917,N,11851.47998684,E,3.820,0.2,120510,3.1,W,D",
    "VTG": "GPVTG,0.2,T,359.0,M,3.820,N,7.075,K,D",
    "GST": "GPGST,100000.00,0.5,0.3,0.2,10.0,0.3,0.2,0.6",
    "GSA": "GPGSA,A,3,04,05,,09,12,,,24,,,,,2.5,1.3,2.1",
    "ZDA": "GPZDA,100000.00,12,05,2010,00,00",
    "GLL": "GPGLL,3201.23598917,N,11851.47998684,E,100000.00,A,D",
    "HDT": "GPHDT,123.4,T",
    "THS": "GPTHS,123.4,A",
}
# The numeric fields (indices after the address), read by the bridge or not.
NUMERIC = {
    "GGA": (0, 1, 3, 5, 6, 7, 8, 10, 12, 13),
    "RMC": (0, 2, 4, 6, 7, 8, 9),
    "VTG": (0, 2, 4, 6),
    "GST": (0, 1, 2, 3, 4, 5, 6, 7),
    "GSA": tuple(range(1, 17)),
    "ZDA": (0, 1, 2, 3, 4, 5),
    "GLL": (0, 2, 4),
    "HDT": (0,),
    "THS": (0,),
}
NOT_PLAIN = ["1e308", "nan", "inf", "-inf", "NaN", "Infinity", "1E2", "1e0", "0e0", "1_0",
             " 1", "1 ", "0x1F", "5e-324"]


def _with(kind: str, field: int, value: str) -> str:
    fields = USUAL[kind].split(",")
    fields[field + 1] = value
    return ",".join(fields)


def test_no_exponent_nan_inf_blank_or_underscore_in_any_numeric_field() -> None:
    for kind, body in USUAL.items():
        assert _reason(body) == "accepted", body
        for field in NUMERIC[kind]:
            for value in NOT_PLAIN:
                assert _reason(_with(kind, field, value)) == "bad_field", (kind, field, value)


FORMS = [
    ("GPGGA,100000.5e-1,3201.2,N,11851.4,E,1,08,0.9,9.3,M,3.0,M,,", "bad_field"),  # time
    ("GPGGA,100000.00,3201.5e-1,N,11851.4,E,1,08,0.9,9.3,M,3.0,M,,", "bad_field"),  # 0.15'
    ("GPGGA,100000.00,3201.2,N,11851.4_0,E,1,08,0.9,9.3,M,3.0,M,,", "bad_field"),
    ("GPGGA,100000.00,3201.2,N,11851.4,E,1,08,0.9,9.3,M,3.0,M,1.0,TSTR", "bad_field"),
    ("GPRMC,100000.00,A,3201.2,N,11851.4,E,0.5,1e1,120510,,,D", "bad_field"),
    ("GPVTG,1.0,T,,M,0.5,N," + "9" * 60 + ",K,D", "bad_field"),  # plain, out of range
    # What NMEA numbers may look like stays accepted:
    ("GPGGA,100000.00,3201.2,N,11851.4,E,1,+8,0.9,9.3,M,3.0,M,,", "accepted"),  # a sign
    ("GPGGA,100000.00,3201.2,N,11851.4,E,1,08,.9,9.,M,+3.0,M,,", "accepted"),  # x.x forms
    ("GPGGA,100000.00,3201,N,11851,E,1,08,0.9,9.3,M,3.0,M,,", "accepted"),  # no decimals
    ("GPVTG,1.0,T,,M,0.5,N,00000000000000000000000000000000000000000001,K,D", "accepted"),
    ("GPRMC,100000.00,A,3201.2,N,11851.4,E,0.5,1.0,120510,999.9,E,D", "accepted"),  # the
    # corpus's magnetic variation: a field the bridge does not read is checked for form only
    ("GPGST,100000.00,0.5,0.3,0.2,-11.6,0.3,0.2,0.6", "accepted"),  # a corpus orientation
    ("GPGGA,100000.00,3201.2,N,11851.4,E,1,08,0.9,9.3.1,M,3.0,M,,", "bad_field"),
    ("GPGGA,100000.00,3201.2,N,11851.4,E,1,08,0.9,--9,M,3.0,M,,", "bad_field"),
    ("GPGGA,100000.00,3201.2,N,11851.4,E,1,08,0.9,-,M,3.0,M,,", "bad_field"),
]


def test_forms() -> None:
    assert [(body, _reason(body)) for body, _ in FORMS] == FORMS


# --------------------------------------------------------------------------- ranges

# (sentence, field, the last value inside, the first outside)
RANGES = [
    ("RMC", 6, "1000.0", "1000.01"),  # speed, knots (nmea.MAX_SPEED_KN)
    ("VTG", 4, "1000", "1000.01"),
    ("VTG", 6, "1852.0", "1852.01"),  # km/h
    ("GST", 1, "100000", "100000.1"),  # sigma, m (nmea.MAX_SIGMA_M)
    ("GST", 5, "100000", "100000.1"),
    ("GST", 6, "0", "-0.1"),
    ("GST", 7, "100000", "100000.1"),
    ("GGA", 7, "1000", "1000.1"),  # HDOP (nmea.MAX_DOP)
    ("GSA", 15, "1000", "1000.1"),
    ("GGA", 8, "-12000", "-12000.1"),  # altitude, m
    ("GGA", 8, "100000", "100000.1"),
    ("GGA", 10, "-200", "-200.1"),  # geoid separation, m
    ("GGA", 12, "86400", "86400.1"),  # DGPS age, s
    ("GGA", 13, "1023", "1024"),  # DGPS station
    # ranges the codec had before, kept
    ("GGA", 6, "99", "100"),  # satellites
    ("GGA", 1, "9000.0000", "9000.0001"),  # latitude
    ("GGA", 3, "18000.0000", "18000.0001"),  # longitude
    ("RMC", 7, "360.0", "360.01"),  # course
    ("VTG", 0, "0", "-0.01"),
    ("HDT", 0, "360", "360.1"),  # heading
]


def test_ranges() -> None:
    got = [(k, f, _reason(_with(k, f, inside)), _reason(_with(k, f, outside)))
           for k, f, inside, outside in RANGES]
    assert got == [(k, f, "accepted", "bad_field") for k, f, _, _ in RANGES]


@pytest.mark.parametrize(("kind", "field", "attr"), [
    ("RMC", 6, "speed_mps"), ("VTG", 6, "speed_mps"), ("VTG", 0, "course_deg"),
    ("GGA", 7, "hdop"), ("GST", 5, "sd_lat_m"), ("HDT", 0, "heading_deg"),
])
def test_minus_zero_is_read_as_zero(kind: str, field: int, attr: str) -> None:
    value = getattr(parse_sentence(_line(_with(kind, field, "-0"))), attr)
    assert value == 0.0 and math.copysign(1.0, value) == 1.0


# --------------------------------------------------------------------------- GST fast path


def _outcome(fn: Any, fields: list[str]) -> Any:
    try:
        return fn("GP", fields + nmea._PAD, len(fields))
    except DecodeError as err:
        return ("DecodeError", err.reason, err.detail)


TEXTS = ["", "0", "0.35", "-0", "-0.0", "1e3", "inf", "nan", "1_0", " 3", "x", "100000",
         "100000.1", "-11.6", "100000.00", "235959.99", "246000", "10.0", "5e-324", "1.", ".5",
         "+1", "--1", "1.2.3"]


def test_gst_fast_path_is_the_checked_decoder() -> None:
    """Every field of the usual GST replaced by every text above, every cut, and 3000
    random combinations (seeded): the same message or the same rejection."""
    usual = USUAL["GST"].split(",")[1:]
    for i in range(len(usual)):
        for text in TEXTS:
            d = list(usual)
            d[i] = text
            assert _outcome(nmea._gst, d) == _outcome(nmea._gst_checked, d), d
    for n in range(len(usual) + 1):
        assert _outcome(nmea._gst, usual[:n]) == _outcome(nmea._gst_checked, usual[:n]), n
    rng = random.Random(43)
    for _ in range(3000):
        d = [rng.choice([*TEXTS, u]) for u in usual]
        assert _outcome(nmea._gst, d) == _outcome(nmea._gst_checked, d), d


def test_usual_gst_takes_the_fast_path(monkeypatch: pytest.MonkeyPatch) -> None:
    expected = parse_sentence(_line(USUAL["GST"]))

    def never(*args: Any) -> Any:
        raise AssertionError("the checked decoder was called")

    monkeypatch.setattr(nmea, "_gst_checked", never)
    assert parse_sentence(_line(USUAL["GST"])) == expected
