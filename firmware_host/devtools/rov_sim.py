"""A simulated Outland-1000-like vehicle: yaw model, slow current, noisy compass, gyro, faults.

``plant = "nomoto"`` (first-order Nomoto, exact for a command held over the period):
``T r' + r = K (u + c(t))``, ``psi' = r``, with u the differential thrust (%) and c(t) a slow
current expressed as equivalent thrust (%): a seeded constant plus a slow sinusoid. The compass
reads ``psi + N(0, noise^2)``; faults from ``--fault`` specs modify the reading.

``plant = "nonlinear"`` (:class:`NonlinearRovPlant`), the plant the FIR is *not* exact for:
``T r' = K_t tau(c_port, c_stbd) + K c(t) + w(t) - r - q r|r|`` with per-thruster thrust
``f(c) = sign(c) ((|c| - db) / (100 - db))^2 * 100`` outside the dead band ``db`` (x the reverse
efficiency for c < 0), ``tau = (f(port) - f(stbd)) / 2``, the command applied one period late
(``latency_periods``), waves ``w(t)`` (two seeded sinusoids), and a compass that reads
``psi + deviation * mean(|c|)/100 + noise``, with an outlier of up to ``outlier_deg`` on a
fraction ``outlier_prob`` of samples.

Both plants give a yaw-rate gyro (the average rate over the last period + a seeded constant bias
+ white noise, its own random stream, so the compass samples of the Nomoto plant are those of
before the gyro existed) and the same faults: ``drift:DEG@S[-E]``, ``ramp:DEG_PER_S@S[-E]``,
``stuck@S[-E]``, ``spike:DEG@S-E``, ``noise:SIGMA_DEG@S-E``, ``dropout@S-E``; each is active on
[S, E) and the compass is healthy again after E.

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

FAULT_KINDS = ("drift", "ramp", "stuck", "spike", "noise", "dropout")
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


def apply_faults(faults: Sequence[FaultSpec], t: float, h: float, rng: np.random.Generator,
                 stuck: dict[int, float]) -> float | None:
    """A compass reading ``h`` (deg) at time ``t`` with the active faults applied (drift and
    spike add, a ramp grows from its start, noise draws from ``rng``, stuck holds the value
    it had when it began, kept in ``stuck`` by the fault's index); None during a dropout."""
    for i, f in enumerate(faults):
        if not f.active(t):
            stuck.pop(i, None)
            continue
        if f.kind in ("drift", "spike"):
            h += f.magnitude
        elif f.kind == "ramp":
            h += f.magnitude * (t - f.start_s)
        elif f.kind == "noise":
            h += float(rng.normal(0.0, f.magnitude))
        elif f.kind == "stuck":
            h = stuck.setdefault(i, h)
        elif f.kind == "dropout":
            return None
    return h


def parse_fault(spec: str) -> FaultSpec:
    """Parse ``drift:30@70``, ``ramp:0.3@40``, ``stuck@60-80``, ``spike:25@80-80.4``, ...."""
    m = _SPEC.match(spec.strip())
    if m is None:
        raise ValueError(f"fault spec {spec!r}: expected KIND[:MAGNITUDE]@START[-END]")
    kind = m["kind"]
    if kind not in FAULT_KINDS:
        raise ValueError(f"fault spec {spec!r}: kind must be one of {', '.join(FAULT_KINDS)}")
    mag = float(m["mag"]) if m["mag"] is not None else 0.0
    if kind in ("drift", "ramp", "spike", "noise") and m["mag"] is None:
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
        # The gyro has its own stream: the compass samples do not depend on it.
        self._gyro_rng = np.random.default_rng([cfg.seed, 1])
        self.gyro_bias_dps = float(self._gyro_rng.uniform(-cfg.gyro_bias_max_dps,
                                                          cfg.gyro_bias_max_dps))
        self._rate_avg = 0.0  # average true yaw rate over the last period, deg/s
        self._dropout = False

    def current_pct(self, t: float) -> float:
        c = self.cfg
        return self._c0 + c.current_amp_pct * math.sin(2 * math.pi * t / c.current_period_s
                                                       + self._phase)

    @property
    def heading_true(self) -> float:
        return self.psi % 360.0

    def advance(self, yaw_pct: float, dt: float, surge_pct: float = 0.0) -> None:
        """Integrate the yaw model over ``dt`` with the command held (exact ZOH solution)."""
        c = self.cfg
        psi0 = self.psi
        a = math.exp(-dt / c.nomoto_T_s)
        r_ss = c.nomoto_K * (yaw_pct + self.current_pct(self.t + dt / 2))
        self.psi += r_ss * dt + (self.r - r_ss) * c.nomoto_T_s * (1.0 - a)
        self.r = r_ss + (self.r - r_ss) * a
        self.t += dt
        self._rate_avg = (self.psi - psi0) / dt

    def _compass_extra(self) -> float:
        """Plant-specific additions to the compass reading (none on the Nomoto plant)."""
        return 0.0

    def measure(self) -> Telemetry | None:
        """The telemetry at the current time, faults applied; None during a dropout."""
        t = self.t
        noise = float(self.rng.normal(0.0, self.cfg.compass_noise_deg))
        faulty = apply_faults(self.faults, t, self.psi + noise + self._compass_extra(),
                              self.rng, self._stuck)
        self._dropout = faulty is None
        if faulty is None:
            return None
        return Telemetry(faulty % 360.0, self.cfg.depth_m, 0.0, 0.0, 0)

    def gyro_dps(self) -> float | None:
        """The yaw-rate gyro for the last period (deg/s): call after :meth:`measure`.

        None during a dropout (as when the rate is a field of the same telemetry frame).
        """
        g = self._rate_avg + self.gyro_bias_dps
        g += float(self._gyro_rng.normal(0.0, self.cfg.gyro_noise_dps))
        return None if self._dropout else g


class NonlinearRovPlant(RovPlant):
    """The non-textbook vehicle (module docstring): the FIR's model is no longer exact."""

    SUBSTEPS = 10

    def __init__(self, cfg: SimConfig, faults: Sequence[FaultSpec] = ()):
        super().__init__(cfg, faults)
        self._aux_rng = np.random.default_rng([cfg.seed, 2])
        self._wave_phase = [float(p) for p in self._aux_rng.uniform(0.0, 2.0 * math.pi, 2)]
        self._queue: list[tuple[float, float]] = [(0.0, 0.0)] * cfg.latency_periods
        self._applied = (0.0, 0.0)  # (port, starboard) % being applied

    def thrust(self, c_pct: float) -> float:
        """Per-thruster thrust in % of full: c|c| outside the dead band, weaker in reverse."""
        cfg = self.cfg
        a = abs(c_pct)
        if a <= cfg.dead_band_pct:
            return 0.0
        e = min(a - cfg.dead_band_pct, 100.0 - cfg.dead_band_pct) / (100.0 - cfg.dead_band_pct)
        f = 100.0 * e * e
        return f if c_pct > 0 else -cfg.reverse_efficiency * f

    def wave_dps(self, t: float) -> float:
        cfg = self.cfg
        w = 2 * math.pi * t / cfg.wave_period_s
        return cfg.wave_amp_dps * (math.sin(w + self._wave_phase[0])
                                   + 0.5 * math.sin(1.37 * w + self._wave_phase[1]))

    def advance(self, yaw_pct: float, dt: float, surge_pct: float = 0.0) -> None:
        c = self.cfg
        self._queue.append((min(max(surge_pct + yaw_pct, -100.0), 100.0),
                            min(max(surge_pct - yaw_pct, -100.0), 100.0)))
        self._applied = self._queue.pop(0)
        port, stbd = self._applied
        tau = 0.5 * (self.thrust(port) - self.thrust(stbd))
        psi0 = self.psi
        h = dt / self.SUBSTEPS
        for i in range(self.SUBSTEPS):  # RK2 (midpoint) on the yaw rate
            t = self.t + i * h
            forcing = c.thrust_K * tau + c.nomoto_K * self.current_pct(t) + self.wave_dps(t)

            def rdot(r: float, f: float = forcing) -> float:
                return (f - r - c.quad_damping * r * abs(r)) / c.nomoto_T_s

            k1 = rdot(self.r)
            r_mid = self.r + 0.5 * h * k1
            k2 = rdot(r_mid)
            self.psi += h * r_mid
            self.r += h * k2
        self.t += dt
        self._rate_avg = (self.psi - psi0) / dt

    def _compass_extra(self) -> float:
        cfg = self.cfg
        port, stbd = self._applied
        extra = cfg.deviation_deg * 0.5 * (abs(port) + abs(stbd)) / 100.0
        if cfg.outlier_prob and float(self._aux_rng.random()) < cfg.outlier_prob:
            extra += float(self._aux_rng.uniform(-cfg.outlier_deg, cfg.outlier_deg))
        return extra


def make_plant(cfg: SimConfig, faults: Sequence[FaultSpec] = ()) -> RovPlant:
    """The plant ``cfg.plant`` names."""
    return NonlinearRovPlant(cfg, faults) if cfg.plant == "nonlinear" else RovPlant(cfg, faults)


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
