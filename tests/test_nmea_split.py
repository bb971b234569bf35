"""The usual sentence is split without pynmea2 (for speed): exactly as pynmea2 splits it.

:func:`drivers.gps.nmea.parse_sentence` with its own split must give the same message, or the
same rejection reason, as with pynmea2's, on random sentences near the usual shape (bad
checksums, stray ``*`` and ``$``, lowercase and proprietary addresses, no comma, non-hex
checksums) and on every line of the corpus.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers.gps import nmea
from drivers.gps.nmea import Ignored, checksum, parse_sentence, with_checksum
from fdi.errors import DecodeError


def _outcome(line: bytes) -> Any:
    try:
        return parse_sentence(line)
    except DecodeError as err:
        return ("DecodeError", err.reason)
    except Ignored as ign:
        return ("Ignored", ign.reason, ign.sentence_type)


def _both(line: bytes, monkeypatch: pytest.MonkeyPatch) -> tuple[Any, Any]:
    own = _outcome(line)
    with monkeypatch.context() as m:
        never: Callable[..., None] = lambda *a: None  # noqa: E731
        m.setattr(nmea, "_split_usual", never)
        m.setattr(nmea, "_FAST", {})  # the usual GGA/RMC/VTG's one match: not pynmea2's either
        theirs = _outcome(line)
    return own, theirs


talkers = st.sampled_from(["GP", "GN", "II", "pG", "PG", "gp", "G1", "Gp"])
kinds = st.sampled_from(["GGA", "RMC", "VTG", "GSA", "GST", "ZDA", "GLL", "HDT", "XYZ"])
field_text = st.text(alphabet="0123456789.,-NSEWAVMT*$ ", max_size=70)


@st.composite
def sentences(draw: st.DrawFn) -> bytes:
    body = draw(talkers) + draw(kinds) + draw(st.sampled_from([",", ""])) + draw(field_text)
    cs = f"{checksum(body):02X}"
    tail = draw(st.sampled_from([cs, cs.lower(), "00", "G1", "+1", " 1", "1 "]))
    return f"{draw(st.sampled_from(['$', '', ' $']))}{body}*{tail}".encode("ascii")


@settings(max_examples=3000, deadline=None)
@given(sentences())
def test_own_split_is_pynmea2s(line: bytes) -> None:
    with pytest.MonkeyPatch.context() as mp:
        own, theirs = _both(line, mp)
    assert own == theirs, line


def test_generated_sentences_take_the_own_split(monkeypatch: pytest.MonkeyPatch) -> None:
    """The fast path is the one taken (else this file would test nothing), where the usual
    sentence's one match (tested below) does not decode it."""
    body = "GPGGA,100000.00,3201.23564283,N,11851.47939600,E,2,09,0.9,8.879,M,3.000,M,1.0,0000"
    line = f"${body}*{checksum(body):02X}".encode()
    calls: list[bytes] = []
    real = nmea._split_usual

    def spy(*args: Any) -> Any:
        calls.append(args[0])
        return real(*args)

    monkeypatch.setattr(nmea, "_split_usual", spy)
    monkeypatch.setattr(nmea, "_FAST", {})
    assert parse_sentence(line) is not None and calls == [line]


def test_corpus_lines_parse_alike(corpus: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    n = 0
    for log in sorted((corpus / "gpsd").glob("*.log")):
        framer = nmea.NmeaFramer()
        for item in framer.feed(log.read_bytes()):
            if isinstance(item, bytes):
                own, theirs = _both(item, monkeypatch)
                assert own == theirs, (log.name, item)
                n += 1
    assert n > 4000


# The usual GGA and RMC decoded from one match (nmea._fast_usual) against the split and
# the decoders: fields of a real sentence replaced by values at and past every limit the fast
# paths check (ranges, forms, signs, empties, hemispheres, modes, station ids).
_USUAL = {
    "GGA": "100000.00,3201.23592477,N,11851.48034561,E,2,09,0.9,11.629,M,3.000,M,1.0,0133",
    "RMC": "100000.00,A,3201.23592477,N,11851.48034561,E,3.918,0.6,120525,,,D",
    "VTG": "0.6,T,,M,3.918,N,7.256,K,D",
}
_ODD = ["", "0", "00", "9", "10", "99", "100", "-0.0", "+1.0", "0.", ".5", "1e3", "nan", "A",
        "N", "S", "E", "W", "V", "M", "K", "T", "D", "1023", "1024", "0999", "12345",
        "235959.99", "240000", "236000.00", "235960.5", "235961.0", "100000.", "1000",
        "9000.0000", "9000.0001", "18000.0001", "8959.9999", "5960.0000", "0000.0000",
        "18000.0000", "17959.99",
        "18060.0", "3201.", "3201.2.3", "999.9", "1000.0", "1000.1", "1852.0", "1853.0",
        "360.0", "360.1", "100000.0", "100000.1", "-12000.0", "-12000.1", "200.0", "-200.1",
        "86400.0", "86401", "010100", "320199", "311280", "000000", "12052"]


@st.composite
def usual_sentences(draw: st.DrawFn) -> bytes:
    kind = draw(st.sampled_from(sorted(_USUAL)))
    fields = _USUAL[kind].split(",")
    for i in range(len(fields)):
        if draw(st.integers(0, 4)) == 0:
            fields[i] = draw(st.sampled_from(_ODD))
    extra = draw(st.sampled_from([[], [""], ["X"]]))
    if draw(st.booleans()) and len(fields) > 1:
        del fields[-1]
    body = draw(st.sampled_from(["GP", "GN", "IN"])) + kind + "," + ",".join(fields + extra)
    return with_checksum(body).rstrip(b"\r\n")


def test_every_field_at_every_odd_value_decodes_alike() -> None:
    """Each field of each usual sentence replaced, one at a time, by each odd value: the one
    match and the decoders give the same message (floats to the bit) or the same refusal."""
    n = 0
    for kind, text in _USUAL.items():
        fields = text.split(",")
        for i in range(len(fields)):
            for value in _ODD:
                line = with_checksum(f"GP{kind}," + ",".join(
                    [*fields[:i], value, *fields[i + 1:]])).rstrip(b"\r\n")
                own, theirs = _outcome(line), _without_fast(line)
                assert own == theirs and repr(own) == repr(theirs), line
                n += 1
    assert n > 2000


def _without_fast(line: bytes) -> Any:
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(nmea, "_FAST", {})
        return _outcome(line)


@settings(max_examples=4000, deadline=None)
@given(usual_sentences())
def test_usual_sentences_in_one_match_are_what_the_decoders_make(line: bytes) -> None:
    own = _outcome(line)
    theirs = _without_fast(line)
    assert own == theirs, line
    if type(own) in (nmea.Gga, nmea.Rmc, nmea.Vtg):  # the floats to the bit (-0.0, 0.0)
        assert [repr(v) for v in own] == [repr(v) for v in theirs], line


def test_the_usual_sentences_take_the_one_match(monkeypatch: pytest.MonkeyPatch) -> None:
    """The one-match path is the one the usual sentences take (else the test above tests
    nothing)."""
    hits: list[Any] = []
    real = nmea._fast_usual

    def spy(*args: Any) -> Any:
        out = real(*args)
        hits.append(out)
        return out

    monkeypatch.setattr(nmea, "_fast_usual", spy)
    for kind, fields in _USUAL.items():
        assert type(parse_sentence(with_checksum(f"GP{kind},{fields}").rstrip(b"\r\n"))
                    ).__name__ == kind.capitalize()
    assert len(hits) == 2 and all(h is not None for h in hits)
