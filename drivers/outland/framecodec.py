"""A generic binary frame codec driven by a protocol description (a TOML file in ``config/``).

Three layers: :class:`Framer` turns a byte stream into :class:`Frame` objects (resync on the sync
bytes, frame length capped from the header *before* the body is read, header and payload
checksums, rejects counted by reason); :func:`decode` and :func:`encode` map a frame's payload to
and from named, scaled fields. Everything is a pure function of bytes and the description, so
tests use bytes literals.

Frame layout (modelled on VideoRay PRO4's RS-485 register protocol)::

    sync[0..n) | node | flags | msg_id | length | header_cs | payload[length] | payload_cs

``header_cs`` covers the sync bytes through ``length``; ``payload_cs`` covers the payload. Each is
one of :data:`drivers.checksums.KINDS` (``xor8``, ``sum8``: 1 byte; ``crc16_ccitt_false``,
``crc16_modbus``: 2 bytes; ``crc32``: 4 bytes) or absent (``none``). Field types: u8 i8 u16 i16
u32 i32 f32; the physical value is ``raw * scale + offset`` in ``unit``, and must lie in the
field's ``[min, max]`` (in physical units): a value outside is a rejected frame
(``out_of_range``), never clamped or wrapped. ``max_rate`` (units per second) is the most the
value can change between samples on the real vehicle; the link flags a faster change as suspect.
"""

from __future__ import annotations

import math
import struct
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from drivers.checksums import ChecksumKind, checksum_bytes, width
from drivers.configload import load_dataclass, read_toml
from fdi.errors import ConfigError, DecodeError

FieldType = Literal["u8", "i8", "u16", "i16", "u32", "i32", "f32"]
_STRUCT = {"u8": "B", "i8": "b", "u16": "H", "i16": "h", "u32": "I", "i32": "i", "f32": "f"}
REJECT_REASONS = ("garbage", "bad_header_checksum", "bad_checksum", "too_long", "short",
                  "unknown_id", "out_of_range")


@dataclass(frozen=True)
class FieldSpec:
    name: str
    type: FieldType = "u16"
    scale: float = field(default=1.0, metadata={"ne": 0.0})  # value = raw * scale + offset
    offset: float = 0.0
    unit: str = ""
    min: float | None = None  # the valid range, physical units (None: what the type holds)
    max: float | None = None
    max_rate: float | None = None  # units/s the vehicle can change it at (plausibility)

    def __post_init__(self) -> None:
        if self.scale == 0:
            raise ValueError(f"{self.name}: scale must not be 0")
        if self.min is not None and self.max is not None and self.min > self.max:
            raise ValueError(f"{self.name}: min > max")
        if self.max_rate is not None and self.max_rate <= 0:
            raise ValueError(f"{self.name}: max_rate must be > 0")

    def valid(self, value: float) -> bool:
        return (math.isfinite(value) and (self.min is None or value >= self.min)
                and (self.max is None or value <= self.max))


@dataclass(frozen=True)
class MessageSpec:
    name: str
    id: int = field(metadata={"ge": 0, "le": 255})
    fields: tuple[FieldSpec, ...] = ()


@dataclass(frozen=True)
class Protocol:
    """The description of a link (``config/protocols/*.toml``)."""

    name: str
    sync: tuple[int, ...] = field(default=(0xF5, 0x5F), metadata={"ge": 0, "le": 255})
    byte_order: Literal["little", "big"] = "little"
    max_payload: int = field(default=64, metadata={"ge": 1, "le": 255})
    header_checksum: ChecksumKind = "xor8"
    payload_checksum: ChecksumKind = "xor8"
    request_flag: int = field(default=0x80, metadata={"ge": 0, "le": 255})
    messages: tuple[MessageSpec, ...] = ()

    def __post_init__(self) -> None:
        if not self.sync:
            raise ValueError("sync must have at least one byte")
        ids = [m.id for m in self.messages]
        if len(set(ids)) != len(ids):
            raise ValueError("message ids must be unique")

    def message(self, name: str) -> MessageSpec:
        for m in self.messages:
            if m.name == name:
                return m
        raise KeyError(name)

    @property
    def header_len(self) -> int:
        return len(self.sync) + 4 + width(self.header_checksum)

    @property
    def payload_cs_len(self) -> int:
        return width(self.payload_checksum)


def load_protocol(path: str | Path) -> Protocol:
    """Read and validate a protocol description; errors name the file and key."""
    table: dict[str, Any] = read_toml(path)
    proto = load_dataclass(Protocol, table, str(path))
    for i, m in enumerate(proto.messages):
        _struct_for(proto, m)  # every field type is known (checked by the loader already)
        if 2 + sum(struct.calcsize(_STRUCT[f.type]) for f in m.fields) > proto.max_payload + 2:
            raise ConfigError(str(path), f"messages[{i}]", f"a payload <= {proto.max_payload}",
                              "a longer one")
    return proto


def _struct_for(proto: Protocol, msg: MessageSpec) -> struct.Struct:
    order = "<" if proto.byte_order == "little" else ">"
    return struct.Struct(order + "".join(_STRUCT[f.type] for f in msg.fields))


def checksum(kind: ChecksumKind, data: bytes) -> bytes:
    """The checksum bytes as sent (see :mod:`drivers.checksums`)."""
    return checksum_bytes(kind, data)


@dataclass(frozen=True)
class Frame:
    node: int
    flags: int
    msg_id: int
    payload: bytes
    raw: bytes


def encode(
    proto: Protocol, name: str, values: dict[str, float], node: int, flags: int = 0
) -> bytes:
    """Build a frame for message ``name``; values in physical units, out-of-range -> ValueError."""
    msg = proto.message(name)
    raws: list[int | float] = []
    for f in msg.fields:
        if not f.valid(values[f.name]):
            raise ValueError(f"{name}.{f.name} = {values[f.name]} outside [{f.min}, {f.max}]")
        v = (values[f.name] - f.offset) / f.scale
        if f.type == "f32":
            raws.append(v)
            continue
        r = round(v)
        bits = 8 * struct.calcsize(_STRUCT[f.type])
        lo, hi = (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if f.type[0] == "i" else (0,
                                                                                   (1 << bits) - 1)
        if not lo <= r <= hi:
            raise ValueError(f"{name}.{f.name} = {values[f.name]} does not fit {f.type}")
        raws.append(r)
    payload = _struct_for(proto, msg).pack(*raws)
    head = bytes(proto.sync) + bytes((node, flags, msg.id, len(payload)))
    head += checksum(proto.header_checksum, head)
    return head + payload + checksum(proto.payload_checksum, payload)


def decode(proto: Protocol, frame: Frame) -> tuple[str, dict[str, float]]:
    """A frame's message name and physical field values.

    DecodeError ``unknown_id``, ``short``, ``too_long``, or ``out_of_range`` (a field outside
    its ``[min, max]``: the whole frame is rejected, no value is clamped or wrapped)."""
    for msg in proto.messages:
        if msg.id == frame.msg_id:
            st = _struct_for(proto, msg)
            if len(frame.payload) != st.size:
                raise DecodeError("short" if len(frame.payload) < st.size else "too_long",
                                  f"{msg.name}: {len(frame.payload)} bytes, expected {st.size}")
            raw = st.unpack(frame.payload)
            values = {}
            for f, r in zip(msg.fields, raw, strict=True):
                v = r * f.scale + f.offset
                if not f.valid(v):
                    raise DecodeError("out_of_range",
                                      f"{msg.name}.{f.name} = {v:g} outside [{f.min}, {f.max}]")
                values[f.name] = v
            return msg.name, values
    raise DecodeError("unknown_id", f"message id 0x{frame.msg_id:02x}")


class Framer:
    """Bytes in, checked frames out; bad input is counted in ``rejects`` and dropped."""

    def __init__(self, proto: Protocol) -> None:
        self.proto = proto
        self.buf = bytearray()
        self.rejects: Counter[str] = Counter()
        self.frames = 0

    def feed(self, data: bytes) -> list[Frame]:
        self.buf += data
        out: list[Frame] = []
        p = self.proto
        sync = bytes(p.sync)
        hl = p.header_len
        hcs = width(p.header_checksum)
        pcs = p.payload_cs_len
        while True:
            i = self.buf.find(sync)
            if i < 0:
                keep = len(sync) - 1  # a partial sync at the end may complete later
                drop = len(self.buf) - keep if len(self.buf) > keep else 0
                if drop:
                    self.rejects["garbage"] += drop
                    del self.buf[:drop]
                return out
            if i:
                self.rejects["garbage"] += i
                del self.buf[:i]
            if len(self.buf) < hl:
                return out
            head = bytes(self.buf[:hl])
            n = len(sync)
            length = head[n + 3]
            if hcs and checksum(p.header_checksum, head[:-hcs]) != head[-hcs:]:
                self.rejects["bad_header_checksum"] += 1
                del self.buf[:1]  # resync after the first sync byte
                continue
            if length > p.max_payload:  # capped before the body is read
                self.rejects["too_long"] += 1
                del self.buf[:1]
                continue
            total = hl + length + pcs
            if len(self.buf) < total:
                return out
            payload = bytes(self.buf[hl : hl + length])
            given = bytes(self.buf[total - pcs : total])
            if pcs and checksum(p.payload_checksum, payload) != given:
                self.rejects["bad_checksum"] += 1
                del self.buf[:1]
                continue
            raw = bytes(self.buf[:total])
            del self.buf[:total]
            self.frames += 1
            out.append(Frame(head[n], head[n + 1], head[n + 2], payload, raw))
