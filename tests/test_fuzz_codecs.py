"""Property tests (hypothesis, derandomized) for the three input codecs.

Arbitrary bytes, valid frames with bit flips and overwrites, truncations, oversize length
fields and runs of sync bytes, fed in arbitrary chunks: no exception other than the codec's
own rejection escapes, every rejected piece is counted by reason, and the byte counts add up
(the invariants are :mod:`firmware_host.devtools.fuzz`'s, shared with ``fdi-bridge fuzz``).
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from drivers.mavlink.framer import MavFramer
from drivers.mavlink.io import crc_extra_table
from drivers.outland.framecodec import Framer, checksum
from firmware_host.devtools.fuzz import (
    check_mavlink,
    check_nmea,
    check_outland,
    mavlink_corpus,
    mutate,
    nmea_corpus,
    outland_corpus,
    outland_protocol,
    run_fuzz,
)

PROTO = outland_protocol()
NMEA = nmea_corpus()
OUTLAND = outland_corpus(PROTO)
MAV = mavlink_corpus()

SETTINGS = settings(max_examples=150, deadline=None, derandomize=True, database=None,
                    suppress_health_check=[HealthCheck.too_slow])

cuts = st.lists(st.integers(0, 4000), max_size=4)
# (op, position, value): 0 flip a bit, 1 overwrite, 2 truncate, 3 insert sync run, 4 delete
ops = st.lists(st.tuples(st.integers(0, 4), st.integers(0, 10_000), st.integers(0, 255)),
               max_size=5)


def apply(data: bytes, edits: list[tuple[int, int, int]], sync: bytes) -> bytes:
    b = bytearray(data)
    for op, pos, val in edits:
        if not b:
            break
        i = pos % len(b)
        if op == 0:
            b[i] ^= 1 << (val % 8)
        elif op == 1:
            b[i] = val
        elif op == 2:
            del b[i:]
        elif op == 3:
            b[i:i] = sync * (1 + val % 5)
        else:
            del b[i : i + 1 + val % 8]
    return bytes(b)


def frames(corpus: list[bytes]) -> st.SearchStrategy[bytes]:
    return st.lists(st.sampled_from(corpus), min_size=1, max_size=3).map(b"".join)


# --------------------------------------------------------------------------- NMEA


@SETTINGS
@given(st.binary(max_size=400), cuts)
def test_nmea_arbitrary_bytes(data: bytes, c: list[int]) -> None:
    check_nmea(data, c)


@SETTINGS
@given(frames(NMEA), ops, cuts)
def test_nmea_damaged_sentences(data: bytes, edits: list[tuple[int, int, int]],
                                c: list[int]) -> None:
    check_nmea(apply(data, edits, b"$"), c)


@SETTINGS
@given(st.integers(121, 600), st.integers(1, 20), cuts)
def test_nmea_oversize_lines_and_repeated_starts(n: int, dollars: int, c: list[int]) -> None:
    reasons = check_nmea(b"$" * dollars + b"$GPGGA," + b"1" * n + b"\r\n" + NMEA[0], c)
    assert reasons["too_long"] == 1 and reasons["truncated"] == dollars


def test_nmea_valid_stream_has_no_rejects() -> None:
    assert check_nmea(b"".join(NMEA), [17, 400]) == {
        "ignored_proprietary": 1, "ignored_unknown_sentence": 1}


# --------------------------------------------------------------------------- Outland


@SETTINGS
@given(st.binary(max_size=300), cuts)
def test_outland_arbitrary_bytes(data: bytes, c: list[int]) -> None:
    check_outland(data, c, PROTO)


@SETTINGS
@given(frames(OUTLAND), ops, cuts)
def test_outland_damaged_frames(data: bytes, edits: list[tuple[int, int, int]],
                                c: list[int]) -> None:
    check_outland(apply(data, edits, bytes(PROTO.sync)), c, PROTO)


@SETTINGS
@given(st.integers(PROTO.max_payload + 1, 255), st.integers(0, 6))
def test_outland_oversize_length_is_capped_before_the_body(length: int, syncs: int) -> None:
    head = bytes(PROTO.sync) + bytes((1, 0, 0x10, length))
    head += checksum(PROTO.header_checksum, head)  # a valid header claiming too much
    data = bytes(PROTO.sync) * syncs + head + OUTLAND[0]
    framer = Framer(PROTO)
    got = framer.feed(data)
    assert [f.raw for f in got] == [OUTLAND[0]]  # the good frame after it is not swallowed
    assert framer.rejects["too_long"] == 1
    check_outland(data, [3], PROTO)


# --------------------------------------------------------------------------- MAVLink


@SETTINGS
@given(st.binary(max_size=600), cuts)
def test_mavlink_arbitrary_bytes(data: bytes, c: list[int]) -> None:
    check_mavlink(data, c)


@SETTINGS
@given(frames(MAV), ops, cuts)
def test_mavlink_damaged_packets(data: bytes, edits: list[tuple[int, int, int]],
                                 c: list[int]) -> None:
    check_mavlink(apply(data, edits, b"\xfd"), c)


@SETTINGS
@given(st.integers(0, 2**32 - 1))
def test_mavlink_seeded_mutations(seed: int) -> None:
    rng = np.random.default_rng(seed)
    data = mutate(rng, MAV, b"\xfd", [1])
    check_mavlink(data, [int(x) for x in rng.integers(0, len(data) + 1, 2)])


def test_mavlink1_unknown_id_is_not_marked_crc_checked() -> None:
    """Regression (found by the fuzzer): a MAVLink 1 frame with a message id the dialect does
    not know was passed through unchecked but reported ``crc_checked=True``."""
    extras = crc_extra_table()
    unknown = next(i for i in range(256) if i not in extras)
    pkt = bytes([0xFE, 2, 0, 1, 1, unknown, 0xAA, 0xBB, 0x12, 0x34])
    good = MAV[-1]  # a MAVLink 1 heartbeat, CRC-checked
    framer = MavFramer(extras)
    got = framer.feed(good + pkt, boundary=True)  # a datagram: its end closes the frame
    assert [f.crc_checked for f in got] == [True, False]
    assert framer.stats.unchecked == 1
    stream = MavFramer(extras)  # on a stream an unchecked frame is decided by the next byte
    assert [f.crc_checked for f in stream.feed(good + pkt)] == [True]
    assert [f.crc_checked for f in stream.feed(good)] == [False, True]


# --------------------------------------------------------------------------- the command


@pytest.mark.parametrize("codec", ["nmea", "outland", "mavlink"])
def test_fuzz_command_runs_clean(codec: str) -> None:
    rep = run_fuzz(codec, max_inputs=1500, seed=3)
    assert rep["inputs"] == 1500 and rep["failures"] == 0, rep["examples"]
    assert sum(rep["rejects"].values()) > 0  # the mutations do reach the reject paths
