"""Bounded per-key tables: top N plus "other" (drivers.counters), and NmeaStream.ignored."""

from __future__ import annotations

import tracemalloc

import numpy as np

from drivers.counters import OTHER, TopCounter
from drivers.gps.nmea import with_checksum
from drivers.gps.stream import IGNORED_KEYS, NmeaStream


def test_top_counter_keeps_the_largest_and_an_exact_total() -> None:
    rng = np.random.default_rng(3)
    c = TopCounter(4)
    truth: dict[str, int] = {}
    heavy = ["GPGSV", "PGRME", "GPTXT"]
    for _ in range(20_000):
        key = heavy[int(rng.integers(3))] if rng.random() < 0.6 else f"P{int(rng.integers(10**6))}"
        c[key] += 1
        truth[key] = truth.get(key, 0) + 1
        assert len(c) <= 2 * 4 + 1
    assert sum(c.values()) == sum(truth.values())
    for k in heavy:  # frequent keys survive every compaction with their exact count
        assert c[k] == truth[k], k
    assert c[OTHER] > 0 and c.folded_keys > 0
    assert sum(v for k, v in c.items() if k != OTHER) + c[OTHER] == 20_000


def test_top_counter_below_the_bound_is_a_plain_counter() -> None:
    c = TopCounter(8)
    for k in "abcabca":
        c[k] += 1
    assert dict(c) == {"a": 3, "b": 2, "c": 2} and OTHER not in c
    c.update(["d", "d"])
    assert c["d"] == 2
    assert c.copy() == c and isinstance(c.copy(), TopCounter)


def test_60000_distinct_unknown_addresses_keep_memory_bounded() -> None:
    """Before the bound: +22 MB for 200 000 proprietary addresses, +5.2 MB for these 60 000
    (measured with a plain Counter in its place); now a few dozen keys."""

    def feed(stream: NmeaStream, start: int, count: int) -> None:
        block = bytearray()
        for i in range(start, start + count):
            block += with_checksum(f"P{i:07d},1,2,3")  # proprietary: ignored, counted by address
            if len(block) > 60_000:
                list(stream.feed(bytes(block)))
                block.clear()
        list(stream.feed(bytes(block)))

    stream = NmeaStream()
    feed(stream, 0, 2_000)  # warm up: the table is at its bound already
    tracemalloc.start()
    try:
        base, _ = tracemalloc.get_traced_memory()
        feed(stream, 2_000, 58_000)
        now, _ = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert sum(stream.ignored.values()) == 60_000  # every sentence counted
    assert len(stream.ignored) <= 2 * IGNORED_KEYS + 1
    assert stream.ignored[OTHER] >= 60_000 - 2 * IGNORED_KEYS
    assert now - base < 200_000, f"memory grew by {now - base} bytes"  # 5.2 MB before
    assert len(stream.counters()["ignored"]) <= 2 * IGNORED_KEYS + 1  # type: ignore[arg-type]
