"""True heading (HDT, THS): the decoders on real sentences, and the epoch a heading belongs to."""

from __future__ import annotations

from pathlib import Path

import pytest

from drivers.gps.epochs import EpochAssembler, GpsEpoch
from drivers.gps.nmea import Gga, Hdt, NmeaMessage, Rmc, Ths, parse_sentence, with_checksum
from drivers.gps.stream import NmeaStream
from fdi.errors import DecodeError


def _lines(path: Path, kind: bytes) -> list[bytes]:
    return [ln.strip() for ln in path.read_bytes().splitlines()
            if ln.startswith(b"$") and ln[3:6] == kind]


def test_hdt_from_real_receivers(corpus: Path) -> None:
    """Hemisphere (hemi.log) and OxTS (rst39.log) HDT, empty and with a heading."""
    hemi = corpus / "gpsd" / "hemi.log"
    rst = corpus / "gpsd" / "rst39.log"
    if not hemi.is_file() or not rst.is_file():
        pytest.skip("gpsd's hemi.log / rst39.log (the logs with HDT) are not in the corpus")
    lines = _lines(hemi, b"HDT") + _lines(rst, b"HDT")
    decoded = [parse_sentence(ln) for ln in lines]
    assert all(isinstance(m, Hdt) and m.talker == "GP" for m in decoded)
    headings = {ln: m.heading_deg for ln, m in zip(lines, decoded, strict=True)}
    assert headings[b"$GPHDT,,T*1B"] is None
    assert headings[b"$GPHDT,274.07,T*03"] == pytest.approx(274.07)
    assert headings[b"$GPHDT,25.50,T*37"] == pytest.approx(25.50)
    given = [h for h in headings.values() if h is not None]
    assert len(given) >= 8 and all(0.0 <= h <= 360.0 for h in given)


@pytest.mark.parametrize(
    ("body", "heading", "mode", "valid"),
    [
        ("GPTHS,77.52,A", 77.52, "A", True),
        ("GNTHS,359.99,A", 359.99, "A", True),
        ("GPTHS,77.52,E", 77.52, "E", False),  # estimated (dead reckoning)
        ("GPTHS,77.52,M", 77.52, "M", False),
        ("GPTHS,77.52,S", 77.52, "S", False),
        ("GPTHS,,V", None, "V", False),
        ("GPTHS,12.0,V", 12.0, "V", False),
    ],
)
def test_ths_modes(body: str, heading: float | None, mode: str, valid: bool) -> None:
    msg = parse_sentence(with_checksum(body).strip())
    assert isinstance(msg, Ths)
    assert (msg.heading_deg, msg.mode, msg.valid) == (heading, mode, valid)


@pytest.mark.parametrize(
    ("body", "reason"),
    [
        ("GPHDT,400.0,T", "bad_field"),
        ("GPHDT,-1.0,T", "bad_field"),
        ("GPHDT,12.x,T", "bad_field"),
        ("GPHDT,12.0,M", "bad_field"),  # HDT is true heading: reference T
        ("GPHDT", "short"),
        ("GPTHS,77.52,X", "bad_field"),
        ("GPTHS,nan,A", "bad_field"),
        ("GPTHS,77.52", "short"),
    ],
)
def test_bad_heading_sentences_are_refused(body: str, reason: str) -> None:
    with pytest.raises(DecodeError) as err:
        parse_sentence(with_checksum(body).strip())
    assert err.value.reason == reason


def test_bad_checksum_on_heading() -> None:
    with pytest.raises(DecodeError) as err:
        parse_sentence(b"$GPHDT,274.07,T*04")
    assert err.value.reason == "bad_checksum"


def _gga(t: float) -> Gga:
    return Gga("GP", t, 32.0, 118.0, 1, 9, 0.9, 10.0, 1.0, None, None)


def _feed(msgs: list[NmeaMessage]) -> list[GpsEpoch]:
    asm = EpochAssembler()
    out = [e for m in msgs for e in asm.feed(m)]
    return out + list(asm.flush())


def test_heading_belongs_to_the_epoch_it_arrives_in() -> None:
    epochs = _feed([_gga(1.0), Hdt("GP", 10.0), _gga(2.0), _gga(3.0)])
    assert [e.heading_deg for e in epochs] == [10.0, None, None]
    assert all(e.sentences == ("GGA",) for e in epochs)  # takes no part in grouping


def test_ths_not_valid_means_no_heading_for_its_epoch() -> None:
    epochs = _feed([_gga(1.0), Ths("GP", 10.0, "A"), _gga(2.0), Ths("GP", 20.0, "V"),
                    _gga(3.0), Hdt("GP", 31.0), Ths("GP", 30.0, "E")])
    assert [e.heading_deg for e in epochs] == [10.0, None, None]


def _rmc(t: float) -> Rmc:
    return Rmc("GP", t, True, 32.0, 118.0, 1.0, 45.0, (2024, 6, 3), "A")


def test_trailing_heading_is_learned_as_the_ender() -> None:
    """GGA, RMC, HDT: the epoch waits for its HDT (the learned ender), even when some bursts
    have none; without this the RMC would be learned and each HDT go to the next epoch."""
    msgs: list[NmeaMessage] = []
    for i in range(12):
        msgs += [_gga(float(i)), _rmc(float(i))]
        if i % 3 != 1:
            msgs.append(Hdt("GP", 10.0 * i))
    asm = EpochAssembler()
    epochs = [e for m in msgs for e in asm.feed(m)] + list(asm.flush())
    assert asm.ender == "HDT"
    assert [e.utc_s for e in epochs] == [float(i) for i in range(12)]
    assert [e.heading_deg for e in epochs] == [None if i % 3 == 1 else 10.0 * i
                                               for i in range(12)]


def test_heading_before_the_first_epoch_goes_to_it() -> None:
    epochs = _feed([Hdt("GP", 5.0), _gga(1.0), _gga(2.0)])
    assert [e.heading_deg for e in epochs] == [5.0, None]


def test_hemisphere_log_headings_and_grouping(corpus: Path) -> None:
    """hemi.log: the epochs are the same as without the HDT lines; headings where HDT had one."""
    path = corpus / "gpsd" / "hemi.log"
    if not path.is_file():
        pytest.skip("gpsd's hemi.log is not in the corpus")
    data = path.read_bytes()
    without = b"".join(ln for ln in data.splitlines(keepends=True) if b"HDT," not in ln)

    def run(raw: bytes) -> tuple[list[GpsEpoch], NmeaStream]:
        s = NmeaStream()
        return [*s.feed(raw), *s.flush()], s

    with_hdt, s1 = run(data)
    plain, s2 = run(without)
    assert [e.sentences for e in with_hdt] == [e.sentences for e in plain]
    assert [e.utc_s for e in with_hdt] == [e.utc_s for e in plain]
    assert s1.counters()["orphans"] == s2.counters()["orphans"]
    headings = [e.heading_deg for e in with_hdt if e.heading_deg is not None]
    given = [m.heading_deg for m in map(parse_sentence, _lines(path, b"HDT"))
             if isinstance(m, Hdt) and m.heading_deg is not None]
    assert headings and len(headings) <= len(given)
    assert set(headings) <= set(given)
