"""drivers.capture: the timestamped raw-bytes capture format."""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import pytest

from drivers.capture import (
    MAGIC,
    MAX_RECORD,
    CaptureReader,
    CaptureWriter,
    Channel,
    Record,
    is_capture,
)
from fdi.errors import CaptureFormatError

CHANNELS = [
    Channel("gps", url="/dev/ttyUSB0", baudrate=9600),
    Channel("autopilot", url="socket://127.0.0.1:5760", baudrate=57600, bytesize=7,
            parity="E", stopbits=2.0, direction="tx"),
]
RECORDS = [
    Record(1_700_000_000_000_000, 0, b"$GPGGA,123519,4807.038,N*47\r\n"),
    Record(1_700_000_000_100_000, 1, b"\xfe\x09\x00\x01\x01"),
    Record(1_700_000_000_100_001, 0, b""),  # an empty read is still a record
    Record(1_700_000_000_200_000, 0, bytes(range(256))),
]
RECORD_OVERHEAD = 8 + 1 + 2 + 4  # t_us, channel, length, crc32


def write(path: Path, records: list[Record] = RECORDS) -> None:
    with CaptureWriter(path, CHANNELS, note="bench test") as w:
        for r in records:
            w.write(r.channel, r.data, t_us=r.t_us)


def test_write_read_round_trip(tmp_path: Path) -> None:
    path = tmp_path / "a.fdicap"
    write(path)
    assert is_capture(path)
    reader = CaptureReader(path)
    assert reader.channels == CHANNELS
    assert reader.header["version"] == 1
    assert reader.header["note"] == "bench test"
    assert [c["id"] for c in reader.header["channels"]] == [0, 1]
    assert reader.header["created_utc"].endswith("Z")
    assert list(reader) == RECORDS
    assert (reader.truncated, reader.corrupt) == (False, False)
    assert list(reader) == RECORDS  # the reader can be iterated again


def test_writer_counts_and_layout(tmp_path: Path) -> None:
    path = tmp_path / "a.fdicap"
    with CaptureWriter(path, CHANNELS) as w:
        w.write(0, b"abc", t_us=5)
        assert (w.records, w.bytes_written) == (1, 3)
    raw = path.read_bytes()
    assert raw.startswith(MAGIC)
    (hlen,) = struct.unpack_from(">I", raw, 8)
    rec = raw[12 + hlen :]
    head = struct.pack(">QBH", 5, 0, 3)
    assert rec == head + b"abc" + struct.pack(">I", zlib.crc32(head + b"abc"))


def test_cut_at_every_offset_inside_the_last_record(tmp_path: Path) -> None:
    full = tmp_path / "full.fdicap"
    write(full)
    raw = full.read_bytes()
    last_len = RECORD_OVERHEAD + len(RECORDS[-1].data)
    last_start = len(raw) - last_len
    cut_path = tmp_path / "cut.fdicap"
    # Cut exactly at the record boundary: a clean, shorter capture.
    cut_path.write_bytes(raw[:last_start])
    clean = CaptureReader(cut_path)
    assert list(clean) == RECORDS[:-1]
    assert (clean.truncated, clean.corrupt) == (False, False)
    for cut in range(last_start + 1, len(raw)):
        cut_path.write_bytes(raw[:cut])
        reader = CaptureReader(cut_path)
        assert list(reader) == RECORDS[:-1], cut
        assert reader.truncated, cut
        assert not reader.corrupt, cut


def test_flipped_data_byte_is_corrupt_and_ends_the_read(tmp_path: Path) -> None:
    path = tmp_path / "a.fdicap"
    write(path)
    raw = bytearray(path.read_bytes())
    # Flip one bit in the data of the second record.
    (hlen,) = struct.unpack_from(">I", raw, 8)
    second = 12 + hlen + RECORD_OVERHEAD + len(RECORDS[0].data)
    raw[second + 11 + 2] ^= 0x10
    path.write_bytes(bytes(raw))
    reader = CaptureReader(path)
    assert list(reader) == RECORDS[:1]  # the rest is not trusted
    assert reader.corrupt
    assert not reader.truncated


@pytest.mark.parametrize(
    "content",
    [b"", b"FDICAP0", b"FDICAP02" + b"\x00" * 8, b"$GPGGA,1*00\r\n" * 4],
)
def test_bad_magic_raises(tmp_path: Path, content: bytes) -> None:
    path = tmp_path / "x.log"
    path.write_bytes(content)
    with pytest.raises(CaptureFormatError, match="bad magic"):
        CaptureReader(path)
    assert not is_capture(path)


def test_damaged_header_and_missing_file_raise(tmp_path: Path) -> None:
    path = tmp_path / "h.fdicap"
    path.write_bytes(MAGIC + struct.pack(">I", 10) + b"{not json}")
    with pytest.raises(CaptureFormatError, match="damaged header"):
        CaptureReader(path)
    path.write_bytes(MAGIC + struct.pack(">I", 14) + b'{"version": 2}')
    with pytest.raises(CaptureFormatError, match="unsupported capture version"):
        CaptureReader(path)
    with pytest.raises(CaptureFormatError, match=r"nope\.fdicap"):
        CaptureReader(tmp_path / "nope.fdicap")


def test_records_longer_than_65535_bytes_are_split(tmp_path: Path) -> None:
    path = tmp_path / "big.fdicap"
    data = bytes((i * 7 + i // 256) % 256 for i in range(2 * MAX_RECORD + 1234))
    with CaptureWriter(path, CHANNELS[:1]) as w:
        w.write(0, data, t_us=42)
        assert (w.records, w.bytes_written) == (3, len(data))
    records = list(CaptureReader(path))
    assert [len(r.data) for r in records] == [MAX_RECORD, MAX_RECORD, 1234]
    assert all((r.t_us, r.channel) == (42, 0) for r in records)
    assert b"".join(r.data for r in records) == data
    # Exactly one full record: no empty tail record.
    with CaptureWriter(path, CHANNELS[:1]) as w:
        w.write(0, data[:MAX_RECORD], t_us=1)
    assert [len(r.data) for r in CaptureReader(path)] == [MAX_RECORD]
