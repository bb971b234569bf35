"""drivers.capture: the timestamped raw-bytes capture format."""

from __future__ import annotations

import json
import struct
import zlib
from pathlib import Path

import pytest

from drivers.capture import (
    HEADER_CHANNEL,
    MAGIC,
    MAGIC_V1,
    MAX_RECORD,
    RECORD_SYNC,
    CaptureReader,
    CaptureWriter,
    Channel,
    Record,
    is_capture,
)
from fdi.errors import CaptureFormatError
from firmware_host import cli
from firmware_host.devtools.fuzz import run_fuzz
from firmware_host.devtools.rover_sim import RoverScenario, write_run

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
RECORD_OVERHEAD = 2 + 8 + 1 + 2 + 4  # sync, t_us, channel, length, crc32
V1_OVERHEAD = 8 + 1 + 2 + 4


def v1_capture(records: list[Record] = RECORDS, channels: list[Channel] = CHANNELS) -> bytes:
    """A version-1 file, byte for byte as the previous writer made it (still read)."""
    header = {"version": 1, "created_utc": "2026-11-23T15:00:00Z", "note": "v1",
              "channels": [dict(id=i, **c.__dict__) for i, c in enumerate(channels)]}
    blob = json.dumps(header).encode()
    out = bytearray(MAGIC_V1 + struct.pack(">I", len(blob)) + blob)
    for r in records:
        head = struct.pack(">QBH", r.t_us, r.channel, len(r.data))
        out += head + r.data + struct.pack(">I", zlib.crc32(head + r.data))
    return bytes(out)


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
    assert reader.header["version"] == 2 and reader.version == 2
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
    blob = raw[12 : 12 + hlen]
    assert json.loads(blob)["version"] == 2
    (hcrc,) = struct.unpack_from(">I", raw, 12 + hlen)
    assert hcrc == zlib.crc32(raw[: 12 + hlen])  # the header's checksum
    pos = 12 + hlen + 4
    copy_head = RECORD_SYNC + struct.pack(">QBH", 0, HEADER_CHANNEL, hlen)  # its copy
    assert raw[pos : pos + 13] == copy_head and raw[pos + 13 : pos + 13 + hlen] == blob
    pos += RECORD_OVERHEAD + hlen
    body = RECORD_SYNC + struct.pack(">QBH", 5, 0, 3) + b"abc"
    assert raw[pos:] == body + struct.pack(">I", zlib.crc32(body))


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


def _record_offsets(raw: bytes) -> list[int]:
    (hlen,) = struct.unpack_from(">I", raw, 8)
    pos = 12 + hlen + 4 + RECORD_OVERHEAD + hlen  # past the header and its copy
    out = []
    for r in RECORDS:
        out.append(pos)
        pos += RECORD_OVERHEAD + len(r.data)
    return out


@pytest.mark.parametrize("victim", range(len(RECORDS)))
def test_one_damaged_record_is_skipped_and_the_rest_replayed(tmp_path: Path, victim: int) -> None:
    """The issue's field case: one flipped bit lost 4 000 of 6 000 epochs. Now only its record."""
    path = tmp_path / "a.fdicap"
    write(path)
    raw = bytearray(path.read_bytes())
    start = _record_offsets(bytes(raw))[victim]
    for where in (0, 5, 12, RECORD_OVERHEAD - 1):  # sync, time, length, crc: each is found
        damaged = bytearray(raw)
        damaged[start + where] ^= 0x10
        reader = CaptureReader(path, data=bytes(damaged))
        assert list(reader) == RECORDS[:victim] + RECORDS[victim + 1 :], where
        if victim < len(RECORDS) - 1:
            assert reader.corrupt and reader.damaged_regions == 1, where
            assert reader.skipped_bytes == RECORD_OVERHEAD + len(RECORDS[victim].data), where
        else:  # damage in the last record looks like a cut: skipped, counted
            assert reader.corrupt or reader.truncated


def test_inserted_garbage_between_records_is_counted(tmp_path: Path) -> None:
    path = tmp_path / "a.fdicap"
    write(path)
    raw = path.read_bytes()
    at = _record_offsets(raw)[2]
    junk = b"\x00garbage" + RECORD_SYNC + b"\xff" * 20  # a sync marker in the junk, too
    reader = CaptureReader(path, data=raw[:at] + junk + raw[at:])
    assert list(reader) == RECORDS
    assert (reader.skipped_bytes, reader.damaged_regions) == (len(junk), 1)


def test_version_1_is_still_read(tmp_path: Path) -> None:
    path = tmp_path / "old.cap"
    raw = v1_capture()
    path.write_bytes(raw)
    assert is_capture(path)
    reader = CaptureReader(path)
    assert reader.version == 1 and reader.channels == CHANNELS and list(reader) == RECORDS
    # A cut inside the last record: the rest is read, truncated reported.
    last = V1_OVERHEAD + len(RECORDS[-1].data)
    for cut in range(len(raw) - last + 1, len(raw)):
        reader = CaptureReader(path, data=raw[:cut])
        assert list(reader) == RECORDS[:-1] and reader.truncated and not reader.corrupt
    # Version 1 has no sync marker: a bad record still ends the read (as it always did).
    (hlen,) = struct.unpack_from(">I", raw, 8)
    damaged = bytearray(raw)
    damaged[12 + hlen + V1_OVERHEAD + len(RECORDS[0].data) + 13] ^= 0x10
    reader = CaptureReader(path, data=bytes(damaged))
    assert list(reader) == RECORDS[:1] and reader.corrupt


def test_a_changed_letter_in_a_header_key(tmp_path: Path) -> None:
    """The issue's case: `baudratf` crashed replay with a TypeError. Now: recovered, or a
    clear CaptureFormatError, never a traceback."""
    path = tmp_path / "a.fdicap"
    write(path)
    raw = path.read_bytes()
    first = raw.find(b'"baudrate"')
    primary_damaged = raw[:first] + b'"baudratf"' + raw[first + 10 :]
    reader = CaptureReader(path, data=primary_damaged)
    assert reader.channels == CHANNELS and list(reader) == RECORDS  # from the copy
    assert reader.notes == ["header damaged; read from its copy"]
    (hlen,) = struct.unpack_from(">I", raw, 8)
    in_copy = raw.find(b'"baudrate"', 12 + hlen)
    both = bytearray(primary_damaged)
    both[in_copy + 8] = ord("f")
    with pytest.raises(CaptureFormatError, match=r"damaged header .*no intact copy"):
        CaptureReader(path, data=bytes(both))
    # The copy alone damaged: the header is good, the copy's bytes are skipped and counted.
    copy_damaged = bytearray(raw)
    copy_damaged[in_copy + 8] = ord("f")
    reader = CaptureReader(path, data=bytes(copy_damaged))
    assert list(reader) == RECORDS and reader.skipped_bytes == RECORD_OVERHEAD + hlen
    # Version 1 has no checksum and no copy: a clear error that names the key.
    v1 = v1_capture()
    k = v1.find(b'"baudrate"')
    with pytest.raises(CaptureFormatError, match=r"unknown key.*baudratf"):
        CaptureReader(path, data=v1[:k] + b'"baudratf"' + v1[k + 10 :])
    with pytest.raises(CaptureFormatError, match=r"damaged header.*baudrate"):
        CaptureReader(path, data=v1.replace(b'"baudrate": 9600', b'"baudrate": "96"', 1))


def test_seeded_fuzz_campaign_replays_every_undamaged_record() -> None:
    """Bit flips, overwrites, inserted and deleted bytes, truncations, damaged headers and
    header copies, 1-3 at a time, read with block sizes down to 16 bytes: exactly the
    undamaged records come out, and intact + skipped bytes add up to the file."""
    for seed in (1, 2):
        rep = run_fuzz("capture", max_inputs=3000, seed=seed)
        assert rep["failures"] == 0, rep["examples"][:2]
        got = rep["rejects"]
        assert got["records_replayed"] > 20_000 and got["damaged_regions"] > 1000
        assert got["header_recovered"] > 100 and got["truncated"] > 100


@pytest.mark.parametrize(
    "content",
    [b"", b"FDICAP0", b"FDIXYZ99" + b"\x00" * 8, b"$GPGGA,1*00\r\n" * 4],
)
def test_bad_magic_raises(tmp_path: Path, content: bytes) -> None:
    path = tmp_path / "x.log"
    path.write_bytes(content)
    with pytest.raises(CaptureFormatError, match="bad magic"):
        CaptureReader(path)
    assert not is_capture(path)


def test_damaged_header_and_missing_file_raise(tmp_path: Path) -> None:
    path = tmp_path / "h.fdicap"
    path.write_bytes(MAGIC_V1 + struct.pack(">I", 10) + b"{not json}")
    with pytest.raises(CaptureFormatError, match="damaged header"):
        CaptureReader(path)
    path.write_bytes(MAGIC_V1 + struct.pack(">I", 14) + b'{"version": 2}')
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


def test_replay_of_damaged_captures_from_the_cli(tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    """One flipped bit costs one record (one epoch), not the rest; a header damaged with its
    copy is a one-line error and exit 1, not a traceback."""
    write_run(RoverScenario(rate_hz=5.0, duration_s=60.0, seed=3), tmp_path / "run")
    raw = bytearray((tmp_path / "run" / "rover.cap").read_bytes())
    raw[len(raw) // 3] ^= 0x04
    (tmp_path / "flip.cap").write_bytes(bytes(raw))
    assert cli.main(["replay", str(tmp_path / "flip.cap"), "--out", str(tmp_path / "o"),
                     "--no-pty"]) == 0
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert summary["epochs"] == 299  # of 300
    assert "damaged bytes in 1 place(s) skipped" in summary["input"]["notes"][0]
    both = bytes(raw).replace(b'"baudrate"', b'"baudratf"')  # the header and its copy
    (tmp_path / "hdr.cap").write_bytes(both)
    capsys.readouterr()
    assert cli.main(["replay", str(tmp_path / "hdr.cap"), "--out", str(tmp_path / "o2")]) == 1
    err = capsys.readouterr().err
    assert "damaged header (checksum mismatch) and no intact copy" in err
    assert "Traceback" not in err
