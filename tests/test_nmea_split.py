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
from drivers.gps.nmea import Ignored, checksum, parse_sentence
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
    """The fast path is the one taken (else this file would test nothing)."""
    body = "GPGGA,100000.00,3201.23564283,N,11851.47939600,E,2,09,0.9,8.879,M,3.000,M,1.0,0000"
    line = f"${body}*{checksum(body):02X}".encode()
    calls: list[bytes] = []
    real = nmea._split_usual

    def spy(*args: Any) -> Any:
        calls.append(args[0])
        return real(*args)

    monkeypatch.setattr(nmea, "_split_usual", spy)
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
