"""Live INS/GNSS as a vehicle of the runtime: the autopilot's IMU over MAVLink, the NMEA
receiver of ``[rover]``, the loosely coupled filter of :mod:`fdi.insgnss` (Cai & Shao's
three-zone gate, or the preset's ``fault_state``) and the rover's outputs.

Ports: ``gps`` (``[rover.port]``, the receiver, through the rover's own pipeline: every fix
also goes through the rover detector) and ``imu`` (``[insgnss.live] imu_url``, the
autopilot's MAVLink link: a serial device, a pty, ``socket://HOST:PORT``). With
``imu_url = "router"`` (:data:`ROUTER`) and a ``[mavlink]`` table there is no ``imu`` port:
the IMU messages, SYSTEM_TIME and ATTITUDE are taken from the router's autopilot link
(:meth:`Router.listen <firmware_host.mavlink.router.Router.listen>`, one process), queued
by the router's thread and read by the vehicle's step in arrival order. Both inputs are
recorded by the flight recorder (``gps rx``, ``imu rx``; from the router the packets as the
step takes them). Paced by data.

IMU time (never arrival time): each sample carries the autopilot's ``time_usec`` /
``time_boot_ms``; the autopilot time is mapped to GNSS time **once**, by the first
``SYSTEM_TIME`` (``time_unix_usec − time_boot_ms``) when the receiver gives a date, else at the
first GNSS epoch (the newest sample then is taken as the epoch's time). Samples are kept in a
buffer keyed by their own stamp: a duplicate is dropped, an out-of-order one takes its place,
one older than what the filter has integrated is counted late and dropped, a missing one
makes a longer interval (up to ``max_imu_gap_s``). A GNSS epoch waits until a sample stamped
``hold_s`` after it has arrived (or ``max_wait_s`` of wall clock), so that late bursts of a
telemetry link are in the buffer before the filter passes the epoch.

Rate: the median interval of the first ``rate_samples`` samples is checked against
``min_imu_rate_hz`` (:func:`fdi.insgnss.check_imu_rate`); below it the INS is refused, said
once in the log and in the summary, and the receiver's fixes go through the rover detector.

Alignment (:mod:`firmware_host.insgnss.align`, from the vehicle's own sensors): an epoch is
*at rest* when the GNSS speed is below ``rest_max_speed_m_s``, nothing turns faster than
``align_max_gyro_deg_s``, ``|f|`` is within ``align_max_accel_dev_m_s2`` of g and the mean
specific force moved less than ``rest_max_accel_m_s2`` since the previous epoch. After
``rest_align_s`` at rest: level from the mean specific force, heading by gyrocompassing from
the mean gyro when the configured gyro can (its heading 1σ at most
``gyrocompass_max_sigma_deg``: navigation grade), else (``heading_source = "auto"``, the
default, once the link has carried one; always with ``"attitude"``) the autopilot's ATTITUDE
yaw, velocity zero, the initial covariance with the attitude error
tied to the biases that cause it; then a zero-velocity update (ZUPT, ``rest_sigma_vel_m_s``) on
every epoch still at rest. Otherwise (moving, or a MEMS gyro), in steady motion: level from the
specific force over ``align_s``, heading from the GNSS course once the speed exceeds
``align_min_speed_m_s`` (1σ at least ``course_sigma_deg``), velocity from the receiver. The
position is a fix that agrees with the previous one and the receiver's velocity. Until aligned,
and after any filter error (an IMU gap it cannot bridge), the rover detector alone drives the
outputs.

GNSS observation: position only. NMEA gives horizontal speed and course but no vertical
velocity, and the filter's velocity update takes the three components together, so the live
filter runs as the preset with ``use_velocity = false``.

Outputs, per epoch: the corrected NMEA (GGA/RMC/VTG of the filter's position; quality 6 when
the fix was not used as is) and GPS_INPUT with the horizontal/vertical accuracies from the
filter's covariance ``sqrt(P_ii)`` (with ``fault_state`` the bias covariance added while a
fault is believed); an epoch whose fix was not used as is (replaced, down-weighted, rejected,
or a fault believed) is raised to the innovation's scale ``sqrt(P⁻_ii + R_ii)``: the output is
then mostly the INS prediction and the receiver disagreed with it. One record per epoch in
``epochs.jsonl``.

While coasting (a no-fix epoch) the horizontal accuracy sent is
``sqrt(max(P_h(fix), σ_rx²) + P_h(now) − P_h(fix))``: what the covariance grew since the last
fix used, on top of that fix's claim, and that claim at least the receiver's own accuracy of
the fix (``σ_rx``, as the rover sends it: GST, else σ √2 HDOP). A receiver's error is
correlated in time, so the filter's average of its fixes at rest (``P_h`` far below the
receiver's σ) is no better than the receiver there; the coast starts from it.
"""

from __future__ import annotations

import logging
import math
import time
from collections import Counter, deque
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any, Literal

import numpy as np

from drivers.mavlink.framer import MavFrame, MavFramer
from drivers.mavlink.imu import ImuSample, imu_from_message
from drivers.mavlink.io import decode_packet
from drivers.ratelog import RateLimitedLog
from drivers.resilient import ResilientPort
from drivers.transport import SerialSettings, open_port_nonblocking
from fdi.errors import DecodeError, EstimatorError
from fdi.insgnss import (
    DEG,
    InsGnssFilter,
    InsGnssParams,
    check_imu_rate,
    measure_imu_rate,
)
from fdi.three_zone import Action
from firmware_host.insgnss import align
from firmware_host.insgnss.align import zaru_sigma
from firmware_host.rover.failsafe import RoverFailsafe
from firmware_host.rover.outputs import MavlinkGpsSink, NmeaSink, receiver_accuracy, unix_time
from firmware_host.rover.pipeline import EpochOutcome, EpochSink, RoverPipeline
from firmware_host.rover.vehicle import rover_mavlink_spec
from firmware_host.runtime.config import BridgeConfig
from firmware_host.runtime.config_insgnss import InsGnssSetup
from firmware_host.runtime.mavout import SEVERITY_WARNING
from firmware_host.runtime.vehicle import Context, MavlinkSpec, PortSpec

log = logging.getLogger("fdi_bridge.insgnss")
ROUTER = "router"  # [insgnss.live] imu_url: the IMU from the router's autopilot link
_CHI2_2_99 = 9.2103  # χ²₂(0.99): a coast's claim checked by the fix that ends it


class _Discard:
    """A text stream that keeps nothing (the rover pipeline builds its records only with one;
    this vehicle writes its own)."""

    def write(self, s: str) -> int:
        return len(s)


class _Collect:
    """The rover pipeline's sink: every outcome is queued for the INS."""

    def __init__(self) -> None:
        self.queue: deque[tuple[EpochOutcome, float]] = deque()
        self.clock: Callable[[], float] = time.monotonic

    def emit(self, out: EpochOutcome) -> None:
        self.queue.append((out, self.clock()))

    def close(self) -> None:
        return None


class InsGpsSink(MavlinkGpsSink):
    """GPS_INPUT of the INS solution: the rover's fields, the accuracies from the covariance
    (``out.record["ins"]["acc_h_m"]`` / ``acc_v_m`` when the INS produced the epoch)."""

    def build_fix(self, out: EpochOutcome) -> Any | None:
        fix = super().build_fix(out)
        ins = out.record.get("ins") if out.record else None
        if fix is None or not isinstance(ins, dict) or "acc_h_m" not in ins:
            return fix
        return replace(fix, horiz_accuracy_m=float(ins["acc_h_m"]),
                       vert_accuracy_m=float(ins["acc_v_m"]))


@dataclass
class _ImuStats:
    received: int = 0
    duplicates: int = 0
    out_of_order: int = 0
    late: int = 0
    no_data: int = 0
    bad_packets: int = 0
    integrated: int = 0


def _r(x: float, nd: int = 4) -> float | None:
    return round(float(x), nd) if math.isfinite(x) else None


class InsGnssVehicle:
    """See the module docstring."""

    name = "insgnss"
    pacing: Literal["data"] = "data"
    period_s = 0.05

    def __init__(self, cfg: BridgeConfig, setup: InsGnssSetup, *, nmea_url: str | None = None,
                 mavlink_url: str | None = None) -> None:
        self.cfg = cfg
        self.setup = setup
        self.live = setup.live
        # position-only updates (module docstring: NMEA has no vertical velocity)
        self.params: InsGnssParams = replace(setup.filter, use_velocity=False)
        out = cfg.rover.output
        self.nmea_url = nmea_url if nmea_url is not None else out.nmea_url
        self.mavlink_url = mavlink_url if mavlink_url is not None else out.mavlink_url
        self.clock: Callable[[], float] = time.monotonic
        self.gps: ResilientPort | None = None
        self.imu: ResilientPort | None = None
        self.pipeline: RoverPipeline | None = None
        self.collect = _Collect()
        self.sinks: list[EpochSink] = []
        self.nmea: NmeaSink | None = None
        self.failsafe: RoverFailsafe | None = None
        self.write_record: Callable[[dict[str, Any]], None] = lambda r: None
        self.ratelog = RateLimitedLog(log)
        self.framer = MavFramer()
        self.stats = _ImuStats()
        self.buffer: dict[int, ImuSample] = {}  # by the sample's own stamp, µs
        self.newest_us: int | None = None
        self.rate_times: list[float] = []
        self.rate_hz: float | None = None
        self.refused = "" if self.live.imu_url else "no [insgnss.live] imu_url: rover only"
        self.boot_unix_s: float | None = None  # SYSTEM_TIME: unix time at autopilot boot
        self.offset_s: float | None = None  # GNSS time = autopilot time + offset
        self.time_map = ""
        self.midnight_unix: float | None = None
        self.attitude_yaw: float | None = None
        self._prev_fix: tuple[float, tuple[float, float, float],
                              tuple[float, float] | None] | None = None
        self.kf: InsGnssFilter | None = None
        self.aligned_at: float | None = None
        self.alignment: align.Alignment | None = None
        self._last_f: np.ndarray | None = None  # the previous epoch's mean specific force
        self._was_still = False  # the previous epoch was at rest
        self._prev_t: float | None = None  # the previous epoch's time
        self._rest_f = np.zeros(3)  # sums over the current rest (consecutive still epochs)
        self._rest_w = np.zeros(3)
        self._rest_n = 0
        self._rest_t0: float | None = None
        self.zupts = 0
        self.zarus = 0  # zero-angular-rate updates at rest (the gyro biases)
        self._align_P: np.ndarray | None = None
        self.align_wait: Counter[str] = Counter()
        self.resets: Counter[str] = Counter()
        self.modes: Counter[str] = Counter()
        self.gate_actions: Counter[str] = Counter()
        self.sending = True
        self._idle_s = 0.0
        self._prior_var = np.zeros(3)
        self.output_errors = 0
        self._mav: Any | None = None  # the vehicle's MAVLink output (STATUSTEXT)
        self._last_fix_t: float | None = None  # GNSS time of the last fix the filter used
        self._coast_said = -1.0  # coast length (s) of the last "INS coasting" message
        self._coast_ended = False  # this outage's coast passed its limit: no-fix until a fix
        self.coast_epochs = 0  # epochs sent as the INS's coast (3D fix, its own accuracy)
        self.coast_no_fix = 0  # epochs sent as no-fix past the coast limit
        self._coasting = False  # the previous epoch was coasted (no fix)
        self.coast_checks = 0  # coasts ended by a fix: their claim checked against it
        self.coast_failed = 0  # ... of which the fix was beyond the claim (NEES > χ²₂(0.99))
        self.coast_inflation = 1.0  # factor on the coast's accuracy from the failed checks
        self._fix_acc_h = 0.0  # the receiver's own horizontal accuracy of the last fix used
        self._var_h_fix = 0.0  # the filter's horizontal variance just after that fix
        self._rate_win: deque[tuple[float, int]] = deque()  # (GNSS time, integrated so far)
        self._status = "waiting for the first epoch"  # the status line's section
        self.rate_drops = 0  # the integrated rate fell below min_imu_rate_hz (a reset each)
        self._router_q: deque[bytes] = deque()  # appended by the router's thread
        self._imu_tap: Callable[[bytes], None] | None = None

    # ------------------------------------------------------------------ what it needs

    def ports(self) -> list[PortSpec]:
        rc = self.cfg.rover
        specs = [PortSpec("gps", rc.port, rc.reconnect_max_s, opener=open_port_nonblocking)]
        if self.live.imu_url and self.live.imu_url != ROUTER:
            s = SerialSettings(url=self.live.imu_url, baudrate=self.live.imu_baudrate,
                               timeout_s=0.0)
            specs.append(PortSpec("imu", s, rc.reconnect_max_s, opener=open_port_nonblocking))
        return specs

    def mavlink(self) -> MavlinkSpec | None:
        return rover_mavlink_spec(self.cfg, self.mavlink_url)

    def outputs(self) -> tuple[str, ...]:
        """The corrected NMEA output, when there is one (the start banner)."""
        return (f"NMEA {self.nmea_url}",) if self.nmea_url else ()

    def status_fields(self) -> dict[str, Any]:
        """Nothing beyond the runner's own status line fields."""
        return {}

    def start(self, ctx: Context) -> None:
        rc = self.cfg.rover
        out = rc.output
        self.clock = self.collect.clock = ctx.clock
        self.gps = ctx.ports["gps"]
        self.imu = ctx.ports.get("imu")
        if self.live.imu_url == ROUTER and self.imu is None and not self.refused:
            # (a replay hands the recorded "imu rx" as the port instead)
            if ctx.router is None:
                self.refused = (f'[insgnss.live] imu_url = "{ROUTER}" needs the router (a '
                                "[mavlink] table); the rover detector alone")
            else:
                for kind in (self.live.imu_message, "SYSTEM_TIME", "ATTITUDE"):
                    ctx.router.listen(kind, self._on_router_frame)
                self._imu_tap = ctx.tap("imu rx", ROUTER, 0, "rx")
        self.write_record = ctx.epochs.write
        self.pipeline = RoverPipeline(rc, jsonl=_Discard(),  # type: ignore[arg-type]
                                      sinks=[self.collect])
        if self.nmea_url:
            tap = ctx.tap("nmea tx", self.nmea_url, out.nmea_baudrate, "tx")
            self.nmea = NmeaSink(self.nmea_url, out.nmea_baudrate, clock=ctx.clock,
                                 backoff_max_s=rc.reconnect_max_s,
                                 opener=open_port_nonblocking, tap=tap)
            self.sinks.append(self.nmea)
        if ctx.mavlink is not None:
            rover = replace(rc, output=replace(out, mavlink_url=self.mavlink_url or "output"))
            self.sinks.append(InsGpsSink(rover, endpoint=ctx.mavlink))
        self.failsafe = RoverFailsafe(rc, ctx.mavlink, clock=ctx.clock)
        self._mav = ctx.mavlink
        self.sinks.append(self.failsafe)
        if self.refused:
            log.warning("INS/GNSS: %s", self.refused)

    # ------------------------------------------------------------------ the loop's hooks

    def step(self, t: float) -> int:
        assert self.gps is not None and self.pipeline is not None
        t0 = self.clock()
        got = False
        if self.imu is not None:
            data = self.imu.read_some(65536)
            if data:
                got = True
                self._feed_imu(data)
        elif self._router_q:
            q = self._router_q
            data = b"".join(q.popleft() for _ in range(len(q)))
            got = True
            if self._imu_tap is not None:
                self._imu_tap(data)
            self._feed_imu(data)
        data = self.gps.read_some(65536)
        if data:
            got = True
            self.pipeline.feed(data)
        n = self._drain(force=False)
        if got:
            self._idle_s = 0.0
        else:
            wait = max(self.cfg.rover.port.timeout_s, 0.01)
            self._idle_s = max(0.0, wait - (self.clock() - t0))
        return n

    def status_detail(self) -> tuple[str, ...]:
        """The status line's section (Snapshot ``detail``): what drives the output now, as
        the operator needs it: ``INS 0.37 m`` (the accuracy sent), ``INS coasting, 6 s,
        accuracy 0.5 m``, ``INS coast limit, 11 s: no fix``, ``rover detector (aligning: at
        rest: levelling (heading from ATTITUDE))``, or the refusal; with the IMU's rate."""
        rate = () if self.rate_hz is None else (f"imu {self.rate_hz:.0f} Hz",)
        if self.refused:
            return ("INS refused: rover detector", *rate)
        return (self._status, *rate)

    def check(self, now: float) -> None:
        if self.failsafe is not None:
            self.failsafe.check()

    def idle_s(self) -> float:
        if self.gps is None:
            return 0.0
        if self.gps.up:
            return self._idle_s
        return max(self.gps.wait_s(), 0.01)

    def finish(self) -> None:
        """The pending epochs are recorded, not sent (as the rover's)."""
        if self.pipeline is None:
            return
        self.sending = False
        try:
            self.pipeline.finish()
            self._drain(force=True)
        finally:
            for sink in self.sinks:
                sink.close()

    # ------------------------------------------------------------------ IMU

    def _on_router_frame(self, frame: MavFrame) -> None:
        """The router's thread: keep the packet for the next step (deque appends are atomic)."""
        self._router_q.append(frame.raw)

    def _feed_imu(self, data: bytes) -> None:
        want = self.live.imu_message
        for frame in self.framer.feed(data):
            msg = decode_packet(frame.raw)
            if msg is None:
                self.stats.bad_packets += 1
                continue
            kind = msg.get_type()
            if kind == "SYSTEM_TIME":
                unix_us = int(getattr(msg, "time_unix_usec", 0) or 0)
                if self.boot_unix_s is None and unix_us > 0:
                    self.boot_unix_s = unix_us * 1e-6 - int(msg.time_boot_ms) * 1e-3
            elif kind == "ATTITUDE":
                self.attitude_yaw = float(msg.yaw)
            elif kind == want:
                try:
                    sample = imu_from_message(msg)
                except DecodeError as err:
                    self.stats.bad_packets += 1
                    self.ratelog.warning("imu decode", str(err))
                    continue
                if sample is None:
                    self.stats.no_data += 1
                    continue
                self._add_sample(sample)

    def _add_sample(self, s: ImuSample) -> None:
        st = self.stats
        st.received += 1
        if self.refused:
            return  # counted, not kept: the rover detector alone
        key = round(s.t_s * 1e6)
        if key in self.buffer:
            st.duplicates += 1
            return
        kf = self.kf
        if kf is not None and self.offset_s is not None and s.t_s + self.offset_s <= kf.t_s:
            st.late += 1  # the filter has passed it; a duplicate of an integrated one lands here
            return
        if self.newest_us is not None and key < self.newest_us:
            st.out_of_order += 1
        self.buffer[key] = s
        if self.newest_us is None or key > self.newest_us:
            self.newest_us = key
        if self.rate_hz is None:
            self.rate_times.append(s.t_s)
            if len(self.rate_times) >= self.live.rate_samples:
                self._check_rate()
        if len(self.buffer) > 20000:  # nothing consumes it (no GNSS): keep the newest
            for k in sorted(self.buffer)[:10000]:
                del self.buffer[k]

    def _check_rate(self) -> None:
        times = sorted(set(self.rate_times))
        self.rate_hz = measure_imu_rate(times)
        try:
            check_imu_rate(self.rate_hz, self.params.min_imu_rate_hz,
                           f"IMU ({self.live.imu_message})")
        except EstimatorError as err:
            self.refused = f"{err}; passing the receiver's fixes through the rover detector"
            log.error("INS/GNSS: %s", self.refused)
            self.buffer.clear()

    # ------------------------------------------------------------------ epochs

    def _gnss_time(self, out: EpochOutcome) -> float | None:
        """The epoch's time on the filter's scale: seconds since midnight UTC of the first date
        (the rover pipeline's epoch time)."""
        if out.t_s is None:
            return None
        e = out.epoch
        if self.midnight_unix is None and e.date is not None and e.utc_s is not None:
            self.midnight_unix = unix_time(e.date, e.utc_s) - out.t_s
        return out.t_s

    def _map_time(self, t_g: float) -> None:
        if self.offset_s is not None:
            return
        if self.boot_unix_s is not None and self.midnight_unix is not None:
            self.offset_s = self.boot_unix_s - self.midnight_unix
            self.time_map = "system_time"
        elif self.newest_us is not None:
            self.offset_s = t_g - self.newest_us * 1e-6
            self.time_map = "first_epoch"
        else:
            return
        log.info("INS/GNSS: autopilot time mapped to GNSS time by %s (offset %.3f s)",
                 self.time_map, self.offset_s)

    def _drain(self, *, force: bool) -> int:
        q = self.collect.queue
        n = 0
        now = self.clock()
        while q:
            out, arrived = q[0]
            t_g = self._gnss_time(out)
            # "no imu": none has come yet (an empty buffer after one has is a wait below:
            # the records must not depend on which link's bytes were read first)
            if self.refused or t_g is None or (self.newest_us is None and not force):
                q.popleft()
                self._emit_rover(out, t_g, "no imu" if not self.refused else "refused")
                n += 1
                continue
            self._map_time(t_g)
            if self.offset_s is None:
                q.popleft()
                self._emit_rover(out, t_g, "no imu time")
                n += 1
                continue
            newest = (self.newest_us or 0) * 1e-6 + self.offset_s
            waited = now - arrived
            if not force and newest < t_g + self.live.hold_s and waited < self.live.max_wait_s:
                break  # wait for the samples of this epoch (and late ones)
            q.popleft()
            self._epoch(out, t_g)
            n += 1
        return n

    def _take(self, until_gnss_s: float) -> list[tuple[float, ImuSample]]:
        """The buffered samples stamped up to ``until_gnss_s`` (GNSS time), in time order."""
        assert self.offset_s is not None
        limit = round((until_gnss_s - self.offset_s) * 1e6)
        keys = sorted(k for k in self.buffer if k <= limit)
        return [(k * 1e-6 + self.offset_s, self.buffer.pop(k)) for k in keys]

    def _epoch(self, out: EpochOutcome, t_g: float) -> None:
        if self.kf is None:
            self._try_align(out, t_g)
            self._prev_t = t_g
            return
        kf = self.kf
        zupt = False
        try:
            samples = self._take(t_g)
            for t, s in samples:
                if t <= kf.t_s:
                    self.stats.late += 1
                    continue
                kf.propagate(t, s.gyro_rad_s, s.accel_m_s2)
                self.stats.integrated += 1
            self._watch_rate(t_g)
            still = self._stationary(out, [s for _, s in samples])
            enu = self._fix_enu(out)
            if enu is None:
                kf.coast(t_g)
                rep = None
            else:
                if self._coasting:
                    self._check_coast(enu)
                self._prior_var = np.diag(kf.P)[:3].copy()  # P⁻ (at the last covariance step)
                rep = kf.update(t_g, enu)
                self._last_fix_t = t_g
                self._fix_acc_h = receiver_accuracy(out.epoch, self.cfg.rover.detector)[0]
                self._var_h_fix = self._var_h(kf)
            self._coasting = rep is None
            if still:
                kf.zero_velocity(self.live.rest_sigma_vel_m_s)  # at rest: ZUPT
                self.zupts += 1
                zupt = True
                # and ZARU: the mean gyro over the epoch is the gyro bias (plus Earth rate)
                w = np.array([s.gyro_rad_s for _, s in samples])
                seconds = len(w) / self.rate_hz if self.rate_hz else 0.0  # averaged over
                if len(w) and kf.zero_rate(w.mean(axis=0), zaru_sigma(
                        self.live.rest_sigma_gyro_deg_s * DEG, kf.params, seconds)):
                    self.zarus += 1
        except EstimatorError as err:
            self.resets[str(err).split(" ")[0] or "error"] += 1
            self.ratelog.warning("ins reset", f"{err}; realigning, rover detector meanwhile")
            self.kf = None
            self.aligned_at = None
            self._rate_win.clear()
            self._rest_reset()
            self._emit_rover(out, t_g, "reset")
            return
        finally:
            self._prev_t = t_g
        self._emit_ins(out, t_g, rep, zupt)

    def _watch_rate(self, t_g: float) -> None:
        """The IMU rate on the samples actually integrated, over the last
        ``rate_samples / min_imu_rate_hz`` seconds (2.5 s by default): below
        ``min_imu_rate_hz`` at any time the filter is stopped (an EstimatorError: the rover
        detector meanwhile, realigned when the stream is back), said once per drop."""
        win = self._rate_win
        win.append((t_g, self.stats.integrated))
        span_s = self.live.rate_samples / self.params.min_imu_rate_hz
        while len(win) > 2 and t_g - win[1][0] >= span_s:
            win.popleft()
        dt = t_g - win[0][0]
        if dt < span_s:
            return
        rate = (self.stats.integrated - win[0][1]) / dt
        if rate < self.params.min_imu_rate_hz:
            self.rate_drops += 1
            raise EstimatorError(
                f"imu_rate {rate:.3g} Hz integrated over the last {dt:.1f} s, below "
                f"min_imu_rate_hz {self.params.min_imu_rate_hz:g}")

    # ------------------------------------------------------------------ alignment

    def _stationary(self, out: EpochOutcome, window: list[ImuSample]) -> bool:
        """At rest over this epoch's interval: GNSS speed at most ``rest_max_speed_m_s``, no
        rotation above ``align_max_gyro_deg_s``, ``|f|`` within ``align_max_accel_dev_m_s2``
        of g and the mean specific force within ``rest_max_accel_m_s2`` of the previous
        epoch's (a start is seen by the accelerometers before the GNSS speed). Without a fix
        (an outage: no GNSS speed) a rest that was going on continues while the IMU says
        still, so that the ZUPTs and ZARUs hold the coast."""
        lv = self.live
        if not window:
            self._last_f = None
            self._was_still = False
            return False
        f_all = np.array([s.accel_m_s2 for s in window])
        f = f_all.mean(axis=0)
        last, self._last_f = self._last_f, f
        speed = out.epoch.speed_mps
        was_still, self._was_still = self._was_still, False
        if speed is None and not out.epoch.valid and was_still:
            speed = 0.0  # no fix (an outage): a rest goes on while the IMU says still
        if speed is None or speed > lv.rest_max_speed_m_s or last is None:
            return False
        w = np.array([s.gyro_rad_s for s in window])
        if float(np.max(np.linalg.norm(w, axis=1))) > lv.align_max_gyro_deg_s * DEG:
            return False
        if abs(float(np.linalg.norm(f)) - self.params.earth.g0) > lv.align_max_accel_dev_m_s2:
            return False
        self._was_still = float(np.linalg.norm(f - last)) <= lv.rest_max_accel_m_s2
        return self._was_still

    def _rest_reset(self) -> None:
        self._rest_f = np.zeros(3)
        self._rest_w = np.zeros(3)
        self._rest_n = 0
        self._rest_t0 = None

    def _rest_add(self, window: list[ImuSample], t_g: float) -> float:
        """Adds the epoch's samples to the current rest; returns its length (s)."""
        if self._rest_t0 is None:
            self._rest_t0 = self._prev_t if self._prev_t is not None else t_g
        self._rest_f += np.sum([s.accel_m_s2 for s in window], axis=0)
        self._rest_w += np.sum([s.gyro_rad_s for s in window], axis=0)
        self._rest_n += len(window)
        return t_g - self._rest_t0

    @staticmethod
    def _fix_enu(out: EpochOutcome) -> tuple[float, float, float] | None:
        rec = out.record or {}
        r = (rec.get("e"), rec.get("n"), rec.get("u"))
        if not out.epoch.valid or out.t_s is None or any(v is None for v in r):
            return None
        e, n, u = (float(v) for v in r)  # type: ignore[arg-type]
        return (e, n, u) if math.isfinite(e + n + u) else None

    def _try_align(self, out: EpochOutcome, t_g: float) -> None:
        lv = self.live
        samples = self._take(t_g)
        window = [s for t, s in samples if t >= t_g - lv.align_s]
        still = self._stationary(out, [s for _, s in samples])
        rest_s = self._rest_add([s for _, s in samples], t_g) if still else 0.0
        if not still:
            self._rest_reset()
        reason = self._fix_reason(out)
        a: align.Alignment | None = None
        if not reason and still:
            a, reason = self._align_at_rest(rest_s)
        elif not reason:
            reason = self._motion_reason(out, window)
            if not reason:
                f = np.mean([s.accel_m_s2 for s in window], axis=0)
                speed = float(out.epoch.speed_mps or 0.0)
                course = float(out.epoch.course_deg or 0.0) * DEG
                yaw = self.attitude_yaw if self._motion_heading(out) == "attitude" else None
                a = align.in_motion(self.params, f, lv.align_s, speed, course,
                                    lv.course_sigma_deg, yaw, lv.attitude_sigma_deg)
        if a is None:
            self.align_wait[reason] += 1
            self._emit_rover(out, t_g, f"aligning: {reason}")
            return
        enu = self._fix_enu(out)
        assert enu is not None
        if a.method == "gnss course" or not still:
            speed = float(out.epoch.speed_mps or 0.0)
            course = float(out.epoch.course_deg or 0.0) * DEG
            vel = (speed * math.sin(course), speed * math.cos(course), 0.0)
        else:
            vel = (0.0, 0.0, 0.0)
        self.kf = InsGnssFilter(a.params(self.params), t_g, enu, vel, (a.roll, a.pitch, a.yaw))
        self._last_fix_t = t_g
        if self._align_P is not None:  # at rest: the attitude error tied to the biases
            self.kf.set_ins_covariance(self._align_P)
            self._align_P = None
        self.aligned_at = t_g
        self.alignment = a
        log.info("INS/GNSS aligned at t = %.3f s by %s: roll %.3f pitch %.3f yaw %.3f deg "
                 "(1σ tilt %.4f, yaw %.4f deg)", t_g, a.method, a.roll / DEG, a.pitch / DEG,
                 a.yaw / DEG, a.sigma_tilt_deg, a.sigma_yaw_deg)
        self._emit_rover(out, t_g, "aligned")

    def _rest_heading(self) -> str:
        """Where the heading of an alignment at rest comes from: "gyrocompass" (the configured
        gyro can: navigation grade), "attitude" (the autopilot's ATTITUDE yaw), or "course"
        (none at rest: the GNSS course once moving). ``heading_source``: "attitude" always
        the ATTITUDE yaw; "gnss" gyrocompass or course; "auto" gyrocompass, else ATTITUDE
        once the link has carried one, else course."""
        lv = self.live
        if lv.heading_source == "attitude":
            return "attitude"
        if align.gyrocompass_sigma(self.params, lv.rest_align_s) <= \
                lv.gyrocompass_max_sigma_deg * DEG:
            return "gyrocompass"
        if lv.heading_source == "auto" and self.attitude_yaw is not None:
            return "attitude"
        return "course"

    def _align_at_rest(self, rest_s: float) -> tuple[align.Alignment | None, str]:
        lv = self.live
        heading = self._rest_heading()
        if heading == "course":
            if lv.heading_source == "auto":
                return None, ("at rest, the gyro cannot gyrocompass and no ATTITUDE: heading "
                              "from the course")
            return None, "at rest, the gyro cannot gyrocompass: heading from the course"
        if heading == "attitude" and self.attitude_yaw is None:
            return None, "at rest: no ATTITUDE yet (heading_source attitude)"
        if rest_s < lv.rest_align_s:
            return None, ("at rest: levelling and gyrocompassing" if heading == "gyrocompass"
                          else "at rest: levelling (heading from ATTITUDE)")
        n = max(self._rest_n, 1)
        f, w = self._rest_f / n, self._rest_w / n
        yaw = self.attitude_yaw if heading == "attitude" else None
        a = align.at_rest(self.params, f, w, rest_s, yaw, lv.attitude_sigma_deg,
                          lv.rest_sigma_vel_m_s)
        self._align_P = align.rest_covariance(self.params, a, f, w, rest_s, yaw)
        return a, ""

    def _fix_reason(self, out: EpochOutcome) -> str:
        enu = self._fix_enu(out)
        if enu is None:
            return "no 3D fix"
        prev = self._prev_fix
        if prev is None:
            return "no previous fix"
        # The fix the filter starts from must agree with the previous one and the receiver's
        # velocity (a jump of a faulty fix would be the INS's origin): horizontal residual of
        # p_j − p_{j−1} − (v_j + v_{j−1}) Δt / 2 within 3σ·√2.
        dt = (out.t_s or 0.0) - prev[0]
        v0, v1 = prev[2], self._vel_en(out)
        if not 0.0 < dt <= 2.0 or v0 is None or v1 is None:
            return "no consecutive fixes with velocity"
        res = math.hypot(enu[0] - prev[1][0] - 0.5 * (v0[0] + v1[0]) * dt,
                         enu[1] - prev[1][1] - 0.5 * (v0[1] + v1[1]) * dt)
        if res > 3.0 * math.sqrt(2.0) * self.params.gnss_sigma_h_m:
            return "fix inconsistent with the previous one"
        return ""

    def _motion_reason(self, out: EpochOutcome, window: list[ImuSample]) -> str:
        lv = self.live
        n_need = int(lv.align_s * self.params.min_imu_rate_hz * 0.5)
        if len(window) < max(n_need, 2):
            return "too few IMU samples"
        f = np.array([s.accel_m_s2 for s in window])
        w = np.array([s.gyro_rad_s for s in window])
        if float(np.max(np.linalg.norm(w, axis=1))) > lv.align_max_gyro_deg_s * DEG:
            return "turning"
        if abs(float(np.linalg.norm(f.mean(axis=0))) - self.params.earth.g0) > \
                lv.align_max_accel_dev_m_s2:
            return "accelerating"
        heading = self._motion_heading(out)
        if heading == "attitude" and self.attitude_yaw is None:
            return "no ATTITUDE yet"
        speed = out.epoch.speed_mps
        if heading == "attitude" and speed is not None and speed <= lv.rest_max_speed_m_s:
            # slow enough to be at rest, not (yet) seen still: the alignment at rest levels
            # over rest_align_s and ties the attitude error to the biases
            return "at rest: levelling (heading from ATTITUDE)"
        if heading == "none":
            if lv.heading_source == "auto":
                return "moving slower than align_min_speed_m_s, no ATTITUDE"
            return "not moving (heading from GNSS course)"
        return ""

    def _motion_heading(self, out: EpochOutcome) -> str:
        """In motion: "course" (GNSS course, fast enough), "attitude" (heading_source
        attitude; auto below ``align_min_speed_m_s`` with ATTITUDE) or "none" yet."""
        lv = self.live
        if lv.heading_source == "attitude":
            return "attitude"
        sp, co = out.epoch.speed_mps, out.epoch.course_deg
        if sp is not None and co is not None and sp >= lv.align_min_speed_m_s:
            return "course"
        if lv.heading_source == "auto" and self.attitude_yaw is not None:
            return "attitude"
        return "none"

    @staticmethod
    def _vel_en(out: EpochOutcome) -> tuple[float, float] | None:
        sp, co = out.epoch.speed_mps, out.epoch.course_deg
        if sp is None or co is None:
            return None
        return (sp * math.sin(co * DEG), sp * math.cos(co * DEG))

    # ------------------------------------------------------------------ outputs

    def _base_record(self, out: EpochOutcome, t_g: float | None, mode: str) -> dict[str, Any]:
        """The rover's record of the epoch (the same keys as the rover's ``epochs.jsonl``),
        with ``t``, ``mode`` ("ins": the filter's solution went out, "rover": the detector's)."""
        return {**(out.record or {}), "t": None if t_g is None else round(t_g, 3),
                "mode": mode}

    def _emit_rover(self, out: EpochOutcome, t_g: float | None, why: str) -> None:
        self.modes["rover"] += 1
        enu = self._fix_enu(out)  # every epoch before the INS is the "previous fix" of the next
        self._prev_fix = None if enu is None else (out.t_s or 0.0, enu, self._vel_en(out))
        record = self._base_record(out, t_g, "rover")
        record["why"] = why
        self._status = f"rover detector ({why})"
        self.write_record(record)
        self._send(out)

    def _emit_ins(self, out: EpochOutcome, t_g: float, rep: Any | None,
                  zupt: bool = False) -> None:
        kf = self.kf
        pipeline = self.pipeline
        assert kf is not None and pipeline is not None
        self.modes["ins"] += 1
        p = kf.position
        P = kf.P
        sig = np.sqrt(np.maximum(np.diag(P)[:9], 0.0))
        bias_var = np.diag(kf._Pbb) if kf.bias_active else np.zeros(3)
        used = rep is not None and all(d.action is Action.ACCEPT for d in rep.decisions[:3]) \
            and not kf.bias_active
        var = np.diag(P)[:3] + bias_var
        if rep is not None and not used:
            # the fix was not used as is: the output is (mostly) the INS prediction, and the
            # receiver disagreed with it; say so with the innovation's scale, P⁻_ii + R_ii
            prm = self.params
            r = np.array([prm.gnss_sigma_h_m**2, prm.gnss_sigma_h_m**2, prm.gnss_sigma_v_m**2])
            var = np.maximum(var, self._prior_var + r)
        acc_h = math.sqrt(max(float(var[0]), float(var[1])))
        acc_v = math.sqrt(float(var[2]))
        if rep is None:  # coasting (module docstring): from the receiver's accuracy at least
            grown = max(0.0, self._var_h(kf) - self._var_h_fix)
            acc_h = math.sqrt(max(self._var_h_fix, self._fix_acc_h**2) + grown)
            acc_h *= self.coast_inflation  # and scaled by the coast checks that failed
            acc_v *= self.coast_inflation
        ins: dict[str, Any] = {
            "pos": [_r(x, 3) for x in p], "vel": [_r(x, 3) for x in kf.velocity],
            "rpy_deg": [_r(x / DEG, 3) for x in kf.attitude_rpy],
            "sigma_pos": [_r(x, 3) for x in sig[0:3]], "sigma_vel": [_r(x, 4) for x in sig[3:6]],
            "sigma_att_deg": [_r(x / DEG, 4) for x in sig[6:9]],
            "acc_h_m": round(acc_h, 3), "acc_v_m": round(acc_v, 3),
            "bias_active": kf.bias_active, "zupt": zupt,
        }
        if rep is not None:
            ins["zones"] = [int(d.zone.value) for d in rep.decisions]
            ins["dm"] = [_r(d.dm) for d in rep.decisions]
            ins["actions"] = [d.action.value for d in rep.decisions]
            ins["innov"] = [_r(float(x), 3) for x in kf.y]
            if rep.verdict is not None:
                ins["verdict"] = rep.verdict.value
            for d in rep.decisions:
                self.gate_actions[d.action.value] += 1
        lat = lon = alt = None
        frame = pipeline.frame
        if frame is not None:
            lat, lon, h = frame.to_lla(float(p[0]), float(p[1]), float(p[2]))
            alt = h - (out.epoch.geoid_sep_m or 0.0)
            ins["lla"] = [round(lat, 9), round(lon, 9), round(h, 3)]
        coast_s = t_g - (self._last_fix_t if self._last_fix_t is not None else t_g)
        self._status = f"INS {acc_h:.2f} m" + (" (fix not used as is)" if rep is not None
                                                and not used else "")
        if rep is None:
            ins["coast_s"] = round(coast_s, 3)
            self._status = f"INS coasting, {coast_s:.0f} s, accuracy {acc_h:.1f} m"
            if not self._coast(coast_s, acc_h):
                self._status = f"INS coast limit, {coast_s:.0f} s: no fix"
                ins["output"] = "no fix"
                record = self._base_record(out, t_g, "ins")
                record["ins"] = ins
                self.write_record(record)
                self._send(out)  # the receiver's no-fix epoch: GPS_INPUT fix_type 1
                return
        else:
            self._coast_ended = False
            self._coast_said = -1.0
        record = self._base_record(out, t_g, "ins")
        record["ins"] = ins
        self.write_record(record)
        decision = out.decision._replace(action="accept" if used else "replace",
                                         out_enu=(float(p[0]), float(p[1]), float(p[2])))
        self._send(EpochOutcome(out.epoch, decision, lat, lon, alt, out.t_s,
                                {**(out.record or {}), "ins": ins},
                                heading_deg=out.heading_deg))

    @staticmethod
    def _var_h(kf: InsGnssFilter) -> float:
        """The larger horizontal variance of the position (the fault bias's added while a
        fault is believed), m²."""
        var = np.diag(kf.P)[:2] + (np.diag(kf._Pbb)[:2] if kf.bias_active else 0.0)
        return float(max(var[0], var[1]))

    def _check_coast(self, enu: tuple[float, float, float]) -> None:
        """The first fix after a coast checks the coast's claim: the horizontal NEES
        ``νᵀ (P + R)⁻¹ ν`` of the fix against the coasted position, before the update. Beyond
        χ²₂(0.99) = 9.21 the claim failed: the filter's ``P`` is widened by ``k`` before the
        fix is taken (:meth:`~fdi.insgnss.InsGnssFilter.inflate`), ``k`` the factor on ``P``
        that would have made this return typical (``νᵀ (k P + R)⁻¹ ν = 2``, its mean), so the
        fix pulls the drifted state back and corrects what drifted; and the coast's accuracy
        (GPS_INPUT, the records) is scaled from now on by ``√k``, the largest so far, because
        the filter's model drifted faster than it claimed."""
        kf = self.kf
        assert kf is not None
        zhat, hph = kf.predicted_fix()  # p̂ + ĝ, H P Hᵀ (the receiver's error in the state)
        nu = np.array(enu[:2]) - zhat[:2]
        P = hph[:2, :2] + (kf._Pbb[:2, :2] if kf.bias_active else 0.0)
        R = np.eye(2) * self.params.gnss_sigma_h_m**2
        nees = float(nu @ np.linalg.solve(P + R, nu))
        self.coast_checks += 1
        if not nees > _CHI2_2_99:
            return
        self.coast_failed += 1
        lo, hi = 1.0, 1e8  # ν'(kP + R)⁻¹ν falls with k: bisect (in log) for 2
        for _ in range(60):
            k = math.sqrt(lo * hi)
            if float(nu @ np.linalg.solve(k * P + R, nu)) > 2.0:
                lo = k
            else:
                hi = k
        self.coast_inflation = max(self.coast_inflation, math.sqrt(hi))
        kf.inflate(hi)  # the filter's own claim widened before the fix is taken
        claim = math.sqrt(max(float(P[0, 0]), float(P[1, 1])))
        self.ratelog.warning(
            "coast check", f"INS coast claimed {claim:.2f} m (1σ), the fix returned "
            f"{float(np.hypot(*nu)):.2f} m away (NEES {nees:.1f}): coast accuracies are "
            f"scaled by {self.coast_inflation:.2f} from now on")

    def _coast(self, coast_s: float, acc_h: float) -> bool:
        """A GNSS outage (no fix this epoch): True while the INS's coast goes out as a 3D fix
        with its own accuracy, False (no-fix, as the rover's failsafe sends) once it is past
        ``coast_max_s`` or claims worse than ``coast_max_acc_h_m``, until a fix is used again.
        While it goes out, the failsafe's silence watchdog is held (one message, not a no-fix
        and a 3D fix in turn); past the limit the watchdog runs on and its own no-fix and
        STATUSTEXT follow after ``silence_s``, in agreement."""
        lv = self.live
        if not self._coast_ended and (coast_s > lv.coast_max_s or acc_h > lv.coast_max_acc_h_m):
            self._coast_ended = True
            text = (f"FDI INS: coast limit, {coast_s:.0f} s, accuracy {acc_h:.1f} m: no fix")
            log.warning("%s", text)
            self._statustext(SEVERITY_WARNING, text)
        if self._coast_ended:
            self.coast_no_fix += 1
            return False
        if self.failsafe is not None and not self.failsafe.watchdog.silent:
            self.failsafe.watchdog.valid()  # the INS's output is the valid data meanwhile
        self.coast_epochs += 1
        if self._coast_said < 0.0 or coast_s >= self._coast_said + 5.0:
            self._coast_said = coast_s
            text = f"INS coasting, {coast_s:.0f} s, accuracy {acc_h:.1f} m"
            log.warning("%s", text)
            self._statustext(SEVERITY_WARNING, "FDI " + text)
        return True

    def _statustext(self, severity: int, text: str) -> None:
        if self._mav is None or not self.sending:
            return
        try:
            self._mav.send_statustext(severity, text)
        except Exception as err:  # an output failing must not stop the filter
            self.output_errors += 1
            self.ratelog.warning("output statustext", str(err))

    def _send(self, out: EpochOutcome) -> None:
        if not self.sending:
            return
        for sink in self.sinks:
            try:
                sink.emit(out)
            except Exception as err:  # an output failing must not stop the filter
                self.output_errors += 1
                self.ratelog.warning(f"output {type(sink).__name__}", str(err))

    # ------------------------------------------------------------------ summary

    def summary(self) -> dict[str, Any]:
        if self.pipeline is None:
            return {}
        s = self.pipeline.summary()
        st = self.stats
        s["ins"] = {
            "refused": self.refused, "imu_rate_hz": None if self.rate_hz is None
            else round(self.rate_hz, 2), "time_map": self.time_map,
            "aligned_at": self.aligned_at, "epochs": dict(self.modes),
            "alignment": None if self.alignment is None else {
                "method": self.alignment.method,
                "sigma_tilt_deg": round(self.alignment.sigma_tilt_deg, 5),
                "sigma_yaw_deg": round(self.alignment.sigma_yaw_deg, 5)},
            "zupts": self.zupts, "zarus": self.zarus, "coast_epochs": self.coast_epochs,
            "coast_no_fix": self.coast_no_fix, "coast_checks": self.coast_checks,
            "coast_failed": self.coast_failed,
            "coast_inflation": round(self.coast_inflation, 3),
            "rate_drops": self.rate_drops,
            "align_wait": dict(self.align_wait), "resets": dict(self.resets),
            "gate_actions": dict(self.gate_actions),
            "imu": {"received": st.received, "integrated": st.integrated,
                    "duplicates": st.duplicates, "out_of_order": st.out_of_order,
                    "late": st.late, "no_data": st.no_data, "bad_packets": st.bad_packets},
            "strategy": self.params.strategy, "output_errors": self.output_errors,
        }
        if self.failsafe is not None:
            s["failsafe"] = {"silences": self.failsafe.watchdog.episodes,
                             "no_fix_sent": self.failsafe.no_fix_sent,
                             "statustexts": self.failsafe.statustexts}
        if self.nmea is not None:
            w = self.nmea.writer
            s["nmea_out"] = w.port.counters() if w.port is not None else {
                "dropped": w.dropped_bytes}
        return s
