"""The run's two files: ``epochs.jsonl`` (one JSON object a line) and ``summary.json``.

:class:`EpochLog` is the one JSON Lines writer of the runtime: the ROV's records go through
:meth:`EpochLog.write`; the rover pipeline writes its records (the replay contract, in the same
compact encoding) to :attr:`EpochLog.stream`. Without a directory both are no-ops, so a vehicle
never asks whether there is an output.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable
from pathlib import Path
from typing import Any, TextIO

try:  # the ``fast`` extra: a compiled encoder (no wheel on every platform, so optional)
    import orjson as _orjson
except ImportError:  # pragma: no cover - exercised by the tests with the encoder disabled
    _orjson = None  # type: ignore[assignment]

_floor = math.floor
EPOCHS = "epochs.jsonl"
SUMMARY = "summary.json"


def encode_line_stdlib(record: dict[str, Any]) -> str:
    """One line of ``epochs.jsonl`` with the standard library (compact separators, as the
    replay contract has them): the reference encoding."""
    return json.dumps(record, separators=(",", ":")) + "\n"


def _same_in_orjson(value: Any) -> bool:
    """Does orjson write ``value`` byte for byte as :func:`json.dumps` does? True for the
    plain JSON types only (exact types: no subclasses, no numpy scalars), floats that are 0 or
    finite with ``1e-4 <= |x| < 1e16`` (outside that, ``repr`` uses an exponent that orjson
    spells differently, and NaN/Infinity become ``null``), strings of printable ASCII (else
    ``json.dumps`` escapes what orjson writes raw), and dicts with such string keys. Integers
    beyond 64 bits make orjson raise, which falls back too. Checked on generated runs, the
    corpus and random values by tests/test_json_encoding.py."""
    t = type(value)
    if t is float:
        return 1e-4 <= abs(value) < 1e16 or value == 0.0
    if t is str:
        return value.isascii() and value.isprintable()
    if value is None or t is int or t is bool:
        return True
    if t is dict:
        return all(type(k) is str and k.isascii() and k.isprintable() and _same_in_orjson(v)
                   for k, v in value.items())
    if t is list or t is tuple:
        return all(_same_in_orjson(v) for v in value)
    return False


def _flat_same_in_orjson(record: dict[str, Any]) -> bool:
    """:func:`_same_in_orjson` of a record, its scalar values checked inline (the hot path:
    once an epoch); a non-string key makes ``join`` raise TypeError (the caller falls back)."""
    for v in record.values():
        t = type(v)
        if t is float:  # the same test as _same_in_orjson's, without the call to abs
            if not (1e-4 <= v < 1e16 or -1e16 < v <= -1e-4 or v == 0.0):
                return False
        elif t is str:
            if not (v.isascii() and v.isprintable()):
                return False
        elif not (v is None or t is bool or t is int or _same_in_orjson(v)):
            return False
    keys = "".join(record)
    return keys.isascii() and keys.isprintable()


def encode_line(record: dict[str, Any]) -> str:
    """One line of ``epochs.jsonl``, byte-identical to :func:`encode_line_stdlib`: orjson
    (about ten times faster) when it is installed and writes this record the same way, else
    the standard library."""
    if _orjson is not None:
        try:
            if _flat_same_in_orjson(record):
                return _orjson.dumps(record, option=_orjson.OPT_APPEND_NEWLINE).decode()
        except TypeError:  # a non-string key, an integer beyond 64 bits
            pass
    return encode_line_stdlib(record)


def round4(x: float) -> float:
    """``round(x, 4)``, the same float (sign of zero included), in about half its time.

    For ``|y| < 2**31`` with ``y = x * 1e4`` the product is within ``2**-22`` of the exact
    ``x * 10**4``; when the guard accepts ``r = floor(y + 0.5)`` (``|y - r| < 0.4999``, exact
    subtraction), the exact value is within ``0.4999 + 2**-22 < 1/2`` of ``r``, so ``r`` is the
    integer :func:`round` rounds it to (near-ties go to :func:`round` itself); ``r / 1e4`` is
    correctly rounded by the division, as :func:`round`'s decimal string is by its
    conversion back. Zero (its sign), NaN,
    infinities, large values and anything but a float (an int stays an int) go to
    :func:`round`. Tested against :func:`round` on millions of values
    (tests/test_json_encoding.py). The rover's records round about fifteen values an epoch."""
    y = x * 10000.0
    if -2147483648.0 < y < 2147483648.0 and type(x) is float:  # (round keeps an int an int)
        r = _floor(y + 0.5)
        if r and -0.4999 < y - r < 0.4999:
            return r / 10000.0
    return round(x, 4)


def round2(x: float) -> float:
    """``round(x, 2)``, the same float: :func:`round4` with 100 for 10 000."""
    y = x * 100.0
    if -2147483648.0 < y < 2147483648.0 and type(x) is float:
        r = _floor(y + 0.5)
        if r and -0.4999 < y - r < 0.4999:
            return r / 100.0
    return round(x, 2)


def numbers_spelled_alike(values: Iterable[float | int | None]) -> bool:
    """Does orjson write each of these numbers (or None) as :func:`json.dumps` does? The
    number part of :func:`_same_in_orjson` for a caller that knows its values are numbers:
    0, or finite with ``1e-4 <= |x| < 1e16`` (an integer that large falls back too)."""
    for v in values:
        if v is not None and not (1e-4 <= v < 1e16 or -1e16 < v <= -1e-4 or v == 0.0):
            return False
    return True


def encode_plain_line(record: dict[str, Any]) -> str:
    """:func:`encode_line` for a record whose maker has checked what :func:`_same_in_orjson`
    checks (the rover's records, :meth:`RoverPipeline._record
    <firmware_host.rover.pipeline.RoverPipeline._record>`): flat, its keys and strings
    printable ASCII, its numbers passed by :func:`numbers_spelled_alike`, the rest None,
    booleans and integers. orjson when installed, else the standard library: the same bytes."""
    if _orjson is not None:
        try:
            return _orjson.dumps(record, option=_orjson.OPT_APPEND_NEWLINE).decode()
        except TypeError:  # an integer beyond 64 bits
            pass
    return encode_line_stdlib(record)


class EpochLog:
    """``DIR/epochs.jsonl`` (or nothing, with ``directory=None``); or a caller's open ``stream``
    (an embedding, a test), which is flushed but not closed."""

    def __init__(self, directory: Path | None, stream: TextIO | None = None) -> None:
        self.dir = directory
        self.stream: TextIO | None = stream
        self._borrowed = stream is not None
        self.lines = 0
        if directory is not None and stream is None:
            directory.mkdir(parents=True, exist_ok=True)
            self.stream = open(directory / EPOCHS, "w", encoding="utf-8")  # noqa: SIM115

    def write(self, record: dict[str, Any]) -> None:
        if self.stream is not None:
            self.stream.write(encode_line(record))
            self.lines += 1

    def flush(self) -> None:
        if self.stream is not None:
            self.stream.flush()

    def close(self) -> None:
        if self.stream is not None:
            if self._borrowed:
                self.stream.flush()
            else:
                self.stream.close()
            self.stream = None

    def write_summary(self, summary: dict[str, Any]) -> Path | None:
        """``DIR/summary.json`` (None without a directory)."""
        if self.dir is None:
            return None
        path = self.dir / SUMMARY
        path.write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
        return path
