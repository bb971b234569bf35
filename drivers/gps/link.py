"""Does the receiver's output fit its serial link? (issue E: what the wire allows)

An asynchronous serial line sends a byte as a start bit, its data bits, its parity bit (if
any) and its stop bits: 8N1 is 10 bits a byte, so 9600 baud carries 960 bytes a second. A
Trimble AgGPS 132 sending GGA + RMC + VTG (about 206 bytes an epoch) at 10 Hz needs 2060 B/s:
at 9600 baud at most 4.66 Hz of it fits (19200: 9.3 Hz; 38400: 18.6 Hz). A receiver asked for
more either drops sentences or falls behind (its epochs arrive later and later), which a
detector then sees as faults. gpsd's and ArduPilot's NMEA drivers count on the same arithmetic
(``gpsd``'s ``--speed``, ArduPilot's ``GPS_RATE_MS`` advice for 9600 baud).

:func:`max_rate_hz` and :func:`smallest_baud` are the arithmetic; :class:`LinkCheck` watches a
running stream (bytes and the receiver's own fix times, so a pty that carries more than its
nominal baud, or a replay at any speed, measures the same) and decides once whether it fits.
:class:`WirePacer` retimes a recording as its line could have delivered it (``replay --speed
1`` onto a pty: a pty carries any rate, a real wire does not).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator
from dataclasses import dataclass

STANDARD_BAUDS: tuple[int, ...] = (4800, 9600, 19200, 38400, 57600, 115200)
"""The rates a GNSS receiver's port offers (the AgGPS 132: 4800 to 38400)."""
CHECK_EPOCHS = 20
"""Epochs seen (with a known period) before the link is judged."""
MARGIN = 1.0
"""A link fits when the receiver's bytes a second are at most this fraction of its capacity."""


def bits_per_byte(bytesize: int = 8, parity: str = "N", stopbits: float = 1.0) -> float:
    """Bits on the wire per byte: start bit + data bits + parity bit (if any) + stop bits."""
    return 1.0 + bytesize + (0.0 if parity.upper() == "N" else 1.0) + stopbits


def capacity_bytes_s(baudrate: int, bits: float = 10.0) -> float:
    """Bytes a second the line carries (9600 baud 8N1: 960)."""
    return baudrate / bits


def max_rate_hz(bytes_per_epoch: float, baudrate: int, bits: float = 10.0) -> float:
    """The highest epoch rate whose sentences fit the line (206 B at 9600 baud: 4.66 Hz)."""
    return capacity_bytes_s(baudrate, bits) / bytes_per_epoch


def smallest_baud(bytes_per_epoch: float, rate_hz: float, bits: float = 10.0) -> int | None:
    """The smallest standard baud rate that carries ``rate_hz`` epochs of ``bytes_per_epoch``
    (None: not even 115200)."""
    need = bytes_per_epoch * rate_hz
    for baud in STANDARD_BAUDS:
        if need <= capacity_bytes_s(baud, bits) * MARGIN:
            return baud
    return None


@dataclass(frozen=True)
class LinkFit:
    """The verdict on one link: what the receiver sends against what the baud rate carries."""

    baudrate: int
    bytes_per_epoch: float
    rate_hz: float
    sentences: tuple[str, ...]
    bits: float = 10.0

    @property
    def need_bytes_s(self) -> float:
        return self.bytes_per_epoch * self.rate_hz

    @property
    def capacity_bytes_s(self) -> float:
        return capacity_bytes_s(self.baudrate, self.bits)

    @property
    def load(self) -> float:
        """Bytes a second needed over bytes a second carried (1.0 = the line is full)."""
        return self.need_bytes_s / self.capacity_bytes_s

    @property
    def fits(self) -> bool:
        return self.load <= MARGIN

    @property
    def max_rate_hz(self) -> float:
        return max_rate_hz(self.bytes_per_epoch, self.baudrate, self.bits)

    def message(self) -> str:
        """One line for the operator (the log, the replay's warnings)."""
        kinds = "+".join(self.sentences) or "NMEA"
        text = (f"GPS link: {self.rate_hz:.3g} Hz of {kinds} ({self.bytes_per_epoch:.0f} B an "
                f"epoch, {self.need_bytes_s:.0f} B/s) does not fit {self.baudrate} baud "
                f"({self.capacity_bytes_s:.0f} B/s): at most {math.floor(self.max_rate_hz):d} "
                f"Hz fits ({self.max_rate_hz:.2f} Hz)")
        baud = smallest_baud(self.bytes_per_epoch, self.rate_hz, self.bits)
        fixes = ["send fewer sentences"]
        if baud is not None:
            fixes.append(f"set {baud} baud on the receiver and in [rover.port] baudrate")
        return text + "; " + " or ".join(fixes)

    def as_dict(self) -> dict[str, object]:
        return {"baudrate": self.baudrate, "sentences": list(self.sentences),
                "bytes_per_epoch": round(self.bytes_per_epoch, 1),
                "rate_hz": round(self.rate_hz, 3), "need_bytes_s": round(self.need_bytes_s, 1),
                "capacity_bytes_s": round(self.capacity_bytes_s, 1),
                "load": round(self.load, 3), "fits": self.fits,
                "max_rate_hz": round(self.max_rate_hz, 3)}


class LinkCheck:
    """Judges a stream once, after :data:`CHECK_EPOCHS` epochs: ``observe`` returns the
    :class:`LinkFit` the first time it can (None before and after). The bytes are every byte
    the stream received (junk and ignored sentences take the line too); the rate is the
    receiver's, from its fix times."""

    def __init__(self, baudrate: int, bits: float = 10.0) -> None:
        self.baudrate = baudrate
        self.bits = bits
        self.result: LinkFit | None = None
        self._done = baudrate <= 0

    def observe(self, bytes_in: int, epochs: int, period_s: float | None,
                sentences: tuple[str, ...]) -> LinkFit | None:
        if self._done or period_s is None or period_s <= 0 or epochs < CHECK_EPOCHS:
            return None
        self._done = True
        kinds = tuple(dict.fromkeys(sentences))
        self.result = LinkFit(self.baudrate, bytes_in / epochs, 1.0 / period_s, kinds,
                              self.bits)
        return self.result


class WirePacer:
    """A recording's chunks ``(t, bytes)`` at the times the line could have delivered them.

    A chunk is complete when its last byte has arrived, and the line carries one byte every
    ``bits / baudrate`` seconds, one chunk after the other:
    ``t'_k = max(t_k, t'_{k-1} + n_k · bits / baudrate)``. A recording made on a real wire is
    unchanged (its times already respect the line); one whose receiver sent more than the
    baud rate carries (a capture written through a pty, ``sim rover`` at 10 Hz with a 9600
    baud header) falls behind as it would on the wire: the backlog grows by the excess, a
    late epoch after another. ``lag_s`` is the largest delay so far (``t'_k - t_k``).

    The times stay on the recording's axis: ``replay --speed S`` divides them by ``S`` as it
    does every recording's, so at ``S > 1`` the line is taken to be ``S`` times faster too
    (the same epochs late by the same share of their period); at ``--speed 0`` nothing is
    paced and this is not used.
    """

    def __init__(self, chunks: Iterable[tuple[float, bytes]], baudrate: int,
                 bits: float = 10.0) -> None:
        self.chunks = chunks
        self.byte_s = bits / baudrate if baudrate > 0 else 0.0
        self.lag_s = 0.0

    def __iter__(self) -> Iterator[tuple[float, bytes]]:
        free = -math.inf  # when the line has sent everything before
        for t, data in self.chunks:
            free = max(t, free + len(data) * self.byte_s)
            self.lag_s = max(self.lag_s, free - t)
            yield free, data
