"""``fdi-bridge fuzz --seconds N [--codec nmea|outland|mavlink]``: a seeded mutation fuzzer.

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
import itertools
import json
import logging
import time
import traceback
from collections import Counter
from collections.abc import Callable
from typing import Any

import numpy as np

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
from fdi.errors import DecodeError
from firmware_host.commands.checks import output_file_arg, positive_float, positive_int
from firmware_host.devtools.rover_sim import RoverScenario, generate
from firmware_host.runtime.config import resolve_protocol

CODECS = ("nmea", "outland", "mavlink")
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
    import math

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
        for v in msg.__slots__:
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
        _require(checksum(proto.payload_checksum, f.payload) == f.raw[-1:], "payload checksum")
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
    parser.add_argument("--inputs", type=positive_int, default=None,
                        help="stop after this many inputs per codec (overrides --seconds)")
    parser.add_argument("--codec", choices=CODECS, action="append", default=None,
                        help="codec to fuzz (repeatable; default: all three)")
    parser.add_argument("--seed", type=int, default=0, help="mutation seed")
    parser.add_argument("--out", type=output_file_arg, default=None,
                        help="write the report as JSON to this file")
    parser.add_argument("--json", action="store_true",
                        help="print the reports as JSON (one object per codec) instead of text")


def run(args: argparse.Namespace) -> int:
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
