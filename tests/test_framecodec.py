"""Frame codec: round trips and malformed frames from bytes literals."""

from __future__ import annotations

import binascii
import struct
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from drivers.checksums import (
    checksum_bytes,
    crc16_ccitt_false,
    crc16_modbus,
    crc32,
)
from drivers.outland.framecodec import (
    Frame,
    Framer,
    Protocol,
    checksum,
    decode,
    encode,
    load_protocol,
)
from fdi.errors import ConfigError, DecodeError

ROOT = Path(__file__).resolve().parent.parent
DEFAULT = load_protocol(ROOT / "config" / "protocols" / "outland1000.toml")
# The literal frames below use the earlier xor8 layout (still offered as data).
PROTO = replace(DEFAULT, header_checksum="xor8", payload_checksum="xor8")

# telemetry: heading 150.25 deg, depth 10 m, pitch -1.5, roll 0.2, status 3, node 1
TEL = bytes.fromhex("f55f01001009b2b13ae8036aff140003e2")


def test_encode_matches_literal_and_round_trips() -> None:
    values = {"heading_deg": 150.25, "depth_m": 10.0, "pitch_deg": -1.5, "roll_deg": 0.2,
              "status": 3}
    assert encode(PROTO, "telemetry", values, node=1) == TEL
    frames = Framer(PROTO).feed(TEL)
    assert len(frames) == 1
    name, got = decode(PROTO, frames[0])
    assert name == "telemetry"
    assert got == pytest.approx(values, abs=1e-9)


def test_thruster_round_trip_negative_values() -> None:
    vals = {"port_pct": -100, "starboard_pct": 100, "lateral_pct": -7, "vertical_pct": 0}
    raw = encode(PROTO, "thrusters", vals, node=2, flags=0x80)
    (fr,) = Framer(PROTO).feed(raw)
    assert (fr.node, fr.flags, fr.msg_id) == (2, 0x80, 0x20)
    assert decode(PROTO, fr) == ("thrusters", pytest.approx(vals))


def test_out_of_range_value_refused() -> None:
    with pytest.raises(ValueError):
        encode(PROTO, "thrusters", {"port_pct": 200, "starboard_pct": 0, "lateral_pct": 0,
                                    "vertical_pct": 0}, node=1)


def test_resync_after_garbage_and_split_feed() -> None:
    fr = Framer(PROTO)
    data = b"\x00\xf5\x12garbage" + TEL + TEL
    out = []
    for i in range(0, len(data), 3):
        out += fr.feed(data[i : i + 3])
    assert [f.raw for f in out] == [TEL, TEL]
    assert fr.rejects["garbage"] == 10


def test_bad_payload_checksum_counted_and_next_frame_kept() -> None:
    bad = TEL[:-1] + bytes([TEL[-1] ^ 0xFF])
    fr = Framer(PROTO)
    out = fr.feed(bad + TEL)
    assert [f.raw for f in out] == [TEL]
    assert fr.rejects["bad_checksum"] == 1


def test_bad_header_checksum() -> None:
    bad = TEL[:6] + bytes([TEL[6] ^ 0x01]) + TEL[7:]
    fr = Framer(PROTO)
    assert fr.feed(bad) == []
    assert fr.rejects["bad_header_checksum"] == 1


def test_too_long_capped_before_body() -> None:
    # length byte 0xFF > max_payload 32: rejected from the header alone, no body awaited
    head = bytes.fromhex("f55f011010ff")
    head += bytes([0xF5 ^ 0x5F ^ 0x01 ^ 0x10 ^ 0x10 ^ 0xFF])
    fr = Framer(PROTO)
    assert fr.feed(head) == []
    assert fr.rejects["too_long"] == 1
    assert fr.feed(TEL) != []  # not stuck waiting for 255 bytes


def test_short_and_unknown_id_rejected_at_decode() -> None:
    short = Frame(1, 0, 0x10, b"\x00\x01", b"")
    with pytest.raises(DecodeError) as ei:
        decode(PROTO, short)
    assert ei.value.reason == "short"
    with pytest.raises(DecodeError) as ei:
        decode(PROTO, Frame(1, 0, 0x77, b"", b""))
    assert ei.value.reason == "unknown_id"


def test_truncated_frame_waits_then_completes() -> None:
    fr = Framer(PROTO)
    assert fr.feed(TEL[:9]) == []
    assert [f.raw for f in fr.feed(TEL[9:])] == [TEL]
    assert sum(fr.rejects.values()) == 0


def test_bad_protocol_file_names_key(tmp_path: Path) -> None:
    p = tmp_path / "p.toml"
    p.write_text('name = "x"\nbyte_order = "middle"\n')
    with pytest.raises(ConfigError) as ei:
        load_protocol(p)
    assert "byte_order" in str(ei.value)


# --------------------------------------------------------------------------- checksums, ranges

CHECK = b"123456789"


@pytest.mark.parametrize(("kind", "value"), [
    ("xor8", b"\x31"),
    ("sum8", b"\xdd"),  # 477 mod 256
    ("crc16_ccitt_false", b"\x29\xb1"),  # CRC RevEng catalogue check values
    ("crc16_modbus", b"\x37\x4b"),  # 0x4B37, sent low byte first
    ("crc32", b"\xcb\xf4\x39\x26"),
    ("none", b""),
])
def test_published_check_values(kind: str, value: bytes) -> None:
    assert checksum_bytes(kind, CHECK) == value  # type: ignore[arg-type]
    assert checksum(kind, CHECK) == value  # type: ignore[arg-type]


def test_crc_values_against_independent_references() -> None:
    rng = np.random.default_rng(5)
    for _ in range(200):
        data = rng.integers(0, 256, int(rng.integers(0, 40)), dtype=np.uint8).tobytes()
        assert crc32(data) == binascii.crc32(data)
        assert crc16_ccitt_false(data) == binascii.crc_hqx(data, 0xFFFF)  # same polynomial
        # MODBUS, bit by bit from its definition (reflected 0x8005, init 0xFFFF)
        crc = 0xFFFF
        for b in data:
            crc ^= b
            for _ in range(8):
                crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
        assert crc16_modbus(data) == crc


@pytest.mark.parametrize("kind", ["crc16_ccitt_false", "crc16_modbus", "crc32"])
def test_crc_layouts_catch_every_bit_flip_pair_and_swap(kind: str) -> None:
    """Exhaustive on one telemetry frame: every 1- and 2-bit error and every swap of two
    adjacent different bytes is rejected (xor8 misses 35 % of same-bit pairs, 91 % of swaps)."""
    proto = replace(DEFAULT, header_checksum=kind, payload_checksum=kind)  # type: ignore[arg-type]
    good = encode(proto, "telemetry", {"heading_deg": 150.25, "depth_m": 10.0, "pitch_deg": -1.5,
                                       "roll_deg": 0.2, "status": 3}, node=1)
    bits = len(good) * 8

    def accepted(frame: bytes) -> bool:
        return any(f.raw == frame for f in Framer(proto).feed(frame))

    assert accepted(good)
    for i in range(bits):
        one = bytearray(good)
        one[i // 8] ^= 1 << (i % 8)
        assert not accepted(bytes(one)), i
        for j in range(i + 1, bits, 3):  # every third second bit: 2-bit errors at all spacings
            two = bytearray(one)
            two[j // 8] ^= 1 << (j % 8)
            assert not accepted(bytes(two)), (i, j)
    for i in range(len(good) - 1):
        if good[i] != good[i + 1]:
            sw = bytearray(good)
            sw[i], sw[i + 1] = sw[i + 1], sw[i]
            assert not accepted(bytes(sw)), i


def test_default_layout_uses_a_crc_and_every_field_has_a_range() -> None:
    assert DEFAULT.header_checksum == DEFAULT.payload_checksum == "crc16_ccitt_false"
    for msg in DEFAULT.messages:
        for f in msg.fields:
            assert f.min is not None and f.max is not None, (msg.name, f.name)


def _raw_telemetry(proto: Protocol, heading_raw: int, depth_raw: int = 1000) -> bytes:
    payload = struct.pack("<HHhhB", heading_raw, depth_raw, 0, 0, 0)
    head = bytes(proto.sync) + bytes((1, 0, 0x10, len(payload)))
    head += checksum(proto.header_checksum, head)
    return head + payload + checksum(proto.payload_checksum, payload)


@pytest.mark.parametrize("raw", [36000, 36001, 40000, 65535])
def test_out_of_range_heading_is_a_rejected_frame_not_a_wrapped_value(raw: int) -> None:
    """Issue 18: 867 raw headings above 360 deg were wrapped by `% 360`."""
    (frame,) = Framer(DEFAULT).feed(_raw_telemetry(DEFAULT, raw))  # the checksums are right
    with pytest.raises(DecodeError) as ei:
        decode(DEFAULT, frame)
    assert ei.value.reason == "out_of_range" and "heading_deg" in ei.value.detail
    _, ok = decode(DEFAULT, Framer(DEFAULT).feed(_raw_telemetry(DEFAULT, 35999))[0])
    assert ok["heading_deg"] == pytest.approx(359.99)
    with pytest.raises(ValueError, match="outside"):
        encode(DEFAULT, "telemetry", {"heading_deg": 360.5, "depth_m": 1.0, "pitch_deg": 0.0,
                                      "roll_deg": 0.0, "status": 0}, node=1)


def test_range_keys_are_validated_at_load(tmp_path: Path) -> None:
    p = tmp_path / "p.toml"
    p.write_text('name = "x"\n[[messages]]\nname = "m"\nid = 1\n'
                 'fields = [{ name = "a", type = "u8", min = 5, max = 1 }]\n')
    with pytest.raises(ConfigError, match="min > max"):
        load_protocol(p)
    p.write_text('name = "x"\n[[messages]]\nname = "m"\nid = 1\n'
                 'fields = [{ name = "a", type = "u8", min = "low" }]\n')
    with pytest.raises(ConfigError, match=r"messages\[0\]\.fields\[0\]\.min"):
        load_protocol(p)
