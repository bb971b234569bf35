"""Output encoding and the never-blocking pty writer."""

from __future__ import annotations

import os

from drivers.gps.nmea import parse_sentence
from firmware_host.rover.outputs import NmeaSink, gps_week_ms, unix_time


def test_pty_output_nobody_reads_drops_and_counts_instead_of_blocking() -> None:
    sink = NmeaSink("pty:")
    try:
        blob = b"$GPGGA,1*00\r\n" * 20000  # 260 kB, far more than a tty buffer holds
        sink.writer.write(blob)
        sink.writer.write(blob)
        assert sink.writer.dropped_bytes > 0
        assert sink.writer.dropped_bytes < 2 * len(blob)
        # What was taken is readable, in order, from the slave side.
        fd = os.open(sink.url, os.O_RDONLY | os.O_NONBLOCK)
        try:
            got = os.read(fd, 100)
        finally:
            os.close(fd)
        assert got.startswith(b"$GPGGA,1*00\r\n")
    finally:
        sink.close()


def test_gps_week_and_leap_seconds() -> None:
    # 2017-01-01 00:00:00 UTC is GPS 2017-01-01 00:00:18 (18 leap seconds since then).
    week, ms = gps_week_ms(unix_time((2017, 1, 1), 0.0))
    assert week == 1930 and ms == 0 * 86400000 + 18000
    # The day before, 17 leap seconds.
    week, ms = gps_week_ms(unix_time((2016, 12, 31), 0.0))
    assert week == 1929 and ms == 6 * 86400000 + 17000


def test_encoded_sentences_parse_back() -> None:
    from drivers.gps.nmea import format_lat, format_lon, with_checksum

    la, ns = format_lat(-33.8688)
    lo, ew = format_lon(151.2093)
    msg = parse_sentence(with_checksum(f"GPGGA,010203.40,{la},{ns},{lo},{ew},6,09,0.9,12.000,M,"
                                       "20.000,M,,").rstrip(b"\r\n"))
    assert abs(msg.lat_deg + 33.8688) < 1e-9 and abs(msg.lon_deg - 151.2093) < 1e-9  # type: ignore[union-attr]
    assert msg.quality == 6  # type: ignore[union-attr]
