"""The GPS receiver driver: a byte stream in, receiver epochs out, every rejection counted.

:class:`NmeaStream` chains the layers — :class:`~drivers.gps.nmea.NmeaFramer` (bytes -> lines),
:func:`~drivers.gps.nmea.parse_sentence` (line -> typed message), and
:class:`~drivers.gps.epochs.EpochAssembler` (messages -> :class:`~drivers.gps.epochs.GpsEpoch`)
— and keeps the counters that the summary shows: bytes in, sentences accepted, lines rejected
by reason, sentences ignored by kind. It does no I/O: the caller reads the port (any URL,
:mod:`drivers.transport`) and feeds the bytes, so a replay, a test and the vehicle run the same
code.
"""

from __future__ import annotations

import logging
from collections import Counter
from collections.abc import Iterator
from typing import cast

from drivers.counters import TopCounter
from drivers.gps.epochs import EpochAssembler, GpsEpoch
from drivers.gps.nmea import MAX_LINE, Ignored, NmeaFramer, Rejected, parse_sentence
from drivers.ratelog import RateLimitedLog
from fdi.errors import DecodeError

log = logging.getLogger("fdi_bridge.gps")

IGNORED_KEYS = 32  # sentence types kept by name in ``ignored``; the rest are counted as "other"


class NmeaStream:
    """Feed bytes, iterate :class:`GpsEpoch`; see the counters for everything thrown away."""

    def __init__(self, max_line: int = MAX_LINE, ratelog: RateLimitedLog | None = None) -> None:
        self.framer = NmeaFramer(max_line)
        self.assembler = EpochAssembler()
        self.bytes_in = 0
        self.sentences = 0
        self.rejected: Counter[str] = Counter()
        # Keyed by the sentence address the input chooses: bounded (top N plus "other").
        self.ignored: Counter[str] = TopCounter(IGNORED_KEYS)
        self.ratelog = ratelog or RateLimitedLog(log)

    def feed(self, data: bytes) -> Iterator[GpsEpoch]:
        self.bytes_in += len(data)
        # The whole block is framed, decoded, counted and assembled first, then its epochs
        # are yielded with each rejection logged at its place among them: the same epochs
        # and the same log in the same order, but the decoding runs as one tight loop rather
        # than alternating with the caller's per-epoch work (a replay feeds 64 KiB blocks;
        # the alternation cost about a quarter of its time, in processor caches).
        events: list[GpsEpoch | tuple[str, bytes, str]] = []  # epochs; rejections to log
        push = self.assembler.push
        parse = parse_sentence
        rejected = False
        sentences = self.sentences
        for item in self.framer.feed(data):
            if isinstance(item, Rejected):
                self.rejected[item.reason] += 1
                events.append((item.reason, item.data, ""))
                rejected = True
                continue
            try:
                msg = parse(item)
            except DecodeError as err:
                self.rejected[err.reason] += 1
                events.append((err.reason, item, err.detail))
                rejected = True
                continue
            except Ignored as ign:
                self.ignored[ign.sentence_type] += 1
                continue
            sentences += 1
            events += push(msg)
        self.sentences = sentences
        if not rejected:  # epochs only (the usual block)
            yield from cast("list[GpsEpoch]", events)
            return
        for event in events:
            if isinstance(event, GpsEpoch):
                yield event
            else:
                self._log_reject(*event)

    def flush(self) -> Iterator[GpsEpoch]:
        for item in self.framer.flush():
            self._reject(item.reason, item.data)
        yield from self.assembler.flush()

    def _reject(self, reason: str, data: bytes, detail: str = "") -> None:
        self.rejected[reason] += 1
        self._log_reject(reason, data, detail)

    def _log_reject(self, reason: str, data: bytes, detail: str = "") -> None:
        shown = data[:40].decode("ascii", "backslashreplace")
        self.ratelog.warning(f"nmea {reason}", f"{shown!r} {detail}".strip())

    def counters(self) -> dict[str, object]:
        return {
            "bytes_in": self.bytes_in,
            "sentences": self.sentences,
            "rejected": dict(sorted(self.rejected.items())),
            "rejected_total": sum(self.rejected.values()),
            "ignored": dict(sorted(self.ignored.items())),
            "duplicates": self.assembler.duplicates,
            "orphans": self.assembler.orphans,
            "late": self.assembler.late,
        }
