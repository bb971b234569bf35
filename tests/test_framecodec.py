"""Frame codec: round trips and malformed frames from bytes literals."""

from __future__ import annotations

from pathlib import Path

import pytest

from drivers.outland.framecodec import Frame, Framer, decode, encode, load_protocol
from fdi.errors import ConfigError, DecodeError

ROOT = Path(__file__).resolve().parent.parent
PROTO = load_protocol(ROOT / "config" / "protocols" / "outland1000.toml")

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
