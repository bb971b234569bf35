"""A generic binary frame codec driven by a protocol description (a TOML file in ``config/``).

Three layers: :class:`Framer` turns a byte stream into :class:`Frame` objects (resync on the sync
bytes, frame length capped from the header *before* the body is read, header and payload
checksums, rejects counted by reason); :func:`decode` and :func:`encode` map a frame's payload to
and from named, scaled fields. Everything is a pure function of bytes and the description, so
tests use bytes literals.

Frame layout (modelled on VideoRay PRO4's RS-485 register protocol)::

    sync[0..n) | node | flags | msg_id | length | header_cs | payload[length] | payload_cs

``header_cs`` covers the sync bytes through ``length``; ``payload_cs`` covers the payload. Each is
one byte (``xor8``, ``sum8``) or absent (``none``). Field types: u8 i8 u16 i16 u32 i32 f32; the
physical value is ``raw * scale + offset`` in ``unit``.
"""

from __future__ import annotations

import struct
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from drivers.configload import load_dataclass, read_toml
from fdi.errors import ConfigError, DecodeError

FieldType = Literal["u8", "i8", "u16", "i16", "u32", "i32", "f32"]
ChecksumKind = Literal["xor8", "sum8", "none"]
_STRUCT = {"u8": "B", "i8": "b", "u16": "H", "i16": "h", "u32": "I", "i32": "i", "f32": "f"}
REJECT_REASONS = ("garbage", "bad_header_checksum", "bad_checksum", "too_long", "short",
                  "unknown_id")


@dataclass(frozen=True)
class FieldSpec:
    name: str
    type: FieldType = "u16"
    scale: float = field(default=1.0, metadata={"ne": 0.0})  # value = raw * scale + offset
    offset: float = 0.0
    unit: str = ""


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
        return len(self.sync) + 4 + (self.header_checksum != "none")


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
    if kind == "none":
        return b""
    if kind == "xor8":
        c = 0
        for b in data:
            c ^= b
        return bytes((c,))
    return bytes((sum(data) & 0xFF,))


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
    """A frame's message name and physical field values; DecodeError(unknown_id / short)."""
    for msg in proto.messages:
        if msg.id == frame.msg_id:
            st = _struct_for(proto, msg)
            if len(frame.payload) != st.size:
                raise DecodeError("short" if len(frame.payload) < st.size else "too_long",
                                  f"{msg.name}: {len(frame.payload)} bytes, expected {st.size}")
            raw = st.unpack(frame.payload)
            return msg.name, {f.name: r * f.scale + f.offset
                              for f, r in zip(msg.fields, raw, strict=True)}
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
        pcs = 1 if p.payload_checksum != "none" else 0
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
            if p.header_checksum != "none" and checksum(p.header_checksum, head[:-1]) != head[-1:]:
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
            if pcs and checksum(p.payload_checksum, payload) != bytes(self.buf[total - 1 : total]):
                self.rejects["bad_checksum"] += 1
                del self.buf[:1]
                continue
            raw = bytes(self.buf[:total])
            del self.buf[:total]
            self.frames += 1
            out.append(Frame(head[n], head[n + 1], head[n + 2], payload, raw))
