""".tlog damage (issue C item 5): one flipped byte loses the record it hit and nothing else.

Before: a flipped length byte made the reader look for a timestamp "within a day" of a garbage
value, losing the rest of the file (173 173 of 346 346 records in the issue's run).
"""

from __future__ import annotations

import os
import struct
from pathlib import Path

import numpy as np
import pytest

from drivers.mavlink import io as mio
from drivers.mavlink.framer import x25crc

ROOT = Path(__file__).resolve().parents[1]
SMALL_TLOG = ROOT.parent / "shared" / "corpus" / "ardusub" / "small.tlog"
T0 = 1_700_000_000_000_000


def _synthetic(n: int = 60, gap_at: int | None = None, gap_us: int = 0) -> list[tuple[int, bytes]]:
    """``n`` records 100 ms apart of HEARTBEAT / STATUSTEXT / ATTITUDE packets (a real outage of
    ``gap_us`` before record ``gap_at``)."""
    packer = mio.MavPacker()
    out: list[tuple[int, bytes]] = []
    t = T0
    for k in range(n):
        if k == gap_at:
            t += gap_us
        kind = k % 3
        if kind == 0:
            raw = packer.send_heartbeat()
        elif kind == 1:
            raw = packer.send_statustext(6, f"record {k}")
        else:
            raw = packer.send_named_value_float("X", float(k), 100 * k)
        out.append((t, raw))
        t += 100_000
    return out


def _tlog(records: list[tuple[int, bytes]]) -> bytes:
    return b"".join(struct.pack(">Q", t) + raw for t, raw in records)


def _check_damage(orig: list[mio.TlogRecord], damaged: bytes, flipped: np.ndarray,
                  path: Path) -> tuple[int, int]:
    """(intact records recovered, intact records) of ``damaged``; asserts that every record
    yielded is byte-identical to the original record at its offset, or holds a flipped byte."""
    starts = np.cumsum([0] + [8 + len(r.raw) for r in orig])
    by_off = {int(starts[k]): r for k, r in enumerate(orig)}
    hit = set((np.searchsorted(starts, flipped, side="right") - 1).tolist())
    intact = {int(starts[k]) for k in range(len(orig)) if k not in hit}
    path.write_bytes(damaged)
    flipped = np.sort(flipped)
    off = got = 0
    for r in mio.iter_tlog(path):
        n = 8 + len(r.raw)
        o = by_off.get(off)
        same = (o is not None and o.t_us == r.t_us and o.raw == r.raw
                and (o.msg is None) == (r.msg is None))
        if same and off in intact:
            got += 1
        else:
            j = int(np.searchsorted(flipped, off))
            assert j < len(flipped) and flipped[j] < off + n, (
                f"record at offset {off} ({len(r.raw)} bytes) is not in the original and holds "
                "no flipped byte: invented")
        off += n
    assert off == len(damaged)  # the records tile the file
    return got, len(intact)


@pytest.mark.parametrize("where", ["magic", "length", "seq", "msgid", "payload", "crc",
                                   "t_high", "t_mid", "t_16s", "t_2s"])
def test_one_flip_loses_only_its_record(tmp_path: Path, where: str) -> None:
    """One flipped byte: every other record comes back whole, and the damaged one is never
    passed on as a good message with a wrong time (a timestamp 16 s or 2 s off is refused,
    as its neighbours agree without it)."""
    recs = _synthetic()
    data = bytearray(_tlog(recs))
    k = 19  # a STATUSTEXT (MAVLink 2), away from both ends
    off = sum(8 + len(raw) for _, raw in recs[:k])
    offset, mask = {"magic": (8, 0x40), "length": (9, 0x40), "seq": (12, 0x40),
                    "msgid": (15, 0x40), "payload": (20, 0x40),
                    "crc": (8 + len(recs[k][1]) - 1, 0x40), "t_high": (0, 0x40),
                    "t_mid": (4, 0x40), "t_16s": (4, 0x01), "t_2s": (5, 0x20)}[where]
    data[off + offset] ^= mask
    path = tmp_path / "one.tlog"
    path.write_bytes(bytes(data))
    got = list(mio.iter_tlog(path))
    good = [(r.t_us, r.raw) for r in got if r.msg is not None]
    if where == "msgid":  # an id the dialect lacks: framed, unchecked, passed as UNKNOWN_<id>
        (unknown,) = [r for r in got if r.msg is not None and r.msg.get_type().startswith("UNK")]
        good.remove((unknown.t_us, unknown.raw))
    assert good == recs[:k] + recs[k + 1 :]
    assert sum(8 + len(r.raw) for r in got) == len(data)


def test_a_real_outage_is_not_damage(tmp_path: Path) -> None:
    """A 10-minute gap (and a 5 s clock step back) in an undamaged file: every record kept,
    and a flip just after the gap still loses only its own record."""
    recs = _synthetic(gap_at=30, gap_us=600_000_000)
    recs[45] = (recs[45][0] - 5_000_000, recs[45][1])
    recs[46:] = [(t - 5_000_000, raw) for t, raw in recs[46:]]
    path = tmp_path / "gap.tlog"
    path.write_bytes(_tlog(recs))
    assert [(r.t_us, r.raw) for r in mio.iter_tlog(path) if r.msg is not None] == recs
    data = bytearray(_tlog(recs))
    off = sum(8 + len(raw) for _, raw in recs[:29])
    data[off + 9] ^= 0x01  # the length of the record before the gap
    path.write_bytes(bytes(data))
    good = [(r.t_us, r.raw) for r in mio.iter_tlog(path) if r.msg is not None]
    assert good == recs[:29] + recs[30:]


def test_unknown_message_after_damage_is_kept_when_the_next_record_chains(
        tmp_path: Path) -> None:
    recs = _synthetic(12)
    raw = bytearray(recs[6][1])
    raw[7:10] = (60_000).to_bytes(3, "little")  # a message id no dialect has: unchecked
    recs[6] = (recs[6][0], bytes(raw))
    data = bytearray(_tlog(recs))
    off = sum(8 + len(r) for _, r in recs[:5])
    data[off + 9] ^= 0x04  # damage the record just before the unknown one
    path = tmp_path / "unk.tlog"
    path.write_bytes(bytes(data))
    got = [(r.t_us, r.raw) for r in mio.iter_tlog(path)]
    assert got[:5] == recs[:5] and got[6:] == recs[6:]


@pytest.mark.skipif(not SMALL_TLOG.exists(), reason=f"corpus capture {SMALL_TLOG} is absent")
@pytest.mark.parametrize("seed", range(int(os.environ.get("FDI_TLOG_FILES", "3"))))
def test_hundred_flips_recover_the_intact_records(tmp_path: Path, seed: int) -> None:
    """The issue's measurement on the ArduSub dive: one byte flipped at 100 seeded places, at
    least 99 % of the records no flip touched come back unchanged, and no record is invented.
    Three files by default; ``FDI_TLOG_FILES=100`` runs the issue's 100 (measured: 100 % of
    the intact records in every file, none invented)."""
    orig = list(mio.iter_tlog(SMALL_TLOG))
    data = SMALL_TLOG.read_bytes()
    rng = np.random.default_rng(seed)
    pos = rng.choice(len(data), 100, replace=False)
    buf = bytearray(data)
    for p in pos:
        buf[p] ^= int(rng.integers(1, 256))
    got, intact = _check_damage(orig, bytes(buf), pos, tmp_path / "d.tlog")
    assert got >= 0.99 * intact, f"{got} of {intact} intact records"


def test_the_readers_crc_is_the_framers() -> None:
    rng = np.random.default_rng(7)
    for n in (0, 1, 9, 40, 280):
        data = rng.integers(0, 256, n, dtype=np.uint8).tobytes()
        assert mio._x25crc(data) == x25crc(data)
