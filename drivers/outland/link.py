"""The Outland 1000 driver: telemetry in, thruster commands out, over either wiring.

* ``rs232``: through the control converter, full duplex; the vehicle streams telemetry at 5 Hz
  and the bridge sends a ``thrusters`` frame every period (:meth:`OutlandLink.send_command`,
  :meth:`OutlandLink.read_telemetry`).
* ``rs485``: directly on the vehicle's bus, half duplex; the bridge sends the ``thrusters`` frame
  with the request flag to the vehicle's address and waits for its ``telemetry`` reply within
  ``reply_timeout_s`` (:meth:`OutlandLink.poll`). pyserial's RS-485 driver-enable settings come
  from ``SerialSettings.rs485``.

The port is any pyserial URL (:func:`drivers.transport.open_port`); the frame layout is the
protocol description (:mod:`drivers.outland.framecodec`). Malformed frames are counted, never
returned.
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

from drivers.outland.framecodec import FieldSpec, Framer, Protocol, decode, encode
from drivers.transport import Port, read_some, write_all
from fdi.errors import DecodeError

Wiring = Literal["rs232", "rs485"]


@dataclass(frozen=True)
class Telemetry:
    """One telemetry message (units in the names)."""

    heading_deg: float
    depth_m: float
    pitch_deg: float = 0.0
    roll_deg: float = 0.0
    status: int = 0
    # The heading changed faster than the vehicle can turn (the protocol's max_rate): passed
    # on, flagged for the detector, counted in the link's ``heading_suspect``; never hidden.
    heading_suspect: bool = False


@dataclass(frozen=True)
class ThrusterCommand:
    """Thruster setpoints, % of full thrust, -100..100."""

    port_pct: float = 0.0
    starboard_pct: float = 0.0
    lateral_pct: float = 0.0
    vertical_pct: float = 0.0

    @property
    def yaw_pct(self) -> float:
        """Differential thrust (the yaw command u of the FIR)."""
        return (self.port_pct - self.starboard_pct) / 2.0


NEUTRAL = ThrusterCommand()


def _clamp(x: float) -> float:
    return min(max(x, -100.0), 100.0)


def encode_command(proto: Protocol, cmd: ThrusterCommand, node: int, flags: int = 0) -> bytes:
    values = {
        "port_pct": _clamp(cmd.port_pct),
        "starboard_pct": _clamp(cmd.starboard_pct),
        "lateral_pct": _clamp(cmd.lateral_pct),
        "vertical_pct": _clamp(cmd.vertical_pct),
    }
    return encode(proto, "thrusters", values, node=node, flags=flags)


def encode_telemetry(proto: Protocol, tel: Telemetry, node: int) -> bytes:
    spec = next(f for f in proto.message("telemetry").fields if f.name == "heading_deg")
    steps = round(360.0 / spec.scale)  # 359.996 -> 0.00, not 360.00 (outside [0, 359.99])
    values = {
        "heading_deg": round((tel.heading_deg % 360.0) / spec.scale) % steps * spec.scale,
        "depth_m": tel.depth_m,
        "pitch_deg": tel.pitch_deg,
        "roll_deg": tel.roll_deg,
        "status": float(tel.status),
    }
    return encode(proto, "telemetry", values, node=node)


def to_telemetry(values: dict[str, float], heading_suspect: bool = False) -> Telemetry:
    """Decoded values (already checked against the protocol's ranges: never wrapped here)."""
    return Telemetry(
        heading_deg=values["heading_deg"],
        depth_m=values.get("depth_m", float("nan")),
        pitch_deg=values.get("pitch_deg", 0.0),
        roll_deg=values.get("roll_deg", 0.0),
        status=int(values.get("status", 0)),
        heading_suspect=heading_suspect,
    )


def to_command(values: dict[str, float]) -> ThrusterCommand:
    return ThrusterCommand(values["port_pct"], values["starboard_pct"], values["lateral_pct"],
                           values["vertical_pct"])


class OutlandLink:
    """The bridge's side of the link on an open pyserial port."""

    def __init__(
        self,
        port: Port,
        proto: Protocol,
        wiring: Wiring = "rs232",
        node: int = 1,
        reply_timeout_s: float = 0.05,
        clock: Callable[[], float] = time.monotonic,
        sample_period_s: float = 0.2,
    ) -> None:
        self.port = port
        self.proto = proto
        self.wiring = wiring
        self.node = node
        self.reply_timeout_s = reply_timeout_s
        self.clock = clock
        self.framer = Framer(proto)
        self.counts: Counter[str] = Counter()
        # Heading plausibility: the largest turn rate (deg/s) from the protocol file.
        self.sample_period_s = sample_period_s
        self.max_heading_rate = next((f.max_rate for f in self._telemetry_fields()
                                      if f.name == "heading_deg"), None)
        self._last_heading: tuple[float, float] | None = None  # (time, deg) last plausible

    def _telemetry_fields(self) -> tuple[FieldSpec, ...]:
        try:
            return self.proto.message("telemetry").fields
        except KeyError:
            return ()

    @property
    def rejects(self) -> Counter[str]:
        """Rejected input by reason (framer rejects plus decode rejects)."""
        return self.framer.rejects + Counter(
            {k: v for k, v in self.counts.items() if k in ("unknown_id", "short", "too_long",
                                                            "wrong_node", "out_of_range")}
        )

    def _suspect(self, heading: float) -> bool:
        """A heading that moved more than ``max_rate`` allows since the last plausible one.

        The allowance grows with the time since that sample (at least one sample period), so
        a real step is accepted again once the vehicle could have turned that far."""
        if self.max_heading_rate is None:
            return False
        now = self.clock()
        last = self._last_heading
        if last is not None:
            jump = abs((heading - last[1] + 180.0) % 360.0 - 180.0)
            if jump > self.max_heading_rate * max(now - last[0], self.sample_period_s):
                self.counts["heading_suspect"] += 1
                return True
        self._last_heading = (now, heading)
        return False

    def send_command(self, cmd: ThrusterCommand, request: bool = False) -> None:
        flags = self.proto.request_flag if request else 0
        write_all(self.port, encode_command(self.proto, cmd, self.node, flags))
        self.counts["commands"] += 1

    def _telemetry_from(self, data: bytes) -> list[Telemetry]:
        out: list[Telemetry] = []
        for frame in self.framer.feed(data):
            if frame.node != self.node:
                self.counts["wrong_node"] += 1
                continue
            try:
                name, values = decode(self.proto, frame)
            except DecodeError as err:
                self.counts[err.reason] += 1
                continue
            if name == "telemetry":
                out.append(to_telemetry(values, self._suspect(values["heading_deg"])))
                self.counts["telemetry"] += 1
        return out

    def read_telemetry(self) -> list[Telemetry]:
        """RS-232 streaming: every telemetry message waiting (may block up to the port timeout)."""
        return self._telemetry_from(read_some(self.port))

    def poll(self, cmd: ThrusterCommand) -> Telemetry | None:
        """RS-485: send ``cmd`` with the request flag, return the reply or None on timeout."""
        reset = getattr(self.port, "reset_input_buffer", None)
        if reset is not None:  # drop a late reply to an earlier, timed-out poll
            reset()
        self.framer.buf.clear()
        self.send_command(cmd, request=True)
        deadline = self.clock() + self.reply_timeout_s
        while self.clock() < deadline:
            got = self._telemetry_from(read_some(self.port))
            if got:
                return got[-1]
        self.counts["timeouts"] += 1
        return None
