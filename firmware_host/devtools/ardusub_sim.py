"""A simulated ArduSub autopilot on a MAVLink link, for the ArduSub ROV's tests and demos.

Two vehicles. ``plant = "outland"`` (the default): the ROV plant of
:mod:`firmware_host.devtools.rov_sim` (seeded, its compass faults applied to the reported
heading), the model of the tests written before a real ArduSub was met. ``plant = "ardusub"``:
the ArduSub SITL's own behaviour, calibrated on ``../shared/corpus/ardusub-sitl``
(:mod:`firmware_host.devtools.ardusub_calib`): :class:`SubYawModel`'s yaw in MANUAL (a dead band
of ~13 % of ``r``, a ~9 deg/s kick just above it, 77 deg/s at full stick within 100 ms, slow
coasting), ATTITUDE's yaw as the EKF's (0 until it aligns at 2.0 s, again from 3.8 to 5.4 s;
then the true heading with a slow wander of ``ekf_wander_deg`` and ``ekf_offset_deg``; its
rate the true one, bias-corrected), RAW_IMU's compass ``compass_lag_s`` (0.14 s) behind the
vehicle and its gyro with the plant's bias and noise, each at 10 Hz with one time stamp, and
HEARTBEAT at 1 Hz: the message set and rates of the captures (plus what the bridge's own
``[rov.ardusub]`` asks for).

:class:`ArduSubSim` speaks to the bridge's router over
a real pymavlink endpoint (``udpout:127.0.0.1:PORT``, :mod:`drivers.mavlink.io`):

* ATTITUDE at ``attitude_hz`` (10 Hz; ``yaw`` = the compass heading, faults included; none
  while a ``dropout`` fault is active or the link is unplugged) and HEARTBEAT at 1 Hz
  (``MAV_TYPE_SUBMARINE``, the armed flag, the custom mode);
* MANUAL_CONTROL is accepted only from ``gcs_system_id`` (ArduSub's ``MAV_GCS_SYSID``) and for
  this vehicle (``target`` = its system id); others are counted in ``refused``;
* the yaw command is ``r / 10`` % of the plant's yaw thrust while armed in a mode that takes the
  pilot's yaw (MANUAL, STABILIZE, ACRO, ALT_HOLD, POSHOLD); 0 otherwise;
* the pilot-input failsafe (``FS_PILOT_INPUT``): no accepted MANUAL_CONTROL for
  ``pilot_timeout_s`` (``FS_PILOT_TIMEOUT``, 3 s) neutralises the controls (``failsafes``
  counts the episodes), as ArduSub's ``failsafe_pilot_input_check`` does for any enabled value
  (``FS_PILOT_INPUT = 2`` also disarms; not simulated).

:meth:`ArduSubSim.step` advances ``dt`` of simulated time: tests drive it in lockstep with the
bridge (no wall clock), :meth:`ArduSubSim.serve` runs it in real time in a thread.

The raw compass (``compass = "RAW_IMU"``, ``"SCALED_IMU"``, ``"SCALED_IMU2"`` or
``"SCALED_IMU3"``, at ``imu_hz``): the body-frame field of the compass heading (faults
included) in an Earth field of ``field_mgauss`` (horizontal, down) whose north is
``declination_deg`` east of true north, at a rolling and pitching attitude (``tilt_deg``
amplitudes, reported in ATTITUDE), and the body rates from the plant's yaw gyro, in the same
message (int16: mGauss, mrad/s, as ArduPilot's ``send_raw_imu``). ``fault_on =
"magnetometer"`` puts the injected faults on the magnetometer only: ATTITUDE's yaw is then an
EKF that takes the compass's error in slowly (a first-order lag of ``ekf_tau_s``), so its
heading hides a drift for a while; ``"attitude"`` (the default) reports the faulty compass
heading as ATTITUDE's yaw, as before.

ATTITUDE's ``rollspeed, pitchspeed, yawspeed`` are the same body rates (ArduPilot sends the
gyro there).

RC_CHANNELS_OVERRIDE from ``gcs_system_id`` for this vehicle sets the yaw on
``rc_yaw_channel`` (``(pwm - 1500) / 4`` % over 1100..1900; UINT16_MAX ignores the field, 0
releases it: no yaw) and counts as pilot input for the failsafe (ArduSub's
``GCS_MAVLINK_Sub::handle_message``); MANUAL_CONTROL sets it to ``r / 10`` %.
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from drivers.mavlink import io as mio
from drivers.mavlink.compass import body_field_mgauss
from drivers.mavlink.modes import MODES
from drivers.outland.link import Telemetry
from firmware_host.devtools.rov_sim import FaultSpec, RovPlant, apply_faults, make_plant
from firmware_host.runtime.config_rov import ARDUSUB_YAW_MODES, SimConfig

_YAW_MODES = frozenset(MODES["sub"][m] for m in ARDUSUB_YAW_MODES)


@dataclass(frozen=True)
class SubYawModel:
    """ArduSub SITL's yaw in MANUAL (``vectored`` frame), as measured on the captures of
    ``../shared/corpus/ardusub-sitl`` (:mod:`firmware_host.devtools.ardusub_calib` fits it).

    The yaw rate ``r`` (deg/s) answers the pilot's MANUAL_CONTROL ``r`` (``u``, -1000..1000)::

        T(u) = sign(u) k (|u| / 1000)^p    if |u| > u0(sign u), else 0           (1)
        dr/dt = T(u) + D(t) - c r |r|^(q - 1) - d r                              (2)
        dpsi/dt = r                                                              (3)

    (1) is a thrust with a dead band: ArduSub passes ``r`` at the joystick gain to the yaw
    channel, and a command within ``u0`` (130 of 1000 turning right, 128 left on the captures)
    moves nothing, while one just above it turns the vehicle at ~7 deg/s at once. (2)'s drag
    grows faster than the rate (``q`` ~ 3): the turn at r = 1000 reaches 77 deg/s within one
    100 ms ATTITUDE period, while an uncommanded 1 deg/s takes ~10 s to fall to 0.3 deg/s.
    ``D(t)`` is the disturbance a current puts on the yaw (deg/s^2; none in the SITL).
    """

    # fitted on the att capture (fdi-bridge sim ardusub-calib --fit att), checked on raw
    u0_pos: float = 129.89
    u0_neg: float = 122.32
    k: float = 148779.8  # deg/s^2 at |u| = 1000
    p: float = 3.1882
    c: float = 0.21039  # (deg/s)^(1 - q) / s
    q: float = 3.0917
    d: float = 0.02707  # 1/s

    def thrust(self, u: float) -> float:
        """(1): the yaw acceleration of the command ``u`` (deg/s^2)."""
        u0 = self.u0_pos if u > 0 else self.u0_neg
        if abs(u) <= u0:
            return 0.0
        return math.copysign(self.k * (abs(u) / 1000.0) ** self.p, u)

    def drag(self, r: float) -> float:
        """(2)'s damping at the rate ``r`` (deg/s^2)."""
        return self.c * r * abs(r) ** (self.q - 1.0) + self.d * r

    def rate_for(self, accel: float) -> float:
        """The steady rate a constant acceleration holds against the drag (deg/s)."""
        if accel == 0.0:
            return 0.0
        lo, hi = 0.0, 1.0
        while self.drag(hi) < abs(accel):
            hi *= 2.0
        for _ in range(60):  # drag is increasing: bisection
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if self.drag(mid) < abs(accel) else (lo, mid)
        return math.copysign(0.5 * (lo + hi), accel)

    def step_rate(self, r: float, accel: float, h: float) -> float:
        """One backward-Euler step of (2) over ``h`` s: the ``x`` with
        ``x + h drag(x) = r + h accel`` (the drag is stiff at speed: 77 deg/s settles in
        ~10 ms; monotone in ``x``, so Newton's method kept inside a bracket converges)."""
        b = r + h * accel
        if b == 0.0:
            return 0.0
        lo, hi = (0.0, b) if b > 0 else (b, 0.0)
        x = b
        for _ in range(60):
            g = x + h * self.drag(x) - b
            dg = 1.0 + h * (self.c * self.q * abs(x) ** (self.q - 1.0) + self.d)
            if g > 0:
                hi = x
            else:
                lo = x
            xn = x - g / dg
            if not lo <= xn <= hi:
                xn = 0.5 * (lo + hi)
            if abs(xn - x) < 1e-9:
                return xn
            x = xn
        return x


SUB_YAW = SubYawModel()
"""The fitted model (docs/rov-ardusub.md, "The simulator, calibrated")."""

EKF_ALIGN_S = ((0.0, 2.0), (3.8, 5.4))
"""Seconds after boot during which ArduSub's EKF reports yaw 0 (the vehicle still): it aligns
its yaw at 2.0 s, restarts it at 3.8 s and aligns again at 5.4 s (both captures)."""
EKF_WANDER_DEG = 0.2
"""The sigma of the EKF yaw's slow wander against the true heading (a first-order
Gauss-Markov process; the captures' EKF wanders +-0.4 deg, 0.02-0.04 deg/s)."""
COMPASS_LAG_S = 0.14
"""RAW_IMU's compass trails the vehicle by 0.12-0.17 s on the raw capture."""


class SubPlant(RovPlant):
    """The ArduSub vehicle: :class:`SubYawModel`'s yaw with the compass, gyro and faults of
    :class:`~firmware_host.devtools.rov_sim.RovPlant`. ``yaw_pct`` is MANUAL_CONTROL's ``r``
    / 10. The current (``current_max_pct``, ``current_amp_pct``, ``current_period_s`` of the
    sim config) is read as the yaw rate it would hold alone (deg/s): ``D(t)`` is the
    acceleration that holds that rate against the drag."""

    SUBSTEP_S = 0.01

    def __init__(self, cfg: SimConfig, faults: Sequence[FaultSpec] = (),
                 model: SubYawModel = SUB_YAW) -> None:
        super().__init__(cfg, faults)
        self.model = model
        self.fault_err = 0.0

    def advance(self, yaw_pct: float, dt: float, surge_pct: float = 0.0) -> None:
        m = self.model
        psi0 = self.psi
        n = max(1, math.ceil(dt / self.SUBSTEP_S - 1e-9))
        h = dt / n
        thrust = m.thrust(yaw_pct * 10.0)
        for i in range(n):
            accel = thrust + m.drag(self.current_pct(self.t + (i + 0.5) * h))
            r1 = m.step_rate(self.r, accel, h)
            self.psi += 0.5 * (self.r + r1) * h  # (3), trapezoidal
            self.r = r1
        self.t += dt
        self._rate_avg = (self.psi - psi0) / dt

    @property
    def rate_dps(self) -> float:
        """The true yaw rate now (deg/s): SIMSTATE's, and the EKF's (bias-corrected)."""
        return self.r

    def measure(self) -> Telemetry | None:
        """The compass as :meth:`RovPlant.measure` reads it (the same random draws, the same
        faults), keeping the faults' share apart: ``fault_err`` (deg) is what the faults add to
        the healthy reading ``psi + noise``, which the EKF model needs on its own."""
        t = self.t
        noise = float(self.rng.normal(0.0, self.cfg.compass_noise_deg))
        healthy = self.psi + noise
        faulty = apply_faults(self.faults, t, healthy, self.rng, self._stuck)
        self._dropout = faulty is None
        if faulty is None:
            return None
        h = faulty
        self.fault_err = (h - healthy + 180.0) % 360.0 - 180.0
        return Telemetry(h % 360.0, self.cfg.depth_m, 0.0, 0.0, 0)


@dataclass
class ArduSubCounters:
    attitude_sent: int = 0
    heartbeat_sent: int = 0
    accepted: int = 0
    refused: int = 0  # MANUAL_CONTROL from another system id, or for another vehicle
    failsafes: int = 0
    imu_sent: int = 0
    rc_accepted: int = 0
    rc_refused: int = 0
    rc_releases: int = 0
    r_log: list[tuple[float, int]] = field(default_factory=list)  # (t, r) accepted


class ArduSubSim:
    """The simulated autopilot (module docstring)."""

    def __init__(self, url: str, sim: SimConfig, faults: Sequence[FaultSpec] = (), *,
                 system_id: int = 1, gcs_system_id: int = 255, armed: bool = True,
                 mode: str = "ALT_HOLD", attitude_hz: float = 10.0,
                 pilot_timeout_s: float = 3.0, compass: str | None = None,
                 imu_hz: float = 10.0, fault_on: str = "attitude", ekf_tau_s: float = 30.0,
                 tilt_deg: tuple[float, float] = (3.0, 2.0),
                 field_mgauss: tuple[float, float] = (200.0, 400.0),
                 declination_deg: float = 0.0, rc_yaw_channel: int = 4,
                 plant: str = "outland", ekf_offset_deg: float = 0.0,
                 ekf_align_s: tuple[tuple[float, float], ...] = EKF_ALIGN_S,
                 ekf_wander_deg: float = EKF_WANDER_DEG, ekf_wander_tau_s: float = 10.0,
                 compass_lag_s: float = COMPASS_LAG_S, model: SubYawModel = SUB_YAW) -> None:
        if plant not in ("outland", "ardusub"):
            raise ValueError(f"plant: outland or ardusub, found {plant!r}")
        if fault_on not in ("attitude", "magnetometer"):
            raise ValueError(f"fault_on: attitude or magnetometer, found {fault_on!r}")
        if compass not in (None, "RAW_IMU", "SCALED_IMU", "SCALED_IMU2", "SCALED_IMU3"):
            raise ValueError(f"compass: not a compass message: {compass!r}")
        self.sub: SubPlant | None = SubPlant(sim, faults, model) if plant == "ardusub" else None
        self.plant: RovPlant = self.sub if self.sub is not None else make_plant(sim, faults)
        self.ekf_offset_deg = ekf_offset_deg
        self.ekf_align_s = ekf_align_s
        self.ekf_wander_deg = ekf_wander_deg
        self.ekf_wander_tau_s = ekf_wander_tau_s
        self._wander = 0.0
        self._wander_rng = np.random.default_rng([sim.seed, 3])  # its own stream
        self.compass_lag_s = compass_lag_s
        self._compass_hist: deque[tuple[float, float]] = deque()  # (t, compass heading)
        self.link = mio.MavEndpoint(url, source_system=system_id, source_component=1)
        self.system_id = system_id
        self.gcs_system_id = gcs_system_id
        self.armed = armed
        self.mode = MODES["sub"][mode]
        self.attitude_period_s = 1.0 / attitude_hz
        self.pilot_timeout_s = pilot_timeout_s
        self.unplugged = False
        self.last_axes: tuple[int, int, int, int] | None = None
        self.counters = ArduSubCounters()
        self.t = 0.0
        self._next_att = 0.0
        self._next_hb = 0.0
        self._r = 0
        self._since_input = 0.0
        self._in_failsafe = False
        self._lock = threading.Lock()
        self.compass = compass
        self.imu_period_s = 1.0 / imu_hz
        self._next_imu = 0.0
        self.fault_on = fault_on
        self.ekf_tau_s = ekf_tau_s
        self._ekf_err = 0.0  # the EKF's share of the compass error, deg
        self.tilt_deg = tilt_deg if compass is not None else (0.0, 0.0)
        self.field_mgauss = field_mgauss
        self.declination_deg = declination_deg
        self.rc_yaw_channel = rc_yaw_channel
        self.last_rc: tuple[int, ...] | None = None

    def attitude_rp(self, t: float) -> tuple[float, float, float, float]:
        """(roll, pitch, roll rate, pitch rate) at ``t`` (rad, rad/s): slow waves."""
        ar, ap = (math.radians(a) for a in self.tilt_deg)
        wr, wp = 2 * math.pi / 6.0, 2 * math.pi / 8.0
        return (ar * math.sin(wr * t), ap * math.sin(wp * t + 1.0),
                ar * wr * math.cos(wr * t), ap * wp * math.cos(wp * t + 1.0))

    def set_mode(self, mode: str, armed: bool | None = None) -> None:
        with self._lock:
            self.mode = MODES["sub"][mode]
            if armed is not None:
                self.armed = armed

    def _receive(self) -> None:
        msg = self.link.recv(0.0)
        while msg is not None:
            if msg.get_type() == "MANUAL_CONTROL" and not self.unplugged:
                if msg.get_srcSystem() == self.gcs_system_id and msg.target == self.system_id:
                    self._r = int(msg.r)
                    self._since_input = 0.0
                    self._in_failsafe = False
                    self.counters.accepted += 1
                    self.counters.r_log.append((round(self.t, 3), self._r))
                    self.last_axes = (int(msg.x), int(msg.y), int(msg.z), int(msg.r))
                else:
                    self.counters.refused += 1
            elif msg.get_type() == "RC_CHANNELS_OVERRIDE" and not self.unplugged:
                if (msg.get_srcSystem() == self.gcs_system_id
                        and msg.target_system == self.system_id):
                    self.counters.rc_accepted += 1
                    self._since_input = 0.0  # pilot input for FS_PILOT_INPUT, as ArduSub
                    self._in_failsafe = False
                    chans = tuple(int(getattr(msg, f"chan{i}_raw")) for i in range(1, 19))
                    self.last_rc = chans
                    pwm = chans[self.rc_yaw_channel - 1]
                    if pwm == 0:
                        self._r = 0
                        self.counters.rc_releases += 1
                    elif pwm != 0xFFFF:
                        self._r = round((min(max(pwm, 1100), 1900) - 1500) * 2.5)
                    self.counters.r_log.append((round(self.t, 3), self._r))
                else:
                    self.counters.rc_refused += 1
            msg = self.link.recv(0.0)

    def pump(self) -> None:
        """Read what has arrived (lockstep tests: before the next :meth:`step`)."""
        with self._lock:
            self._receive()

    def yaw_pct(self) -> float:
        """The yaw thrust the autopilot applies now (% of full)."""
        if not self.armed or self.mode not in _YAW_MODES or self._in_failsafe:
            return 0.0
        return max(-100.0, min(100.0, self._r / 10.0))

    def step(self, dt: float) -> None:
        """Read the link, advance the vehicle ``dt``, report what is due."""
        with self._lock:
            self._receive()
            self._since_input += dt
            if not self._in_failsafe and self._since_input > self.pilot_timeout_s + 1e-9:
                self._in_failsafe = True
                self.counters.failsafes += 1
            self.plant.advance(self.yaw_pct(), dt)
            self.t += dt
            tel = self.plant.measure()
            if self.sub is not None:
                self._step_sub(tel, dt)
                return
            if self.t + 1e-9 >= self._next_hb:
                self._next_hb += 1.0
                if not self.unplugged:
                    base = mio.MAV_MODE_FLAG_SAFETY_ARMED if self.armed else 0
                    self.link.send_vehicle_heartbeat(mio.MAV_TYPE_SUBMARINE, base, self.mode)
                    self.counters.heartbeat_sent += 1
            gyro = self.plant.gyro_dps()  # its own random stream: the compass is unchanged
            truth = self.plant.heading_true
            if tel is not None:
                err = (tel.heading_deg - truth + 180.0) % 360.0 - 180.0
                self._ekf_err += (err - self._ekf_err) * min(1.0, dt / self.ekf_tau_s)
            roll, pitch, droll, dpitch = self.attitude_rp(self.t)
            if self.fault_on == "magnetometer":
                att_yaw: float | None = truth + self._ekf_err  # the EKF: gyro + slow compass
            else:
                att_yaw = None if tel is None else tel.heading_deg
            if self.t + 1e-9 >= self._next_att:
                self._next_att += self.attitude_period_s
                if att_yaw is not None and not self.unplugged:
                    yaw = (att_yaw + 180.0) % 360.0 - 180.0  # ATTITUDE yaw: -pi..pi
                    rates = self._body_rates(gyro, roll, pitch, droll, dpitch)
                    self.link.send_attitude(int(self.t * 1000), roll, pitch, math.radians(yaw),
                                            rates)
                    self.counters.attitude_sent += 1
            if self.compass is not None and self.t + 1e-9 >= self._next_imu:
                self._next_imu += self.imu_period_s
                if tel is not None and not self.unplugged:
                    h, d = self.field_mgauss
                    mag = body_field_mgauss(tel.heading_deg, roll, pitch, h, d,
                                            self.declination_deg)
                    p, q, r = self._body_rates(gyro, roll, pitch, droll, dpitch)
                    m = (round(mag[0]), round(mag[1]), round(mag[2]))
                    g = (round(p * 1000), round(q * 1000), round(r * 1000))
                    acc = (0, 0, -1000)
                    if self.compass == "RAW_IMU":
                        self.link.send_raw_imu(int(self.t * 1e6), acc, g, mag=m)
                    else:
                        inst = {"SCALED_IMU": 0, "SCALED_IMU2": 1, "SCALED_IMU3": 2}
                        self.link.send_scaled_imu(inst[self.compass], int(self.t * 1000), acc,
                                                  g, m)
                    self.counters.imu_sent += 1

    def ekf_aligning(self) -> bool:
        return any(a <= self.t < b for a, b in self.ekf_align_s)

    def ekf_yaw(self) -> float | None:
        """ATTITUDE's yaw now (deg) with the ``ardusub`` plant: the EKF. 0 while it aligns
        (``ekf_align_s``); else the true heading, the frame offset (``ekf_offset_deg``: the
        SITL's declination with ``COMPASS_DEC 0``), the slow wander, and the compass faults:
        all of them at once with ``fault_on = "attitude"``, through the ``ekf_tau_s`` lag
        with ``"magnetometer"``. None while the compass drops out (``"attitude"``)."""
        if self.ekf_aligning():
            return 0.0
        assert self.sub is not None
        if self.fault_on == "attitude":
            if self.sub._dropout:
                return None
            err = self.sub.fault_err
        else:
            err = self._ekf_err
        return self.sub.psi + self.ekf_offset_deg + self._wander + err

    def _compass_now(self, tel: Telemetry | None) -> float | None:
        """The compass heading ``compass_lag_s`` ago (RAW_IMU's lag), None without one."""
        if tel is None:
            self._compass_hist.clear()
            return None
        hist = self._compass_hist
        hist.append((self.t, tel.heading_deg))
        target = self.t - self.compass_lag_s
        while len(hist) > 1 and hist[1][0] <= target + 1e-9:
            hist.popleft()
        (t0, h0) = hist[0]
        if len(hist) == 1 or t0 >= target:
            return h0
        t1, h1 = hist[1]  # between two steps: interpolated, across 0/360
        dh = (h1 - h0 + 180.0) % 360.0 - 180.0
        return (h0 + dh * (target - t0) / (t1 - t0)) % 360.0

    def _step_sub(self, tel: Telemetry | None, dt: float) -> None:
        """The rest of :meth:`step` with the ``ardusub`` plant (module docstring)."""
        sub = self.sub
        assert sub is not None
        a = math.exp(-dt / self.ekf_wander_tau_s)  # Gauss-Markov, exact over dt
        self._wander = (a * self._wander + self.ekf_wander_deg * math.sqrt(1.0 - a * a)
                        * float(self._wander_rng.normal()))
        if tel is not None:
            self._ekf_err += (sub.fault_err - self._ekf_err) * min(1.0, dt / self.ekf_tau_s)
        if self.t + 1e-9 >= self._next_hb:
            self._next_hb += 1.0
            if not self.unplugged:
                base = mio.MAV_MODE_FLAG_SAFETY_ARMED if self.armed else 0
                self.link.send_vehicle_heartbeat(mio.MAV_TYPE_SUBMARINE, base, self.mode)
                self.counters.heartbeat_sent += 1
        gyro = sub.gyro_dps()  # RAW_IMU's: the plant's bias and noise
        roll, pitch, droll, dpitch = self.attitude_rp(self.t)
        compass = self._compass_now(tel)
        att_due = self.t + 1e-9 >= self._next_att
        if att_due:
            self._next_att += self.attitude_period_s
            yaw = self.ekf_yaw()
            if yaw is not None and not self.unplugged:
                rate = 0.0 if self.ekf_aligning() else sub.rate_dps  # bias-corrected
                rates = self._body_rates(rate, roll, pitch, droll, dpitch)
                self.link.send_attitude(round(self.t * 1000), roll, pitch,
                                        math.radians((yaw + 180.0) % 360.0 - 180.0), rates)
                self.counters.attitude_sent += 1
        if self.compass is not None and self.t + 1e-9 >= self._next_imu:
            self._next_imu += self.imu_period_s
            if compass is not None and not self.unplugged:
                self._send_compass(compass, gyro, roll, pitch, droll, dpitch)

    def _send_compass(self, heading_deg: float, gyro: float | None, roll: float, pitch: float,
                      droll: float, dpitch: float) -> None:
        h, d = self.field_mgauss
        mag = body_field_mgauss(heading_deg, roll, pitch, h, d, self.declination_deg)
        p, q, r = self._body_rates(gyro, roll, pitch, droll, dpitch)
        m = (round(mag[0]), round(mag[1]), round(mag[2]))
        g = (round(p * 1000), round(q * 1000), round(r * 1000))
        acc = (0, 0, -1000)
        if self.compass == "RAW_IMU":
            self.link.send_raw_imu(round(self.t * 1e6), acc, g, mag=m)
        elif self.compass is not None:
            inst = {"SCALED_IMU": 0, "SCALED_IMU2": 1, "SCALED_IMU3": 2}
            self.link.send_scaled_imu(inst[self.compass], round(self.t * 1000), acc, g, m)
        self.counters.imu_sent += 1

    @staticmethod
    def _body_rates(gyro_dps: float | None, roll: float, pitch: float, droll: float,
                    dpitch: float) -> tuple[float, float, float]:
        """Body rates (p, q, r) in rad/s of the Euler rates (the heading's from the gyro)."""
        if gyro_dps is None:
            return (0.0, 0.0, 0.0)
        dpsi = math.radians(gyro_dps)
        sr, cr = math.sin(roll), math.cos(roll)
        sp, cp = math.sin(pitch), math.cos(pitch)
        return (droll - dpsi * sp, dpitch * cr + dpsi * sr * cp, -dpitch * sr + dpsi * cr * cp)

    def serve(self, stop: threading.Event, dt: float = 0.02) -> None:
        """Real time: :meth:`step` every ``dt`` until ``stop``."""
        next_t = time.monotonic()
        while not stop.is_set():
            self.step(dt)
            next_t += dt
            stop.wait(max(0.0, next_t - time.monotonic()))

    def close(self) -> None:
        self.link.close()
