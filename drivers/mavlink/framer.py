"""Bytes -> MAVLink frames, byte for byte: MAVLink 1 and 2, unknown ids, signed packets.

The framer never decodes a payload: a :class:`MavFrame` carries the packet's bytes exactly as
they arrived plus the header fields a router needs (source, sequence, message id, signing). It
is the first of the three layers (STYLE.md rule 2); :func:`drivers.mavlink.io.decode_packet`
is the codec for the few frames the bridge reads itself.

Policy
------
* **Start of frame**: ``0xFE`` (MAVLink 1) or ``0xFD`` (MAVLink 2). Bytes before a start byte
  are dropped and counted (``junk_bytes``).
* **Length from the header**: ``6 + len + 2`` (v1), ``10 + len + 2 (+ 13 when signed)`` (v2),
  at most 280 bytes, so a frame is capped before its body is waited for. A MAVLink 2 header
  with an incompatibility flag other than "signed" cannot be framed and is dropped.
* **CRC**: checked whenever the message id is in the dialect's CRC_EXTRA table
  (ardupilotmega, taken from pymavlink through :mod:`drivers.mavlink.io`). A frame whose CRC
  fails is counted (``bad_crc``) and only its start byte is dropped: the framer resyncs from the
  next byte, so a corrupted length byte cannot swallow the good packets that follow.
* **One datagram is one framing context**: the resync state (below) ends with the datagram,
  so a corrupt datagram does not make the router refuse the next datagram's unknown ids.
* **CRC over the untruncated payload**: a MAVLink 2 sender that computed the CRC before
  cutting the payload's trailing zeros (ArduSub's camera messages 259/260/262/269 in
  ``small.tlog``) fails the normal check; the CRC is then tried over the zero-padded payload
  (up to the dialect's length). A match is a checked frame (``crc_untruncated``), forwarded
  byte for byte, as mavlink-router forwards them; anything else is ``bad_crc``.
* **Unknown message ids** (no CRC_EXTRA) are passed through *framed but unchecked*
  (``unchecked``), as mavlink-router does, so a dialect the bridge does not know still flows,
  if the byte after the frame is a start byte (or the datagram ends there; on a stream the
  frame waits for the next byte): an unknown id whose length is wrong (a byte lost inside it)
  would otherwise swallow the next packet.
  Without a CRC such a frame cannot be told from noise, so while the framer is resyncing
  (after dropped bytes, until a CRC-checked frame has been found) unknown-id candidates are
  dropped too (``unknown_refused``): a 0xFD inside a damaged packet must not become a frame.
  The decision is taken as soon as the header is in, without waiting for the body its length
  byte announces, so the packets behind a refused candidate are not held back.
  A byte stream joined at an unknown point (``synced=False``: a serial line, a TCP connection,
  whose first bytes may be stray, e.g. ``FD FF 00``) starts resyncing. And an unknown-id
  candidate whose body holds a complete CRC-valid frame is refused even in sync
  (``unchecked_swallow``): it is stray bytes about to swallow good packets, not a frame.
  A byte error that hits an in-sync packet's message id can turn it into an unknown one, which
  then passes (framed whole, its neighbours intact); ``pass_unknown=False`` refuses every
  unknown id instead.
* **Signatures** are framed, not verified here: :func:`signature_ok` checks one with a key.

Every drop goes to ``on_drop(bytes, reason)`` when given, and into :class:`FramerStats`.
"""

from __future__ import annotations

import binascii
import hashlib
import hmac
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

from drivers.mavlink.io import crc_extra_table, payload_length_table

MAGIC_V1 = 0xFE
MAGIC_V2 = 0xFD
HEADER_V1 = 6
HEADER_V2 = 10
CRC_LEN = 2
SIGNATURE_LEN = 13
IFLAG_SIGNED = 0x01
MAX_FRAME = HEADER_V2 + 255 + CRC_LEN + SIGNATURE_LEN  # 280

# CRC-16/MCRF4XX (MAVLink's "X.25" CRC) is the bit-reflected twin of CRC-16/XMODEM, which the
# standard library computes in C (binascii.crc_hqx): reflect every input byte, run crc_hqx from
# 0xFFFF (its own reflection), reflect the 16-bit result.
_REV8 = bytes(int(f"{i:08b}"[::-1], 2) for i in range(256))


def x25crc(data: bytes | bytearray | memoryview, crc: int = 0xFFFF) -> int:
    """MAVLink's CRC-16/MCRF4XX of ``data`` (initial value 0xFFFF, no final xor)."""
    start = (_REV8[crc & 0xFF] << 8) | _REV8[crc >> 8]
    c = binascii.crc_hqx(bytes(data).translate(_REV8), start)
    return (_REV8[c & 0xFF] << 8) | _REV8[c >> 8]


@dataclass(frozen=True, slots=True)
class MavFrame:
    """One MAVLink packet exactly as received, and its header fields."""

    raw: bytes
    version: int  # 1 or 2
    seq: int
    sysid: int
    compid: int
    msgid: int
    signed: bool
    crc_checked: bool  # False: message id unknown to the dialect, passed through unchecked

    @property
    def header_len(self) -> int:
        return HEADER_V2 if self.version == 2 else HEADER_V1

    @property
    def payload(self) -> bytes:
        return self.raw[self.header_len : self.header_len + self.raw[1]]

    @property
    def link_id(self) -> int | None:
        """The signing link id, or None for an unsigned packet."""
        return self.raw[-SIGNATURE_LEN] if self.signed else None

    @property
    def signature_timestamp(self) -> int | None:
        """The signing timestamp (10 µs units since 2015-01-01), or None if unsigned."""
        if not self.signed:
            return None
        return int.from_bytes(self.raw[-12:-6], "little")

    def payload_byte(self, offset: int) -> int:
        """Payload byte at ``offset``; 0 past the end (MAVLink 2 cuts trailing zeros)."""
        if offset < self.raw[1]:
            return self.raw[self.header_len + offset]
        return 0


def signature_ok(frame: MavFrame, key: bytes) -> bool:
    """True when ``frame`` is signed and its signature matches ``key`` (32 bytes).

    signature = SHA-256(key + header + payload + CRC + link id + timestamp)[:6]
    (MAVLink 2 message signing). Replay protection (timestamps) is the caller's job.
    """
    if not frame.signed:
        return False
    expected = hashlib.sha256(key + frame.raw[:-6]).digest()[:6]
    return hmac.compare_digest(expected, frame.raw[-6:])


def sign_packet(raw: bytes, key: bytes, link_id: int, timestamp: int) -> bytes:
    """Append a signature to an already-signed-flagged MAVLink 2 packet's bytes (for tests).

    ``raw`` must be a MAVLink 2 packet with the signed incompat flag set and without its
    13 signature bytes.
    """
    body = raw + bytes([link_id]) + timestamp.to_bytes(6, "little")
    return body + hashlib.sha256(key + body).digest()[:6]


@dataclass
class FramerStats:
    """Counters of one framer."""

    bytes_in: int = 0
    frames: int = 0
    unchecked: int = 0  # frames with an unknown message id, passed without a CRC check
    bad_crc: int = 0  # candidate frames whose CRC failed (their start byte dropped)
    bad_flags: int = 0  # MAVLink 2 headers with unsupported incompatibility flags
    unknown_refused: int = 0  # unknown-id candidates dropped (resyncing, or pass_unknown=False)
    crc_untruncated: int = 0  # CRC right over the zero-padded payload (a sender's bug): passed
    junk_bytes: int = 0  # bytes dropped while looking for a start byte
    dropped_bytes: int = 0  # every byte dropped for any reason
    by_reason: dict[str, int] = field(default_factory=dict)

    def as_dict(self) -> dict[str, int]:
        return {
            "bytes_in": self.bytes_in,
            "frames": self.frames,
            "unchecked": self.unchecked,
            "bad_crc": self.bad_crc,
            "bad_flags": self.bad_flags,
            "unknown_refused": self.unknown_refused,
            "crc_untruncated": self.crc_untruncated,
            "junk_bytes": self.junk_bytes,
            "dropped_bytes": self.dropped_bytes,
        }


OnDrop = Callable[[bytes, str], None]


def _default_crc_extras() -> Mapping[int, int]:
    return crc_extra_table()


def _default_full_lengths() -> Mapping[int, int]:
    return payload_length_table()


class MavFramer:
    """Incremental MAVLink framer (see the module docstring for the policy).

    ``feed(data)`` returns the frames completed by ``data``; an incomplete frame waits for more
    bytes. ``boundary=True`` says ``data`` ended a datagram (UDP): an incomplete frame left at a
    datagram's end is then dropped as truncated, since the next datagram starts afresh.
    """

    def __init__(
        self,
        crc_extras: Mapping[int, int] | None = None,
        *,
        on_drop: OnDrop | None = None,
        pass_unknown: bool = True,
        full_lengths: Mapping[int, int] | None = None,
        synced: bool = True,
    ) -> None:
        """``synced=False``: the bytes are a stream joined at an unknown point (serial, TCP):
        unknown ids are refused until a CRC-checked frame has been found."""
        self._pass_unknown = pass_unknown
        self._extras = _default_crc_extras() if crc_extras is None else crc_extras
        if full_lengths is None:
            full_lengths = _default_full_lengths() if crc_extras is None else {}
        self._full_len = full_lengths
        self._on_drop = on_drop
        self._buf = bytearray()
        self._in_sync = synced
        self.stats = FramerStats()

    def _drop(self, data: bytes | bytearray, reason: str) -> None:
        n = len(data)
        if n == 0:
            return
        st = self.stats
        st.dropped_bytes += n
        st.by_reason[reason] = st.by_reason.get(reason, 0) + n
        self._in_sync = False
        if self._on_drop is not None:
            self._on_drop(bytes(data), reason)

    def feed(self, data: bytes, *, boundary: bool = False) -> list[MavFrame]:
        if boundary and not self._buf:
            frame = self._whole_datagram(data)
            if frame is not None:  # the usual datagram: one packet of a known id, CRC right
                st = self.stats
                st.bytes_in += len(data)
                st.frames += 1
                self._in_sync = True
                return [frame]
        self.stats.bytes_in += len(data)
        buf = self._buf
        buf += data
        out: list[MavFrame] = []
        pos = 0
        n = len(buf)
        extras = self._extras
        st = self.stats
        while pos < n:
            if self._stalled(buf, pos, n, boundary):
                # At the end of a datagram a frame cannot complete: drop its start byte and
                # rescan the rest (a corrupt length must not take the good packets with it).
                self._drop(buf[pos : pos + 1], "truncated")
                pos += 1
                continue
            b0 = buf[pos]
            if b0 != MAGIC_V2 and b0 != MAGIC_V1:
                nxt = _next_magic(buf, pos + 1)
                st.junk_bytes += nxt - pos
                self._drop(buf[pos:nxt], "junk")
                pos = nxt
                continue
            if b0 == MAGIC_V2:
                if n - pos < 3:
                    break
                plen = buf[pos + 1]
                iflags = buf[pos + 2]
                if iflags & ~IFLAG_SIGNED:
                    st.bad_flags += 1
                    self._drop(buf[pos : pos + 1], "bad_flags")
                    pos += 1
                    continue
                signed = bool(iflags & IFLAG_SIGNED)
                hlen = HEADER_V2
                total = hlen + plen + CRC_LEN + (SIGNATURE_LEN if signed else 0)
            else:
                if n - pos < 2:
                    break
                plen = buf[pos + 1]
                signed = False
                hlen = HEADER_V1
                total = hlen + plen + CRC_LEN
            end = pos + total
            if n - pos < hlen:
                break  # wait for the header
            if hlen == HEADER_V2:
                msgid = buf[pos + 7] | (buf[pos + 8] << 8) | (buf[pos + 9] << 16)
            else:
                msgid = buf[pos + 5]
            extra = extras.get(msgid)
            if extra is None and not (self._pass_unknown and self._in_sync):
                # An unknown id is refused from its header alone (see the policy): waiting for
                # the body its length byte announces would hold the packets behind it.
                st.unknown_refused += 1
                self._drop(buf[pos : pos + 1],
                           "unchecked_resync" if self._pass_unknown else "unknown_id")
                pos += 1
                continue
            if end > n:
                break  # the length is known: wait for the body (at most 280 bytes)
            crc_end = pos + hlen + plen
            checked = extra is not None
            if end == n and not boundary and self._pass_unknown and self._in_sync and (
                    extra is None or not self._crc_ok(buf, pos, crc_end, extra)):
                break  # unchecked on a stream: decided by the next byte (see _next_is_start)
            if extra is not None:
                crc = x25crc(bytes(buf[pos + 1 : crc_end]) + bytes((extra,)))
                wire = buf[crc_end] | (buf[crc_end + 1] << 8)
                if crc != wire:
                    # A sender that computed the CRC before cutting the trailing zeros
                    # (ArduSub's camera component: 259/260/262/269 in small.tlog; mavlink-router
                    # forwards them): the CRC is checked over the zero-padded payload.
                    full = self._full_len.get(msgid, 0) if hlen == HEADER_V2 else 0
                    if full > plen and _padded_crc_ok(buf, pos, crc_end, plen, full, extra, wire):
                        st.crc_untruncated += 1
                    else:
                        st.bad_crc += 1
                        self._drop(buf[pos : pos + 1], "bad_crc")
                        pos += 1
                        continue
            elif not _next_is_start(buf, end, n, boundary):
                # In sync, but what follows is not a frame start: the length byte of this
                # unknown-id packet is wrong (a byte lost inside it), and taking it whole would
                # swallow the start of the good packet after it.
                st.unknown_refused += 1
                self._drop(buf[pos : pos + 1], "unchecked_overrun")
                pos += 1
                continue
            elif _holds_a_frame(buf, pos + 1, end, extras):
                # In sync, but a complete CRC-valid packet lies inside: stray bytes (``FD FF
                # 00`` at a stream's start) whose length byte would swallow good packets.
                st.unknown_refused += 1
                self._drop(buf[pos : pos + 1], "unchecked_swallow")
                pos += 1
                continue
            raw = bytes(buf[pos:end])
            if hlen == HEADER_V2:
                frame = MavFrame(raw, 2, raw[4], raw[5], raw[6], msgid, signed, checked)
            else:
                frame = MavFrame(raw, 1, raw[2], raw[3], raw[4], msgid, False, checked)
            st.frames += 1
            if not checked:
                st.unchecked += 1
            self._in_sync = True
            out.append(frame)
            pos = end
        if pos:
            del buf[:pos]
        if boundary:
            self._in_sync = True  # one datagram is one framing context: the next starts afresh
        return out

    def _whole_datagram(self, data: bytes) -> MavFrame | None:
        """The frame ``data`` is when it is exactly one packet of a known id with a right CRC
        (what :meth:`feed` would find, without its loop); None for anything else, which the
        loop then frames byte by byte."""
        n = len(data)
        if n < HEADER_V1 + CRC_LEN:
            return None
        b0 = data[0]
        if b0 == MAGIC_V2:
            iflags = data[2]
            if iflags & ~IFLAG_SIGNED or n < HEADER_V2 + CRC_LEN:
                return None
            signed = bool(iflags)
            crc_end = HEADER_V2 + data[1]
            if crc_end + CRC_LEN + (SIGNATURE_LEN if signed else 0) != n:
                return None
            msgid = data[7] | (data[8] << 8) | (data[9] << 16)
        elif b0 == MAGIC_V1:
            crc_end = HEADER_V1 + data[1]
            if crc_end + CRC_LEN != n:
                return None
            signed = False
            msgid = data[5]
        else:
            return None
        extra = self._extras.get(msgid)
        if extra is None or x25crc(data[1:crc_end] + bytes((extra,))) != (
                data[crc_end] | (data[crc_end + 1] << 8)):
            return None
        raw = bytes(data)
        if b0 == MAGIC_V2:
            return MavFrame(raw, 2, raw[4], raw[5], raw[6], msgid, signed, True)
        return MavFrame(raw, 1, raw[2], raw[3], raw[4], msgid, False, True)

    @staticmethod
    def _crc_ok(buf: bytearray, pos: int, crc_end: int, extra: int) -> bool:
        crc = x25crc(bytes(buf[pos + 1 : crc_end]) + bytes((extra,)))
        return crc == buf[crc_end] | (buf[crc_end + 1] << 8)

    @staticmethod
    def _stalled(buf: bytearray, pos: int, n: int, boundary: bool) -> bool:
        """True at a datagram's end when the frame starting at ``pos`` cannot complete."""
        if not boundary:
            return False
        b0 = buf[pos]
        if b0 == MAGIC_V2:
            if n - pos < 3:
                return True
            sig = SIGNATURE_LEN if buf[pos + 2] & IFLAG_SIGNED else 0
            return pos + HEADER_V2 + buf[pos + 1] + CRC_LEN + sig > n
        if b0 == MAGIC_V1:
            return n - pos < 2 or pos + HEADER_V1 + buf[pos + 1] + CRC_LEN > n
        return False

    @property
    def pending(self) -> int:
        """Bytes held waiting for the rest of a frame."""
        return len(self._buf)


def _padded_crc_ok(buf: bytearray, pos: int, crc_end: int, plen: int, full: int, extra: int,
                   wire: int) -> bool:
    """True when the CRC matches the packet with its payload zero-padded to ``n`` bytes (and
    the length byte saying ``n``) for some ``plen < n <= full``."""
    body = bytes(buf[pos + 2 : crc_end])
    for n in range(plen + 1, full + 1):
        if x25crc(bytes((n,)) + body + bytes(n - plen) + bytes((extra,))) == wire:
            return True
    return False


def _holds_a_frame(buf: bytearray, start: int, stop: int, extras: Mapping[int, int]) -> bool:
    """True when a complete packet of a known id with a valid CRC starts in ``buf[start:stop]``
    and ends by ``stop``."""
    i = start
    while True:
        i = _next_magic(buf, i)
        if i >= stop:
            return False
        if buf[i] == MAGIC_V2 and i + HEADER_V2 <= stop and not buf[i + 2] & ~IFLAG_SIGNED:
            hlen, msgid = HEADER_V2, buf[i + 7] | (buf[i + 8] << 8) | (buf[i + 9] << 16)
        elif buf[i] == MAGIC_V1 and i + HEADER_V1 <= stop:
            hlen, msgid = HEADER_V1, buf[i + 5]
        else:
            i += 1
            continue
        crc_end = i + hlen + buf[i + 1]
        extra = extras.get(msgid)
        if extra is not None and crc_end + CRC_LEN <= stop and MavFramer._crc_ok(
                buf, i, crc_end, extra):
            return True
        i += 1


def _next_is_start(buf: bytearray, end: int, n: int, boundary: bool) -> bool:
    """True when the frame ending at ``end`` is followed by a start byte or a datagram's end.
    (On a stream the caller waits for the next byte first, so framing does not depend on how
    the bytes were chunked.)"""
    if end < n:
        b = buf[end]
        return b in (MAGIC_V2, MAGIC_V1)
    return boundary


def _next_magic(buf: bytearray, start: int) -> int:
    i2 = buf.find(MAGIC_V2, start)
    i1 = buf.find(MAGIC_V1, start)
    if i2 < 0:
        return len(buf) if i1 < 0 else i1
    if i1 < 0:
        return i2
    return min(i1, i2)


def frame_target(
    frame: MavFrame, offsets: Mapping[int, tuple[int | None, int | None]]
) -> tuple[int, int] | None:
    """``(target_system, target_component)`` of a targeted message, None if it has none.

    A message without a target component field reports component 0 (all components).
    """
    entry = offsets.get(frame.msgid)
    if entry is None:
        return None
    sys_ofs, comp_ofs = entry
    if sys_ofs is None:
        return None
    target_sys = frame.payload_byte(sys_ofs)
    target_comp = frame.payload_byte(comp_ofs) if comp_ofs is not None else 0
    return target_sys, target_comp
