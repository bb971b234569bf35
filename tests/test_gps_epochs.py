"""drivers.gps.epochs (EpochAssembler, GpsEpoch) and drivers.gps.stream (NmeaStream counters).

Messages are built as the codec's dataclasses (the assembler is pure), except for the
``NmeaStream`` tests, which go from bytes.
"""

from __future__ import annotations

import pytest

from drivers.gps.epochs import EpochAssembler, GpsEpoch
from drivers.gps.nmea import Gga, Gsa, Gst, NmeaMessage, Rmc, Vtg, Zda, with_checksum
from drivers.gps.stream import NmeaStream

DATE = (2020, 3, 18)


def gga(t: float | None, quality: int = 1, talker: str = "GP", lat: float = 48.0) -> Gga:
    return Gga(talker, t, lat, 11.0, quality, 9, 0.9, 500.0, 47.0, 1.5, "0133")


def rmc(t: float | None, valid: bool = True, talker: str = "GP",
        date: tuple[int, int, int] | None = DATE) -> Rmc:
    return Rmc(talker, t, valid, 48.0, 11.0, 2.0, 90.0, date, "D" if valid else "N")


def vtg(speed: float = 3.0, course: float = 45.0) -> Vtg:
    return Vtg("GP", course, speed, "D")


def gsa(hdop: float = 1.1, vdop: float = 1.7) -> Gsa:
    return Gsa("GP", 3, 2.0, hdop, vdop)


def feed_all(asm: EpochAssembler, msgs: list[NmeaMessage]) -> list[GpsEpoch]:
    out: list[GpsEpoch] = []
    for m in msgs:
        out += asm.feed(m)
    return out


def test_sentences_are_grouped_by_fix_time() -> None:
    asm = EpochAssembler()
    msgs: list[NmeaMessage] = []
    for t in (10.0, 10.2, 10.4):
        msgs += [gga(t), rmc(t + 0.0004)]  # within TIME_EPS_S (1 ms): the same fix
    out = feed_all(asm, msgs[:4])
    # Learning: each epoch closes when the next fix time arrives.
    assert [e.utc_s for e in out] == [10.0]
    out += feed_all(asm, msgs[4:])  # RMC learned as the ender: the third closes on its RMC
    assert [e.utc_s for e in out] == [10.0, 10.2, 10.4]
    assert list(asm.flush()) == []
    assert all(e.sentences == ("GGA", "RMC") for e in out)
    assert all(e.valid for e in out)
    assert (asm.duplicates, asm.orphans) == (0, 0)


def test_cycle_ender_learned_after_two_epochs_then_used_at_once() -> None:
    asm = EpochAssembler()
    emitted_at: list[tuple[str, float | None]] = []  # (sentence fed, utc of epoch emitted)
    for t in (1.0, 2.0, 3.0, 4.0):
        for msg in (gga(t), rmc(t), vtg()):
            for ep in asm.feed(msg):
                emitted_at.append((f"{type(msg).__name__}@{t}", ep.utc_s))
    assert asm.ender == "VTG"
    assert emitted_at == [
        ("Gga@2.0", 1.0),  # learning: an epoch ends when the next fix time arrives
        ("Gga@3.0", 2.0),  # second vote for VTG: learned
        ("Vtg@3.0", 3.0),  # from now on the ender closes its own epoch
        ("Vtg@4.0", 4.0),
    ]
    assert list(asm.flush()) == []  # nothing pending: epoch 4 was not held back


def test_ender_not_learned_before_two_consecutive_votes() -> None:
    asm = EpochAssembler()
    feed_all(asm, [gga(1.0), rmc(1.0), vtg(), gga(2.0)])
    assert asm.ender is None  # one vote only


def test_a_type_repeated_in_an_epoch_never_becomes_the_ender() -> None:
    # e.g. a GNSS receiver's GPGSA + BDGSA: GSA is last, but twice per burst.
    asm = EpochAssembler()
    out: list[GpsEpoch] = []
    for t in range(1, 8):
        out += feed_all(asm, [gga(float(t)), rmc(float(t)), gsa(), gsa()])
    assert asm.ender is None
    assert [e.utc_s for e in out] == [float(t) for t in range(1, 7)]  # each waits for the next
    assert asm.duplicates == 7  # the second GSA of each burst is counted, first kept


def test_vtg_and_gsa_attach_to_the_current_epoch() -> None:
    asm = EpochAssembler()
    g = Gga("GP", 5.0, 48.0, 11.0, 2, 9, None, 500.0, 47.0, None, None)  # no HDOP in the GGA
    out = feed_all(asm, [g, rmc(5.0), vtg(speed=3.5, course=270.0), gsa(1.3, 2.4)])
    out += asm.flush()
    (ep,) = out
    assert ep.sentences == ("GGA", "RMC", "VTG", "GSA")
    assert (ep.speed_mps, ep.course_deg) == (3.5, 270.0)  # VTG overrides RMC's 2.0 m/s, 90°
    assert (ep.hdop, ep.vdop) == (1.3, 2.4)  # GSA fills the HDOP the GGA lacked
    assert (ep.quality, ep.num_sats, ep.alt_msl_m, ep.geoid_sep_m) == (2, 9, 500.0, 47.0)
    assert ep.talker == "GP"


def test_gst_sigmas_are_carried() -> None:
    asm = EpochAssembler()
    out = feed_all(asm, [gga(7.0), Gst("GP", 7.0, 0.5, 0.31, 0.29, 0.8)]) + list(asm.flush())
    (ep,) = out
    assert (ep.sd_lat_m, ep.sd_lon_m, ep.sd_alt_m) == (0.31, 0.29, 0.8)


def test_untimed_sentences_without_a_fix_are_orphans() -> None:
    asm = EpochAssembler()
    out = feed_all(asm, [vtg(), gsa(), gga(1.0), rmc(1.0)])
    assert asm.orphans == 2  # the VTG and GSA before any fix time
    assert out == []
    out += feed_all(asm, [gga(2.0)])
    assert [e.sentences for e in out] == [("GGA", "RMC")]
    # A trailing untimed sentence with no fix of its own, at the end of the stream:
    asm2 = EpochAssembler()
    feed_all(asm2, [vtg()])
    assert list(asm2.flush()) == []
    assert asm2.orphans == 1


def test_duplicate_talkers_of_the_same_fix_are_counted_first_kept() -> None:
    asm = EpochAssembler()
    msgs = [gga(1.0, talker="GN", lat=48.0), gga(1.0, talker="GP", lat=49.0), rmc(1.0)]
    out = feed_all(asm, msgs) + list(asm.flush())
    (ep,) = out
    assert asm.duplicates == 1
    assert ep.talker == "GN"
    assert ep.lat_deg == 48.0  # the first one
    assert ep.sentences == ("GGA", "GGA", "RMC")


def test_duplicate_of_the_learned_ender_is_counted_not_a_second_epoch() -> None:
    asm = EpochAssembler()
    out = feed_all(asm, [m for t in (1.0, 2.0, 3.0) for m in (rmc(t), gga(t))])
    assert asm.ender == "GGA"
    out += feed_all(asm, [rmc(4.0), gga(4.0, talker="GN"), gga(4.0, talker="GP"), rmc(5.0)])
    times = [e.utc_s for e in out]
    assert times.count(4.0) == 1, times
    assert asm.duplicates == 1


def test_slower_sentences_after_the_ender_join_their_epoch() -> None:
    asm = EpochAssembler()
    out: list[GpsEpoch] = []
    for tenth in range(30):  # rst39: GGA every 0.1 s, ZDA and RMC once a second, after it
        t = 74490.0 + tenth / 10.0
        msgs: list[NmeaMessage] = [gga(t)]
        if tenth % 10 == 0:
            msgs += [Zda("GP", t, DATE), rmc(t)]
        out += feed_all(asm, msgs)
    out += asm.flush()
    # The first whole second's ZDA+RMC arrive after the epoch closed on the learned GGA
    # ender: they are counted as late and the ender is abandoned (epochs then close when the
    # fix time changes), so the later seconds' RMC joins its epoch.
    assert asm.ender is None
    assert asm.late == 2
    times = [e.utc_s for e in out]
    assert len(times) == len(set(times)) == 30, times
    assert sum(e.speed_mps is not None for e in out) == 2


@pytest.mark.parametrize(
    ("msgs", "valid"),
    [
        ([gga(1.0, quality=0), rmc(1.0, valid=False)], False),  # no fix at all
        ([gga(1.0, quality=0)], False),  # GGA quality 0
        ([rmc(1.0, valid=False)], False),  # RMC V alone
        ([gga(1.0, quality=1), rmc(1.0, valid=False)], False),  # GGA fix, RMC void: not a fix
        ([gga(1.0, quality=4), rmc(1.0)], True),
        ([rmc(1.0)], True),  # RMC alone can carry a fix
    ],
)
def test_void_fixes(msgs: list[NmeaMessage], valid: bool) -> None:
    asm = EpochAssembler()
    (ep,) = feed_all(asm, msgs) + list(asm.flush())
    assert ep.valid is valid
    if valid:
        assert (ep.lat_deg, ep.lon_deg) == (48.0, 11.0)
        assert ep.quality >= 1
    else:
        assert (ep.quality, ep.alt_msl_m) == (0, None)
        assert ep.speed_mps is None  # a void RMC's speed is not passed on


def test_gga_fix_with_void_rmc_carries_no_position() -> None:
    asm = EpochAssembler()
    (ep,) = feed_all(asm, [gga(1.0, quality=1), rmc(1.0, valid=False)]) + list(asm.flush())
    assert not ep.valid
    assert (ep.lat_deg, ep.lon_deg) == (None, None)


def test_date_is_carried_from_rmc_and_zda_to_later_epochs() -> None:
    asm = EpochAssembler()
    msgs: list[NmeaMessage] = [
        gga(1.0),  # no date known yet
        gga(2.0), rmc(2.0, date=(2021, 6, 30)),
        gga(3.0),  # carried from RMC
        gga(4.0), Zda("GP", 4.0, (2021, 7, 1)),
        gga(5.0),  # carried from ZDA
    ]
    out = feed_all(asm, msgs) + list(asm.flush())
    assert [e.date for e in out] == [None, (2021, 6, 30), (2021, 6, 30), (2021, 7, 1), (2021, 7, 1)]


# --------------------------------------------------------------------------- NmeaStream


def nmea(body: str) -> bytes:
    return with_checksum(body)


def good_epoch(hhmmss: str) -> bytes:
    return nmea(
        f"GPGGA,{hhmmss},4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,"
    ) + nmea(f"GPRMC,{hhmmss},A,4807.038,N,01131.000,E,022.4,084.4,230394,003.1,W")


def test_nmea_stream_counts_every_rejection_by_reason() -> None:
    bad_chk = nmea("GPGGA,120003,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,")
    bad_chk = bad_chk[:-4] + b"00\r\n"
    stream = b"".join(
        [
            b"\x00\x00@@noise",  # garbage (the NULs are blanks, '@@noise' is garbage)
            good_epoch("120000"),
            b"$GPGGA,120001,48",  # truncated by the next '$'
            good_epoch("120001"),
            nmea("GPVTG,054.7,T,034.4,M,005.5,N,010.2,K,A"),  # attaches to 120001
            bad_chk,  # bad_checksum
            b"$GPGGA,120003,4807.038,N\r\n",  # no_checksum
            b"$GPGGA,1\x01\r\n",  # bad_chars
            b"$" + b"9" * 300 + b"\r\n",  # too_long
            nmea("GPGGA,120003,4860.000,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,"),  # bad_field
            nmea("GPRMC,120003,A"),  # short
            nmea("GP1GA,120003"),  # parse_error
            nmea("PTNL,GGK,1"),  # ignored
            nmea("GPGSV,3,1,11"),  # ignored
            nmea("GPGSV,3,2,11"),  # ignored
            good_epoch("120002"),
            nmea("GNGGA,120002,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,"),  # duplicate
            b"$GPRMC,1200",  # truncated at the end of the stream
        ]
    )
    s = NmeaStream()
    epochs = [e for i in range(0, len(stream), 7) for e in s.feed(stream[i : i + 7])]
    epochs += s.flush()
    assert [e.utc_s for e in epochs] == [43200.0, 43201.0, 43202.0]
    assert all(e.valid for e in epochs)
    assert epochs[1].speed_mps == pytest.approx(10.2 / 3.6, rel=1e-12)  # from the VTG
    assert s.counters() == {
        "bytes_in": len(stream),
        "sentences": 8,  # 3 GGA + 3 RMC + VTG + GNGGA
        "rejected": {
            "bad_chars": 1,
            "bad_checksum": 1,
            "bad_field": 1,
            "garbage": 1,
            "no_checksum": 1,
            "parse_error": 1,
            "short": 1,
            "too_long": 1,
            "truncated": 2,
        },
        "rejected_total": 10,
        "ignored": {"GPGSV": 2, "PTNL": 1},
        "duplicates": 1,
        "orphans": 0,
        "late": 0,
    }
