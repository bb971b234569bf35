"""A simulated ArduSub autopilot on a MAVLink link, for the ArduSub ROV's tests and demos.

The vehicle is the ROV plant of :mod:`firmware_host.devtools.rov_sim` (seeded, its compass
faults applied to the reported heading). :class:`ArduSubSim` speaks to the bridge's router over
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
from collections.abc import Sequence
from dataclasses import dataclass, field

from drivers.mavlink import io as mio
from drivers.mavlink.compass import body_field_mgauss
from drivers.mavlink.modes import MODES
from firmware_host.devtools.rov_sim import FaultSpec, RovPlant, make_plant
from firmware_host.runtime.config_rov import ARDUSUB_YAW_MODES, SimConfig

_YAW_MODES = frozenset(MODES["sub"][m] for m in ARDUSUB_YAW_MODES)


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
                 declination_deg: float = 0.0, rc_yaw_channel: int = 4) -> None:
        if fault_on not in ("attitude", "magnetometer"):
            raise ValueError(f"fault_on: attitude or magnetometer, found {fault_on!r}")
        if compass not in (None, "RAW_IMU", "SCALED_IMU", "SCALED_IMU2", "SCALED_IMU3"):
            raise ValueError(f"compass: not a compass message: {compass!r}")
        self.plant: RovPlant = make_plant(sim, faults)
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
