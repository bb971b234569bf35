"""``fdi-bridge fuzz --seconds N [--codec nmea|outland|mavlink|capture]``: a seeded mutation fuzzer.

``--codec capture`` damages generated capture files instead (see :class:`CaptureCase`),
``fdi-bridge fuzz --checksums`` measures undetected corrupt Outland frames per checksum
(:func:`checksum_strength`), and ``fdi-bridge fuzz --pipeline [-n N]`` fuzzes the whole rover
pipeline (:func:`run_pipeline_fuzz`): sentences of clean generated sessions with their fields
replaced by ``1e308``, ``nan``, ``inf``, ``-0``, huge and boundary numbers, exponent forms,
garbage (or cut, shortened, readdressed), their checksums recomputed so that they pass the
framer, fed to the :class:`~firmware_host.rover.pipeline.RoverPipeline` that ``replay`` feeds,
with all its outputs (records, corrected NMEA, GPS_INPUT). It counts exceptions (0 expected),
broken invariants (a record with NaN or Infinity, own NMEA output the codec refuses, an output
error, a sentence not counted exactly once) and the refused and accepted inputs; before that,
:func:`field_table` puts each of ``1e308``, ``nan``, ``inf`` in each numeric field of every
supported sentence once and checks that each is counted as one ``bad_field``.

For each codec, inputs are built from a corpus of valid frames (NMEA sentences from the rover
generator plus every supported type, Outland telemetry and thruster frames from the protocol
description, MAVLink 1/2 packets from :class:`drivers.mavlink.io.MavPacker`, signed ones too)
by seeded mutations: bit flips, byte overwrites, truncations, deletions, duplicated and spliced
frames, runs of sync/start bytes, oversize length fields, random bytes. Each input goes
through the framer in random chunks and through the parser/decoder, and the invariants of
:func:`check_nmea`, :func:`check_outland`, :func:`check_mavlink` are checked:

* no exception other than the codec's own rejection (``DecodeError``/``Ignored``) escapes;
* every rejected piece is counted by reason, and the bytes add up where the framer's design
  allows: Outland ``bytes in = bytes in frames + bytes rejected + bytes buffered``; MAVLink
  ``bytes in = bytes in frames + bytes dropped + bytes pending`` with the drops by reason
  summing to the total; NMEA (which skips line ends and blanks by design) every ``$`` starts
  exactly one line, accepted or rejected, and the accounted bytes never exceed the input;
* framing does not depend on how the bytes were chunked;
* what the decoders return is in range (finite numbers, latitude/longitude bounds).

A failure is an input that breaks one of these; the first few are kept (hex) in the report.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import io
import itertools
import json
import logging
import math
import time
import traceback
from collections import Counter
from collections.abc import Callable, Iterator
from typing import Any, ClassVar

import numpy as np

from drivers.capture import (
    HEADER_CHANNEL,
    RECORD_SYNC,
    CaptureReader,
    Channel,
    Record,
    encode_header,
    encode_record,
)
from drivers.gps.nmea import (
    Gga,
    Gll,
    Ignored,
    NmeaFramer,
    Rejected,
    Rmc,
    parse_sentence,
    with_checksum,
)
from drivers.gps.stream import NmeaStream
from drivers.mavlink.framer import MAX_FRAME, MavFramer, x25crc
from drivers.mavlink.io import GpsInputFix, MavPacker, crc_extra_table, decode_packet
from drivers.outland.framecodec import Framer, checksum, decode, load_protocol
from drivers.outland.link import Telemetry, ThrusterCommand, encode_command, encode_telemetry
from drivers.ratelog import RateLimitedLog
from fdi.errors import CaptureFormatError, DecodeError
from firmware_host.commands import tables
from firmware_host.commands.checks import output_file_arg, positive_float, positive_int
from firmware_host.devtools.rover_sim import RoverScenario, generate
from firmware_host.rover.outputs import MavlinkGpsSink, encode_nmea
from firmware_host.rover.pipeline import RoverPipeline
from firmware_host.runtime.config import load_config, resolve_protocol
from firmware_host.runtime.mavout import packer_output

CODECS = ("nmea", "outland", "mavlink", "capture")
_quiet_logger = logging.getLogger("fdi_bridge.fuzz.rejects")
_quiet_logger.addHandler(logging.NullHandler())
_quiet_logger.propagate = False  # a million bad sentences are counted, not logged
_QUIET = RateLimitedLog(_quiet_logger, interval_s=1e9)


class InvariantError(AssertionError):
    """An input broke one of the fuzzer's invariants."""


def _require(cond: bool, what: str) -> None:
    if not cond:
        raise InvariantError(what)


def _chunks(data: bytes, cuts: list[int]) -> list[bytes]:
    points = sorted({c % (len(data) + 1) for c in cuts} | {0, len(data)})
    return [data[a:b] for a, b in itertools.pairwise(points)]


# --------------------------------------------------------------------------- corpora


def nmea_corpus() -> list[bytes]:
    sc = RoverScenario(rate_hz=5.0, duration_s=4.0, seed=1, gst=True, zda=True)
    lines: list[bytes] = []
    for _, data, _ in generate(sc):
        lines.extend(x + b"\r\n" for x in data.split(b"\r\n") if x)
    extra = [
        "GPGSA,A,3,04,05,,09,12,,,24,,,,,2.5,1.3,2.1",
        "GPGLL,3201.2345,N,11851.4800,E,100000.00,A,D",
        "GPGLL,,,,,100000.00,V,N",
        "GPRMC,100000.00,V,,,,,,,120510,,,N",
        "GPGGA,100000.00,,,,,0,00,,,M,,M,,",
        "GNGGA,235959.99,8959.9999,S,17959.9999,W,4,12,0.6,-10.5,M,-30.0,M,1.2,0001",
        "PGRME,15.0,M,45.0,M,25.0,M",
        "GPTXT,01,01,02,ANTSTATUS=OK",
        "GPVTG,,T,,M,0.00,N,0.00,K,N",
        "GPZDA,100000.00,12,05,2010,00,00",
    ]
    lines.extend(with_checksum(x) for x in extra)
    return lines


def outland_protocol() -> Any:
    return load_protocol(resolve_protocol("protocols/outland1000.toml", None))  # packaged


def outland_corpus(proto: Any) -> list[bytes]:
    out = []
    for h in (0.0, 123.45, 359.99):
        out.append(encode_telemetry(proto, Telemetry(h, 12.3, -5.0, 3.0, 1), node=1))
    out.append(encode_telemetry(proto, Telemetry(10.0, 0.0), node=7))
    for p, s in ((0, 0), (100, -100), (-37, 42)):
        out.append(encode_command(proto, ThrusterCommand(p, s, 0, 0), node=1, flags=0x80))
    return out


def mavlink_corpus() -> list[bytes]:
    p = MavPacker(1, 191)
    fix = GpsInputFix(1_600_000_000_000_000, 2100, 123456, 3, 32.02, 118.85, 12.0, 0.9, None,
                      1.0, 0.5, None, 0.1, 0.5, 1.0, 9)
    out = [p.send_heartbeat(), p.send_gps_input(fix), p.send_statustext(2, "FDI GPS: test"),
           p.send_statustext(5, "x" * 120), p.request_mode(1, "HOLD"),
           p.send_named_value_float("fdi", 1.5, 1000), p.send_param_value("FDI_A", 0.05, 0, 3)]
    s = MavPacker(1, 191)
    s.setup_signing(bytes(range(32)), link_id=1, timestamp=1000)
    out.append(s.send_heartbeat())
    out.append(s.send_gps_input(fix))
    # MAVLink 1 (0xFE): a HEARTBEAT packed by hand (CRC_EXTRA 50).
    body = bytes([9, 0, 1, 1, 0]) + bytes([0, 0, 0, 0, 18, 8, 0, 0, 3])
    crc = x25crc(body + bytes([50]))
    out.append(bytes([0xFE]) + body + crc.to_bytes(2, "little"))
    return out


# --------------------------------------------------------------------------- mutations


def mutate(rng: np.random.Generator, corpus: list[bytes], sync: bytes, len_offsets: list[int]
           ) -> bytes:
    """A seeded mutation of 1-3 corpus frames (see the module docstring)."""
    n = int(rng.integers(1, 4))
    frames = [corpus[int(rng.integers(len(corpus)))] for _ in range(n)]
    data = bytearray(b"".join(frames))
    for _ in range(int(rng.integers(0, 4))):
        op = int(rng.integers(10))
        if not data:
            data += bytes(rng.integers(0, 256, 8, dtype=np.uint8))
        i = int(rng.integers(len(data)))
        if op == 0:  # bit flip
            data[i] ^= 1 << int(rng.integers(8))
        elif op == 1:  # byte overwrite
            data[i] = int(rng.integers(256))
        elif op == 2:  # truncate
            del data[i:]
        elif op == 3:  # delete a range
            del data[i : i + int(rng.integers(1, 16))]
        elif op == 4:  # repeated sync / start bytes
            data[i:i] = sync * int(rng.integers(1, 6))
        elif op == 5:  # oversize length (where the frame keeps one)
            base = 0
            if len_offsets:
                off = len_offsets[int(rng.integers(len(len_offsets)))]
                base = data.find(sync[:1])
                if base >= 0 and base + off < len(data):
                    data[base + off] = int(rng.choice([255, 254, 128, 65, 33]))
        elif op == 6:  # random bytes inserted
            data[i:i] = bytes(rng.integers(0, 256, int(rng.integers(1, 32)), dtype=np.uint8))
        elif op == 7:  # duplicate a slice
            j = min(len(data), i + int(rng.integers(1, 40)))
            data[i:i] = data[i:j]
        elif op == 8:  # splice with another frame cut anywhere
            other = corpus[int(rng.integers(len(corpus)))]
            data[i:i] = other[: int(rng.integers(len(other) + 1))]
        else:  # line-noise burst: several bytes overwritten
            for k in range(i, min(len(data), i + int(rng.integers(1, 8)))):
                data[k] = int(rng.integers(256))
    if rng.random() < 0.03:
        return bytes(rng.integers(0, 256, int(rng.integers(0, 300)), dtype=np.uint8))
    return bytes(data)


# --------------------------------------------------------------------------- invariants


def check_nmea(data: bytes, cuts: list[int], max_line: int = 120) -> Counter[str]:
    """Framer + parser + stream on ``data`` fed in the pieces ``cuts`` gives; raises on a
    broken invariant; returns the rejections by reason."""
    framer = NmeaFramer(max_line)
    items: list[bytes | Rejected] = []
    for chunk in _chunks(data, cuts):
        items.extend(framer.feed(chunk))
    items.extend(framer.flush())
    whole = NmeaFramer(max_line)
    ref = [*whole.feed(data), *whole.flush()]
    _require(ref == items, "framing depends on chunking")
    reasons: Counter[str] = Counter()
    lines = 0
    accounted = 0
    starts = 0
    for it in items:
        if isinstance(it, Rejected):
            reasons[it.reason] += 1
            accounted += len(it.data)
            if it.reason == "garbage":
                _require(b"$" not in it.data, "garbage holds a '$'")
            else:
                starts += 1
                _require(it.data[:1] == b"$", f"{it.reason} piece does not start at '$'")
            continue
        lines += 1
        starts += 1
        accounted += len(it)
        _require(it[:1] == b"$" and len(it) < max_line, "line not framed at '$' within the cap")
        _require(b"\r" not in it and b"\n" not in it, "line holds a line end")
        try:
            msg = parse_sentence(it)
        except DecodeError as err:
            reasons[err.reason] += 1
            continue
        except Ignored as ign:
            reasons["ignored_" + ign.reason] += 1
            continue
        for v in msg._fields:
            x = getattr(msg, v)
            if isinstance(x, float):
                _require(math.isfinite(x), f"{v} not finite")
        if isinstance(msg, Gga | Rmc | Gll):
            _require(msg.lat_deg is None or -90.0 <= msg.lat_deg <= 90.0, "lat out of range")
            _require(msg.lon_deg is None or -180.0 <= msg.lon_deg <= 180.0, "lon out of range")
    _require(data.count(b"$") == starts, "a '$' did not start exactly one line")
    _require(accounted <= len(data), "accounted more bytes than came in")
    # The stream counts every framed item exactly once (accepted, rejected or ignored).
    stream = NmeaStream(max_line, _QUIET)
    for chunk in _chunks(data, cuts):
        for _ in stream.feed(chunk):
            pass
    for _ in stream.flush():
        pass
    counted = stream.sentences + sum(stream.rejected.values()) + sum(stream.ignored.values())
    _require(counted == len(items), f"stream counted {counted} of {len(items)} items")
    _require(stream.bytes_in == len(data), "stream bytes_in")
    return reasons


def check_outland(data: bytes, cuts: list[int], proto: Any) -> Counter[str]:
    framer = Framer(proto)
    frames = []
    for chunk in _chunks(data, cuts):
        frames.extend(framer.feed(chunk))
    whole = Framer(proto)
    _require(whole.feed(data) == frames, "framing depends on chunking")
    framed = sum(len(f.raw) for f in frames)
    rejected = sum(framer.rejects.values())
    _require(framed + rejected + len(framer.buf) == len(data),
             f"bytes: {len(data)} in != {framed} framed + {rejected} rejected "
             f"+ {len(framer.buf)} buffered")
    reasons = Counter(framer.rejects)
    for f in frames:
        _require(len(f.payload) <= proto.max_payload, "payload over the cap")
        _require(f.raw[: len(proto.sync)] == bytes(proto.sync), "frame without sync")
        pcs = proto.payload_cs_len
        _require(checksum(proto.payload_checksum, f.payload) == f.raw[len(f.raw) - pcs :],
                 "payload checksum")
        try:
            _, values = decode(proto, f)
        except DecodeError as err:
            reasons[err.reason] += 1
            continue
        _require(all(isinstance(v, float) for v in values.values()), "decoded value type")
    return reasons


def check_mavlink(data: bytes, cuts: list[int]) -> Counter[str]:
    extras = crc_extra_table()
    framer = MavFramer(extras)
    frames = []
    for chunk in _chunks(data, cuts):
        frames.extend(framer.feed(chunk))
    whole = MavFramer(extras)
    _require(whole.feed(data) == frames, "framing depends on chunking")
    st = framer.stats
    framed = sum(len(f.raw) for f in frames)
    _require(st.bytes_in == len(data), "bytes_in")
    _require(framed + st.dropped_bytes + framer.pending == len(data),
             f"bytes: {len(data)} in != {framed} framed + {st.dropped_bytes} dropped "
             f"+ {framer.pending} pending")
    _require(sum(st.by_reason.values()) == st.dropped_bytes, "drops by reason != dropped")
    _require(st.frames == len(frames), "frame count")
    for f in frames:
        _require(len(f.raw) <= MAX_FRAME, "frame over 280 bytes")
        if f.crc_checked:
            hl = f.header_len
            plen = f.raw[1]
            crc = x25crc(f.raw[1 : hl + plen] + bytes((extras[f.msgid],)))
            _require(crc == int.from_bytes(f.raw[hl + plen : hl + plen + 2], "little"), "crc")
        decode_packet(f.raw)  # must not raise
    return Counter(st.by_reason)


# --------------------------------------------------------------------------- the capture reader

CAPTURE_OPS = ("bit_flip", "overwrite", "insert", "delete", "truncate", "header", "header_copy")


class CaptureCase:
    """A generated capture damaged by seeded operations that know which records they hit.

    The capture's records are kept as separate byte strings while they are damaged, so every
    operation knows the records it touches (an insertion between two records touches none; a
    deletion touches every record it overlaps); the invariant is that exactly the untouched
    records are replayed, in order, and that the bytes add up (records start + intact records
    + skipped bytes = file length). A header damaged together with its copy must give a
    :class:`CaptureFormatError`, never a crash.
    """

    CHANNELS: ClassVar[list[Channel]] = [
        Channel("gps rx", "/dev/ttyUSB0"),
        Channel("mavlink tx", "udpout:127.0.0.1:14550", 57600, direction="tx"),
    ]

    def __init__(self) -> None:
        self.expected: list[Record] = []
        self.header_lost = False
        self.ops: Counter[str] = Counter()

    def make(self, rng: np.random.Generator) -> bytes:
        n = int(rng.integers(1, 40))
        records = []
        for k in range(n):
            data = rng.integers(0, 256, int(rng.integers(0, 200)), dtype=np.uint8).tobytes()
            if rng.random() < 0.2:  # data that holds the sync marker: resync must not trust it
                cut = int(rng.integers(len(data) + 1))
                data = data[:cut] + RECORD_SYNC + data[cut:]
            records.append(Record(1_700_000_000_000_000 + 1000 * k, int(rng.integers(2)), data))
        head = encode_header(self.CHANNELS, "fuzz", "2026-12-01T00:00:00Z")
        copy_len = len(encode_record(0, HEADER_CHANNEL, b"")) + int.from_bytes(head[8:12], "big")
        primary = bytearray(head[: len(head) - copy_len])
        copy = bytearray(head[len(head) - copy_len :])
        orig = [encode_record(r.t_us, r.channel, r.data) for r in records]
        parts = [bytearray(b) for b in orig]
        before = [b""] * n  # junk inserted between records (damages none)
        primary_hit = copy_hit = False
        tail_cut = n  # records from this index on are cut off
        for _ in range(int(rng.integers(1, 4))):
            op = CAPTURE_OPS[int(rng.integers(len(CAPTURE_OPS)))]
            self.ops[op] += 1
            i = int(rng.integers(n))
            part = parts[i]
            if op in ("bit_flip", "overwrite") and part:
                j = int(rng.integers(len(part)))
                part[j] = part[j] ^ (1 << int(rng.integers(8))) if op == "bit_flip" else int(
                    rng.integers(256))
            elif op == "insert":
                junk = rng.integers(0, 256, int(rng.integers(1, 40)), dtype=np.uint8).tobytes()
                if rng.random() < 0.5:
                    before[i] += junk
                else:
                    j = int(rng.integers(1, max(2, len(part))))
                    part[j:j] = junk
            elif op == "delete":
                span = int(rng.integers(1, 60))
                j = int(rng.integers(len(part))) if part else 0
                k = i
                while span > 0 and k < n:  # the deletion runs on into the next records
                    cut = len(parts[k][j : j + span])
                    del parts[k][j : j + span]
                    span -= cut
                    j = 0
                    k += 1
            elif op == "truncate":
                del part[int(rng.integers(len(part) + 1)) :]
                tail_cut = min(tail_cut, i + 1)
            elif op == "header":
                primary[int(rng.integers(len(primary)))] ^= 1 << int(rng.integers(8))
                primary_hit = True
            else:
                copy[int(rng.integers(len(copy)))] ^= 1 << int(rng.integers(8))
                copy_hit = True
        body = b"".join(before[k] + parts[k] for k in range(tail_cut))
        # Intact: untouched, or touched so that its bytes are all there again (a deleted last
        # byte followed by an equal one); exactly these must be replayed, in order.
        self.expected = [r for k, r in enumerate(records[:tail_cut])
                         if parts[k] == orig[k] or orig[k] in body]
        copy_hit = copy_hit and bytes(copy) != head[len(primary) :]
        primary_hit = primary_hit and bytes(primary) != head[: len(primary)]
        self.header_lost = primary_hit and copy_hit
        return bytes(primary + copy) + body


def check_capture(data: bytes, cuts: list[int], case: CaptureCase) -> Counter[str]:
    """Read ``data`` (block size chosen by ``cuts``); exactly the undamaged records come out."""
    block = 16 + (cuts[0] % 4096 if cuts else 1 << 20)  # small blocks: markers straddle them
    try:
        reader = CaptureReader("fuzz.cap", data=data, block=block)
    except CaptureFormatError as err:
        _require(case.header_lost or "bad magic" in str(err), f"header not recovered: {err}")
        return Counter({"header_lost": 1})
    got = list(reader)
    _require(reader.channels == case.CHANNELS, "channels differ")
    _require(got == case.expected,
             f"replayed {len(got)} records, expected the {len(case.expected)} undamaged ones")
    _require(reader.records_start + reader.good_bytes + reader.skipped_bytes == len(data),
             f"bytes: {reader.records_start} + {reader.good_bytes} good + "
             f"{reader.skipped_bytes} skipped != {len(data)}")
    out: Counter[str] = Counter({"records_replayed": len(got),
                                 "skipped_bytes": reader.skipped_bytes,
                                 "damaged_regions": reader.damaged_regions,
                                 "truncated": int(reader.truncated)})
    if reader.notes:
        out["header_recovered"] += 1
    return out


# --------------------------------------------------------------------------- checksum strength

ERROR_MODELS = ("bit2_random", "bit2_same_bit", "byte_swap", "mutation")


def _corrupt(rng: np.random.Generator, frame: bytes, model: str, corpus: list[bytes]) -> bytes:
    data = bytearray(frame)
    n = len(data)
    if model == "bit2_random":  # two different bits anywhere
        i, j = rng.choice(n * 8, 2, replace=False)
        data[i // 8] ^= 1 << (i % 8)
        data[j // 8] ^= 1 << (j % 8)
    elif model == "bit2_same_bit":  # the same bit in two bytes (a stuck line, a baud glitch)
        i, j = rng.choice(n, 2, replace=False)
        b = 1 << int(rng.integers(8))
        data[i] ^= b
        data[j] ^= b
    elif model == "byte_swap":  # two adjacent different bytes exchanged
        pairs = [k for k in range(n - 1) if data[k] != data[k + 1]]
        k = pairs[int(rng.integers(len(pairs)))]
        data[k], data[k + 1] = data[k + 1], data[k]
    else:
        return mutate(rng, corpus, frame[:2], [4])
    return bytes(data)


def checksum_strength(kinds: tuple[str, ...] = ("xor8", "sum8", "crc16_ccitt_false",
                                                "crc16_modbus", "crc32"),
                      inputs: int = 200_000, seed: int = 0) -> dict[str, Any]:
    """Undetected corrupt Outland frames per checksum and error model.

    For each checksum (header and payload alike, in the protocol file's layout otherwise), valid
    telemetry and thruster frames with random values are corrupted by one error model and fed
    to a fresh framer; a frame it accepts whose bytes are not one of the originals is an
    undetected corrupt frame; ``after_ranges`` counts those that also pass the fields' ranges
    (what reaches the detector)."""
    base = outland_protocol()
    out: dict[str, Any] = {"inputs_per_model": inputs, "seed": seed, "kinds": {}}
    for kind in kinds:
        proto = dataclasses.replace(base, header_checksum=kind, payload_checksum=kind)
        rng = np.random.default_rng(seed)
        frames = []
        for _ in range(256):
            tel = Telemetry(float(rng.uniform(0, 359.99)), float(rng.uniform(0, 300)),
                            float(rng.uniform(-30, 30)), float(rng.uniform(-30, 30)),
                            int(rng.integers(256)))
            frames.append(encode_telemetry(proto, tel, node=1))
            cmd = ThrusterCommand(*(float(x) for x in rng.integers(-100, 101, 4)))
            frames.append(encode_command(proto, cmd, node=1, flags=0x80))
        originals = set(frames)
        res: dict[str, Any] = {}
        for model in ERROR_MODELS:
            undetected = passed_ranges = 0
            worst_heading = 0.0
            for _ in range(inputs):
                good = frames[int(rng.integers(len(frames)))]
                bad = _corrupt(rng, good, model, frames)
                for f in Framer(proto).feed(bad):
                    if f.raw in originals:
                        continue
                    undetected += 1
                    try:
                        name, values = decode(proto, f)
                    except DecodeError:
                        continue
                    passed_ranges += 1
                    if name == "telemetry" and good[4] == 0x10:
                        (g,) = Framer(proto).feed(good)
                        h0 = decode(proto, g)[1]["heading_deg"]
                        err = abs((values["heading_deg"] - h0 + 180.0) % 360.0 - 180.0)
                        worst_heading = max(worst_heading, err)
            res[model] = {"undetected": undetected, "after_ranges": passed_ranges,
                          "rate": undetected / inputs, "worst_heading_error_deg":
                          round(worst_heading, 2)}
        out["kinds"][kind] = res
    return out


# --------------------------------------------------------------------------- the whole pipeline

# The numeric fields of each sentence (indices of the fields after the address): where the
# pipeline fuzzer puts its numbers, and the cases of :func:`field_table`.
NUMERIC_FIELDS: dict[str, tuple[int, ...]] = {
    "GGA": (0, 1, 3, 5, 6, 7, 8, 10, 12, 13),
    "RMC": (0, 2, 4, 6, 7, 8, 9),
    "VTG": (0, 2, 4, 6),
    "GST": (0, 1, 2, 3, 4, 5, 6, 7),
    "GSA": tuple(range(1, 17)),
    "ZDA": (0, 1, 2, 3, 4, 5),
    "GLL": (0, 2, 4),
    "HDT": (0,),
    "THS": (0,),
}
NOT_NUMBERS = ("1e308", "nan", "inf")  # issue 43: each, in each numeric field, is rejected
# What the mutations put into a field: not numbers, numbers Python's float takes and NMEA does
# not write, extreme and boundary numbers (the ranges of drivers/gps/nmea.py), garbage.
FIELD_VALUES = (
    "1e308", "-1e308", "1E308", "1e-308", "5e-324", "1e400", "3.2e1", "1E+2", "0e0",
    "nan", "NaN", "-nan", "NAN", "inf", "-inf", "+inf", "Infinity", "-Infinity", "INF",
    "-0", "-0.0", "+0", "0", "0.0", "00000", ".5", "5.", "-.5", "+1",
    "1" * 60, "9" * 30, "0" * 40 + "1", "99999999999999999999", "-99999999999",
    "4294967296", "18446744073709551616", "-9223372036854775809", "1." + "9" * 50,
    "", "x", "1_0", " 1", "1 ", "0x1F", "1.2.3", "--1", ".", "-", "+", "1e", "e5", "N", "A",
    "360", "360.0", "360.0001", "-0.0001", "1000", "1000.0001", "1852", "1852.01",
    "100000", "100000.1", "-12000", "-12000.1", "200", "200.1", "-200.1", "86400", "86401",
    "1023", "1024", "99", "100", "9", "10", "61", "235959.99", "240000", "246000",
    "9000.0000", "9000.0001", "18000.0000", "18000.0001", "5960.0000", "320510", "000000",
)
PIPELINE_CONFIGS: tuple[str | None, ...] = (None, "rover-paper", "rover-three-zone-paper",
                                            "rover-combined-paper")
# The clean sessions the mutated sentences are put into: (rate Hz, error model, duration s).
PIPELINE_SESSIONS = ((10.0, "gm", 120.0), (5.0, "multipath", 120.0), (1.0, "coarse", 300.0))


def _refuse_constant(name: str) -> Any:
    raise ValueError(f"{name} in a record")


class _RecordCheck(io.StringIO):
    """The pipeline's ``epochs.jsonl``: every line JSON with finite numbers (checked, not
    kept)."""

    def __init__(self) -> None:
        super().__init__()
        self.lines = 0
        self.bad: list[str] = []

    def write(self, s: str) -> int:
        self.lines += 1
        try:
            json.loads(s, parse_constant=_refuse_constant)
        except ValueError as err:
            self.bad.append(f"record: {err}: {s[:200]}")
        return len(s)


class _NmeaEcho:
    """EpochSink: the corrected NMEA :class:`~firmware_host.rover.outputs.NmeaSink` writes,
    parsed back by the codec: the bridge's own output must be sentences it accepts."""

    def __init__(self) -> None:

        self.encode = encode_nmea
        self.bad: list[str] = []

    def emit(self, out: Any) -> None:
        for line in self.encode(out).split(b"\r\n"):
            if line:
                try:
                    parse_sentence(line)
                except (DecodeError, Ignored) as err:
                    self.bad.append(f"own NMEA output refused ({err}): {line[:100]!r}")

    def close(self) -> None:
        pass


def _bodies(data: bytes) -> list[str]:
    """A burst's sentences as bodies (``GPGGA,...``: no ``$``, checksum or line end)."""
    return [line[1 : line.rindex(b"*")].decode("ascii")
            for line in data.split(b"\r\n") if line.startswith(b"$") and b"*" in line]


def _extras(burst: list[str]) -> dict[str, str]:
    """The sentences a session does not have (GSA, GLL, HDT, THS), made to fit its burst."""
    gga = next((b.split(",") for b in burst if b[2:5] == "GGA"), None)
    out = {"GSA": "GPGSA,A,3,04,05,,09,12,,,24,,,,,2.5,1.3,2.1", "HDT": "GPHDT,123.4,T",
           "THS": "GPTHS,123.4,A"}
    if gga is not None and len(gga) > 5:
        out["GLL"] = f"GPGLL,{gga[2]},{gga[3]},{gga[4]},{gga[5]},{gga[1]},A,D"
    return out


def pipeline_sessions(seed: int = 0) -> list[list[list[str]]]:
    """The clean sessions (:data:`PIPELINE_SESSIONS`) as bursts of sentence bodies."""
    out = []
    for k, (rate, model, duration) in enumerate(PIPELINE_SESSIONS):
        sc = RoverScenario(rate_hz=rate, duration_s=duration, seed=seed * 7 + k + 1, gst=True,
                           zda=True, error_model=model)
        out.append([_bodies(data) for _, data, _ in generate(sc)])
    return out


def field_value(rng: np.random.Generator, old: str) -> str:
    """A value for a field that held ``old`` (see :data:`FIELD_VALUES`)."""
    r = rng.random()
    if r < 0.6:
        return FIELD_VALUES[int(rng.integers(len(FIELD_VALUES)))]
    if r < 0.8 and old:  # the field's own value, made into something else
        k = int(rng.integers(6))
        if k == 0:
            return old + ("e0", "E+2", "e-5", "e308")[int(rng.integers(4))]
        if k == 1:
            return ("-", "+", " ", "0")[int(rng.integers(4))] + old
        if k == 2:
            return old + "0" * int(rng.integers(1, 90))
        if k == 3:
            i = int(rng.integers(len(old)))
            return old[:i] + chr(int(rng.integers(0x20, 0x7F))) + old[i + 1 :]
        if k == 4:
            return old[: int(rng.integers(len(old)))]
        return old + "." + "9" * int(rng.integers(1, 40))
    x = float(rng.standard_normal()) * 10.0 ** float(rng.uniform(-12.0, 307.0))
    if rng.random() < 0.5:
        return repr(x)  # exponent notation where repr uses one (and 'inf')
    return f"{x:.{int(rng.integers(0, 12))}f}" if abs(x) < 1e60 else repr(int(x))


def mutate_sentence(rng: np.random.Generator, body: str) -> str:
    """One mutation of a sentence's body; its checksum is computed afterwards (the framer
    and the checksum pass it, the fields are what is tested)."""
    fields = body.split(",")
    kind = fields[0][2:]
    numeric = NUMERIC_FIELDS.get(kind, ())
    op = rng.random()
    if op < 0.8:  # one to three fields replaced, numeric ones mostly
        for _ in range(int(rng.integers(1, 4))):
            if numeric and rng.random() < 0.85:
                i = 1 + numeric[int(rng.integers(len(numeric)))]
            else:
                i = int(rng.integers(1, max(2, len(fields))))
            while i >= len(fields):
                fields.append("")
            fields[i] = field_value(rng, fields[i])
    elif op < 0.87 and len(fields) > 1:  # a field deleted or inserted
        i = int(rng.integers(1, len(fields)))
        if rng.random() < 0.5:
            del fields[i]
        else:
            fields.insert(i, field_value(rng, fields[i]))
    elif op < 0.94:  # cut short
        fields = fields[: int(rng.integers(1, len(fields) + 1))]
    else:  # another sentence's address on these fields
        other = tuple(NUMERIC_FIELDS)[int(rng.integers(len(NUMERIC_FIELDS)))]
        fields[0] = fields[0][:2] + other
    return ",".join(fields)


def _mutated_burst(rng: np.random.Generator, burst: list[str]) -> tuple[bytes, str]:
    """The burst's bytes with one sentence mutated (sometimes an extra sentence, mutated,
    put in at a random place), and that sentence."""
    bodies = list(burst)
    if rng.random() < 0.15 or not bodies:
        extras = _extras(burst)
        kind = tuple(extras)[int(rng.integers(len(extras)))]
        bodies.insert(int(rng.integers(len(bodies) + 1)), extras[kind])
        i = bodies.index(extras[kind])
    else:
        i = int(rng.integers(len(bodies)))
    bodies[i] = mutate_sentence(rng, bodies[i])
    return b"".join(with_checksum(b) for b in bodies), bodies[i]


class PipelineCase:
    """One pipeline as ``replay`` builds it (:class:`~firmware_host.rover.pipeline.RoverPipeline`
    fed received bytes), with every output: ``epochs.jsonl`` records, the corrected NMEA and
    GPS_INPUT (encoded by the MAVLink sink, sent nowhere); and the checks on them."""

    def __init__(self, cfg: Any) -> None:

        self.records = _RecordCheck()
        self.echo = _NmeaEcho()
        self.mav = MavlinkGpsSink(cfg.rover, endpoint=packer_output())
        self.pipeline = RoverPipeline(cfg.rover, jsonl=self.records, sinks=[self.echo, self.mav],
                                      ratelog=_QUIET)
        self.starts = 0  # '$' fed: each starts exactly one line, accepted, rejected or ignored

    def refused(self) -> int:
        """Sentences refused so far (rejected by the framer or the codec, or ignored)."""
        st = self.pipeline.stream
        return sum(st.rejected.values()) + sum(st.ignored.values())

    def feed(self, data: bytes) -> None:
        self.starts += data.count(b"$")
        self.pipeline.feed(data)

    def problems(self) -> list[str]:
        """Broken invariants so far (each reported once)."""
        out = self.records.bad + self.echo.bad
        self.records.bad, self.echo.bad = [], []
        errors = self.pipeline.sink_errors + self.mav.endpoint.counters()["send_errors"]
        if errors:
            out.append(f"{errors} output errors")
            self.pipeline.sink_errors = 0
            self.mav.endpoint.send_errors = 0  # type: ignore[attr-defined]
        return out

    def finish(self) -> list[str]:
        """End of the input: the last epoch, the summary; the checks on both."""
        self.pipeline.finish()
        out = self.problems()
        st = self.pipeline.stream
        items = st.sentences + self.refused() - st.rejected.get("garbage", 0)
        if items != self.starts:
            out.append(f"{self.starts} sentences started, {items} counted")
        try:
            json.dumps(self.pipeline.summary(), allow_nan=False)
        except (TypeError, ValueError) as err:
            out.append(f"summary: {err}")
        return out


def field_table(seed: int = 0) -> dict[str, str]:
    """Each of :data:`NOT_NUMBERS` in each numeric field of every supported sentence, one
    sentence in each epoch of a clean session through the pipeline: the reason it was
    counted under, ``"accepted"``, or what went wrong (an exception, more than one count)."""

    bursts = pipeline_sessions(seed)[0]
    case = PipelineCase(load_config(None))
    out: dict[str, str] = {}
    cases = [(k, i, v) for k, idx in NUMERIC_FIELDS.items() for i in idx for v in NOT_NUMBERS]
    for (kind, i, value), burst in zip(cases, itertools.cycle(bursts), strict=False):
        bodies = list(burst)
        pos = next((j for j, b in enumerate(bodies) if b[2:5] == kind), None)
        if pos is None:
            bodies.append(_extras(burst)[kind])
            pos = len(bodies) - 1
        fields = bodies[pos].split(",")
        while len(fields) <= i + 1:
            fields.append("")
        fields[i + 1] = value
        bodies[pos] = ",".join(fields)
        before = Counter(case.pipeline.stream.rejected)
        key = f"{kind}[{i}]={value}"
        try:
            case.feed(b"".join(with_checksum(b) for b in bodies))
        except Exception as err:
            out[key] = f"exception {type(err).__name__}: {err}"
            case = PipelineCase(load_config(None))
            continue
        delta = Counter(case.pipeline.stream.rejected)
        delta.subtract(before)
        counted = {r: c for r, c in delta.items() if c}
        if not counted:
            out[key] = "accepted"
        elif len(counted) == 1 and sum(counted.values()) == 1:
            out[key] = next(iter(counted))
        else:
            out[key] = f"counted {counted}"
    problems = case.finish()
    if problems:
        out["(invariants)"] = "; ".join(problems[:3])
    return out


def run_pipeline_fuzz(
    *,
    seconds: float | None = None,
    max_inputs: int | None = None,
    seed: int = 0,
    keep: int = 5,
    clock: Callable[[], float] = time.monotonic,
) -> dict[str, Any]:
    """Checksum-valid mutated sentences through the whole pipeline (framer, codec, epochs,
    detector, records, NMEA and MAVLink outputs), one mutated sentence an epoch of a clean
    session, the configurations of :data:`PIPELINE_CONFIGS` in turn; until ``seconds`` or
    ``max_inputs``. Reports inputs, exceptions, broken invariants (records, own outputs,
    counts), and the inputs refused (by reason) and accepted."""

    rng = np.random.default_rng(seed)
    sessions = pipeline_sessions(seed)
    configs = [load_config(name) for name in PIPELINE_CONFIGS]
    n = exceptions = invariant_failures = refused = 0
    examples: list[dict[str, str]] = []
    t0 = clock()
    block = 0

    def done() -> bool:
        if max_inputs is not None:
            return n >= max_inputs
        return seconds is not None and n % 64 == 0 and clock() - t0 >= seconds

    reasons: Counter[str] = Counter()
    while not done():
        cfg = configs[block % len(configs)]
        bursts = sessions[(block // len(configs)) % len(sessions)]
        case = PipelineCase(cfg)
        for burst in bursts:
            if done():
                break
            data, sentence = _mutated_burst(rng, burst)
            before = case.refused()
            n += 1
            try:
                case.feed(data)
            except Exception as err:
                exceptions += 1
                if len(examples) < keep:
                    examples.append({"sentence": sentence, "config": str(cfg.name),
                                     "error": f"{type(err).__name__}: {err}",
                                     "where": traceback.format_exc(limit=-1).strip()[-300:]})
                case = PipelineCase(cfg)  # the pipeline's state is unknown: a new one
                continue
            refused += case.refused() > before
            bad = case.problems()
            if bad:
                invariant_failures += 1
                if len(examples) < keep:
                    examples.append({"sentence": sentence, "config": str(cfg.name),
                                     "error": "; ".join(bad[:3])})
        bad = case.finish()
        if bad:
            invariant_failures += 1
            if len(examples) < keep:
                examples.append({"sentence": "(end of session)", "config": str(cfg.name),
                                 "error": "; ".join(bad[:3])})
        st = case.pipeline.stream
        reasons.update(st.rejected)
        reasons.update({"ignored_" + k: v for k, v in st.ignored.items()})
        block += 1
    elapsed = clock() - t0
    return {"codec": "pipeline", "seed": seed, "inputs": n, "exceptions": exceptions,
            "invariant_failures": invariant_failures, "failures": exceptions + invariant_failures,
            "refused": refused, "accepted": n - refused, "sessions": block,
            "seconds": round(elapsed, 2),
            "inputs_per_s": round(n / elapsed) if elapsed > 0 else None,
            "rejects": dict(sorted(reasons.items())), "examples": examples}


# --------------------------------------------------------------------------- the runner


def make_case(codec: str) -> tuple[Callable[[np.random.Generator], bytes],
                                    Callable[[bytes, list[int]], Counter[str]]]:
    """The input generator and the checker for ``codec``."""
    if codec == "nmea":
        corpus = nmea_corpus()
        return (lambda rng: mutate(rng, corpus, b"$", []), check_nmea)
    if codec == "outland":
        proto = outland_protocol()
        corpus = outland_corpus(proto)
        sync = bytes(proto.sync)
        offs = [len(sync) + 3]  # the length byte
        return (lambda rng: mutate(rng, corpus, sync, offs),
                lambda d, c: check_outland(d, c, proto))
    if codec == "mavlink":
        corpus = mavlink_corpus()
        return (lambda rng: mutate(rng, corpus, b"\xfd", [1]), check_mavlink)
    if codec == "capture":
        case = CaptureCase()  # the generator tells the checker what it damaged
        return (case.make, lambda d, c: check_capture(d, c, case))
    raise ValueError(f"unknown codec {codec!r} (known: {', '.join(CODECS)})")


def run_fuzz(
    codec: str,
    *,
    seconds: float | None = None,
    max_inputs: int | None = None,
    seed: int = 0,
    keep: int = 5,
    clock: Callable[[], float] = time.monotonic,
) -> dict[str, Any]:
    """Fuzz until ``seconds`` or ``max_inputs``; report inputs tried, failures, rejects."""
    gen, check = make_case(codec)
    rng = np.random.default_rng(seed)
    reasons: Counter[str] = Counter()
    failures = 0
    examples: list[dict[str, str]] = []
    n = 0
    byte_count = 0
    t0 = clock()
    while True:
        if max_inputs is not None and n >= max_inputs:
            break
        if seconds is not None and n % 256 == 0 and clock() - t0 >= seconds:
            break
        data = gen(rng)
        cuts = [int(c) for c in rng.integers(0, len(data) + 1, int(rng.integers(0, 4)))]
        n += 1
        byte_count += len(data)
        try:
            reasons.update(check(data, cuts))
        except Exception as err:
            failures += 1
            if len(examples) < keep:
                examples.append({"input": data.hex(), "cuts": json.dumps(cuts),
                                 "error": f"{type(err).__name__}: {err}",
                                 "where": traceback.format_exc(limit=-1).strip()[-300:]})
    elapsed = clock() - t0
    return {"codec": codec, "seed": seed, "inputs": n, "bytes": byte_count,
            "failures": failures, "seconds": round(elapsed, 2),
            "inputs_per_s": round(n / elapsed) if elapsed > 0 else None,
            "rejects": dict(sorted(reasons.items())), "examples": examples}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--seconds", type=positive_float, default=60.0,
                        help="time per codec, s")
    parser.add_argument("-n", "--inputs", type=positive_int, default=None,
                        help="stop after this many inputs per codec (overrides --seconds)")
    parser.add_argument("--codec", choices=CODECS, action="append", default=None,
                        help="codec to fuzz (repeatable; default: all four)")
    parser.add_argument("--seed", type=int, default=0, help="mutation seed")
    parser.add_argument("--out", type=output_file_arg, default=None,
                        help="write the report as JSON to this file")
    parser.add_argument("--json", action="store_true",
                        help="print the reports as JSON (one object per codec) instead of text")
    parser.add_argument("--pipeline", action="store_true",
                        help="fuzz the whole pipeline instead: checksum-valid sentences with "
                             "mutated fields (1e308, nan, inf, -0, huge, garbage, ...) through "
                             "the framer, codec, epochs, detector and outputs, as replay feeds "
                             "them; and each of 1e308/nan/inf in each numeric field once")
    parser.add_argument("--checksums", action="store_true",
                        help="measure undetected corrupt Outland frames per checksum instead "
                             "(--inputs per error model, default 200 000)")


def run(args: argparse.Namespace) -> int:
    if args.checksums:
        rep = checksum_strength(inputs=args.inputs or 200_000, seed=args.seed)
        n = rep["inputs_per_model"]
        print(f"undetected corrupt frames per {n} corrupted frames (after the fields' ranges)")
        print(tables.table(["checksum", *ERROR_MODELS],
                           [[kind, *(f"{r['undetected']} ({r['after_ranges']})"
                                     for r in res.values())]
                            for kind, res in rep["kinds"].items()]))
        if args.out is not None:
            args.out.write_text(json.dumps(rep, indent=2) + "\n")
        return 0
    if args.pipeline:
        return _run_pipeline(args)
    reports = []
    for codec in args.codec or CODECS:
        rep = run_fuzz(codec, seconds=None if args.inputs else args.seconds,
                       max_inputs=args.inputs, seed=args.seed)
        reports.append(rep)
        if args.json:
            print(json.dumps(rep))
            continue
        print(f"{codec}: {rep['inputs']} inputs ({rep['bytes']} bytes) in {rep['seconds']} s, "
              f"{rep['failures']} failures")
        for ex in rep["examples"]:
            print(f"  {ex['error']}\n    input {ex['input'][:160]}")
    if args.out is not None:
        args.out.write_text(json.dumps(reports, indent=2) + "\n")
    return 1 if any(r["failures"] for r in reports) else 0


def _run_pipeline(args: argparse.Namespace) -> int:
    """``fuzz --pipeline``: the field table, then the mutations; 1 on any failure."""
    table = field_table(args.seed)
    missed = {k: v for k, v in table.items() if v != "bad_field"}
    with _quiet("fdi_bridge.rover"):  # the alarms a million bad sentences raise
        rep = run_pipeline_fuzz(seconds=None if args.inputs else args.seconds,
                                max_inputs=args.inputs, seed=args.seed)
    rep["fields"] = {"cases": len(table), "rejected_as_bad_field": len(table) - len(missed),
                     "missed": missed}
    if args.json:
        print(json.dumps(rep))
    else:
        print(f"fields: {len(table) - len(missed)} of {len(table)} (1e308, nan, inf in each "
              "numeric field) rejected and counted as bad_field")
        for key, what in missed.items():
            print(f"  {key}: {what}")
        print(f"pipeline: {rep['inputs']} inputs in {rep['seconds']} s "
              f"({rep['inputs_per_s']}/s), {rep['exceptions']} exceptions, "
              f"{rep['invariant_failures']} broken invariants; {rep['refused']} refused, "
              f"{rep['accepted']} accepted")
        print("  refused by reason: " + ", ".join(f"{k} {v}" for k, v in rep["rejects"].items()))
        for ex in rep["examples"]:
            print(f"  {ex['error'][:200]}\n    after {ex['sentence'][:160]!r} ({ex['config']})")
    if args.out is not None:
        args.out.write_text(json.dumps(rep, indent=2) + "\n")
    return 1 if rep["failures"] or missed else 0


@contextlib.contextmanager
def _quiet(name: str) -> Iterator[None]:
    """Warnings of logger ``name`` off for the block (counted in the report instead)."""
    logger = logging.getLogger(name)
    level = logger.level
    logger.setLevel(logging.ERROR)
    try:
        yield
    finally:
        logger.setLevel(level)
