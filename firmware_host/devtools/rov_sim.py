"""A simulated Outland-1000-like vehicle: Nomoto yaw, slow current, noisy compass, faults.

Yaw model (first-order Nomoto, exact for a command held over the period):
``T r' + r = K (u + c(t))``, ``psi' = r``, with u the differential thrust (%) and c(t) a slow
current expressed as equivalent thrust (%): a seeded constant plus a slow sinusoid. The compass
reads ``psi + N(0, noise^2)``; faults from ``--fault`` specs modify the reading.

:class:`RovPlant` is step-locked (the tests run it in-process with no I/O); :class:`RovSimServer`
puts it on the far side of a real pty speaking the configured protocol, streaming (RS-232) or
answering polls (RS-485) at 5 Hz.
"""

from __future__ import annotations

import math
import re
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from drivers.outland.framecodec import Framer, Protocol, decode
from drivers.outland.link import NEUTRAL, Telemetry, encode_telemetry, to_command
from drivers.ptypair import PtyPair
from fdi.errors import DecodeError
from firmware_host.rov.config import SimConfig

FAULT_KINDS = ("drift", "stuck", "spike", "noise", "dropout")
_SPEC = re.compile(
    r"^(?P<kind>[a-z]+)(?::(?P<mag>[-+]?\d+(?:\.\d*)?))?@(?P<start>\d+(?:\.\d*)?)"
    r"(?:-(?P<end>\d+(?:\.\d*)?))?$"
)
_EPS = 1e-6


@dataclass(frozen=True)
class FaultSpec:
    """``KIND:MAGNITUDE@START[-END]``: active on [start, end) seconds (end None: to the end)."""

    kind: str
    magnitude: float
    start_s: float
    end_s: float | None = None

    def active(self, t: float) -> bool:
        return t >= self.start_s - _EPS and (self.end_s is None or t < self.end_s - _EPS)


def parse_fault(spec: str) -> FaultSpec:
    """Parse ``drift:30@70``, ``stuck@60``, ``spike:25@80-80.4``, ``noise:5@50-60``, ...."""
    m = _SPEC.match(spec.strip())
    if m is None:
        raise ValueError(f"fault spec {spec!r}: expected KIND[:MAGNITUDE]@START[-END]")
    kind = m["kind"]
    if kind not in FAULT_KINDS:
        raise ValueError(f"fault spec {spec!r}: kind must be one of {', '.join(FAULT_KINDS)}")
    mag = float(m["mag"]) if m["mag"] is not None else 0.0
    if kind in ("drift", "spike", "noise") and m["mag"] is None:
        raise ValueError(f"fault spec {spec!r}: {kind} needs a magnitude")
    start = float(m["start"])
    end = float(m["end"]) if m["end"] is not None else None
    if end is not None and end <= start:
        raise ValueError(f"fault spec {spec!r}: END must be after START")
    return FaultSpec(kind, mag, start, end)


class RovPlant:
    """The vehicle and its compass, advanced one period at a time (seeded, deterministic)."""

    def __init__(self, cfg: SimConfig, faults: Sequence[FaultSpec] = ()):
        self.cfg = cfg
        self.faults = list(faults)
        self.rng = np.random.default_rng(cfg.seed)
        self.t = 0.0
        self.psi = cfg.initial_heading_deg  # true heading, unwrapped, deg
        self.r = 0.0  # yaw rate, deg/s
        self._c0 = float(self.rng.uniform(-cfg.current_max_pct, cfg.current_max_pct))
        self._phase = float(self.rng.uniform(0.0, 2.0 * math.pi))
        self._stuck: dict[int, float] = {}

    def current_pct(self, t: float) -> float:
        c = self.cfg
        return self._c0 + c.current_amp_pct * math.sin(2 * math.pi * t / c.current_period_s
                                                       + self._phase)

    @property
    def heading_true(self) -> float:
        return self.psi % 360.0

    def advance(self, yaw_pct: float, dt: float) -> None:
        """Integrate the yaw model over ``dt`` with the command held (exact ZOH solution)."""
        c = self.cfg
        a = math.exp(-dt / c.nomoto_T_s)
        r_ss = c.nomoto_K * (yaw_pct + self.current_pct(self.t + dt / 2))
        self.psi += r_ss * dt + (self.r - r_ss) * c.nomoto_T_s * (1.0 - a)
        self.r = r_ss + (self.r - r_ss) * a
        self.t += dt

    def measure(self) -> Telemetry | None:
        """The telemetry at the current time, faults applied; None during a dropout."""
        t = self.t
        noise = float(self.rng.normal(0.0, self.cfg.compass_noise_deg))
        h = self.psi + noise
        for i, f in enumerate(self.faults):
            if not f.active(t):
                self._stuck.pop(i, None)
                continue
            if f.kind in ("drift", "spike"):
                h += f.magnitude
            elif f.kind == "noise":
                h += float(self.rng.normal(0.0, f.magnitude))
            elif f.kind == "stuck":
                h = self._stuck.setdefault(i, h)
            elif f.kind == "dropout":
                return None
        return Telemetry(h % 360.0, self.cfg.depth_m, 0.0, 0.0, 0)


class RovSimServer:
    """The vehicle's side of the link: bytes in (commands), bytes out (telemetry).

    ``rs232``: :meth:`tick` advances the plant one period with the last command and returns a
    telemetry frame (streaming). ``rs485``: :meth:`receive` answers each polled command addressed
    to ``node`` by advancing one period and returning the telemetry (step-locked to the polls).
    A dropout fault sends nothing.
    """

    def __init__(self, plant: RovPlant, proto: Protocol, wiring: str, node: int = 1,
                 period_s: float = 0.2) -> None:
        self.plant = plant
        self.proto = proto
        self.wiring = wiring
        self.node = node
        self.period_s = period_s
        self.framer = Framer(proto)
        self.command = NEUTRAL
        self.polls = 0

    def _frame(self) -> bytes:
        tel = self.plant.measure()
        return b"" if tel is None else encode_telemetry(self.proto, tel, self.node)

    def tick(self) -> bytes:
        self.plant.advance(self.command.yaw_pct, self.period_s)
        return self._frame()

    def receive(self, data: bytes) -> bytes:
        out = b""
        for frame in self.framer.feed(data):
            if frame.node != self.node:
                continue
            try:
                name, values = decode(self.proto, frame)
            except DecodeError:
                continue
            if name != "thrusters":
                continue
            self.command = to_command(values)
            if self.wiring == "rs485" and frame.flags & self.proto.request_flag:
                self.polls += 1
                if self.polls > 1:
                    self.plant.advance(self.command.yaw_pct, self.period_s)
                out += self._frame()
        return out


def serve_pty(pty: PtyPair, server: RovSimServer, stop: threading.Event,
              clock: Callable[[], float] = time.monotonic) -> None:
    """Run ``server`` on the master side of ``pty`` until ``stop`` is set (a thread target)."""
    next_tick = clock()
    while not stop.is_set():
        if server.wiring == "rs232":
            wait = max(0.0, next_tick - clock())
            data = pty.read(timeout_s=min(wait, 0.05))
            if data:
                server.receive(data)
            if clock() >= next_tick:
                out = server.tick()
                if out:
                    pty.write(out)
                next_tick += server.period_s
        else:
            data = pty.read(timeout_s=0.05)
            if data:
                reply = server.receive(data)
                if reply:
                    pty.write(reply)
