"""A simulated ArduSub autopilot on a MAVLink link, for the ArduSub ROV's tests and demos.

The vehicle is the ROV plant of :mod:`firmware_host.devtools.rov_sim` (seeded, its compass
faults applied to the reported heading). :class:`ArduSubSim` speaks to the bridge's router over
a real pymavlink endpoint (``udpout:127.0.0.1:PORT``, :mod:`drivers.mavlink.io`):

* ATTITUDE at ``attitude_hz`` (10 Hz; ``yaw`` = the compass heading, faults included; none
  while a ``dropout`` fault is active or the link is unplugged) and HEARTBEAT at 1 Hz
  (``MAV_TYPE_SUBMARINE``, the armed flag, the custom mode);
* MANUAL_CONTROL is accepted only from ``gcs_system_id`` (ArduSub's ``SYSID_MYGCS``) and for
  this vehicle (``target`` = its system id); others are counted in ``refused``;
* the yaw command is ``r / 10`` % of the plant's yaw thrust while armed in a mode that takes the
  pilot's yaw (MANUAL, STABILIZE, ACRO, ALT_HOLD, POSHOLD); 0 otherwise;
* the pilot-input failsafe (``FS_PILOT_INPUT``): no accepted MANUAL_CONTROL for
  ``pilot_timeout_s`` (``FS_PILOT_TIMEOUT``, 3 s) neutralises the controls (``failsafes``
  counts the episodes), as ArduSub's ``failsafe_pilot_input_check`` does for any enabled value
  (``FS_PILOT_INPUT = 2`` also disarms; not simulated).

:meth:`ArduSubSim.step` advances ``dt`` of simulated time: tests drive it in lockstep with the
bridge (no wall clock), :meth:`ArduSubSim.serve` runs it in real time in a thread.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, field

from drivers.mavlink import io as mio
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
    r_log: list[tuple[float, int]] = field(default_factory=list)  # (t, r) accepted


class ArduSubSim:
    """The simulated autopilot (module docstring)."""

    def __init__(self, url: str, sim: SimConfig, faults: Sequence[FaultSpec] = (), *,
                 system_id: int = 1, gcs_system_id: int = 255, armed: bool = True,
                 mode: str = "ALT_HOLD", attitude_hz: float = 10.0,
                 pilot_timeout_s: float = 3.0) -> None:
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
            if self.t + 1e-9 >= self._next_att:
                self._next_att += self.attitude_period_s
                if tel is not None and not self.unplugged:
                    yaw = (tel.heading_deg + 180.0) % 360.0 - 180.0  # ATTITUDE yaw: -pi..pi
                    self.link.send_attitude(int(self.t * 1000), 0.0, 0.0, math.radians(yaw))
                    self.counters.attitude_sent += 1

    def serve(self, stop: threading.Event, dt: float = 0.02) -> None:
        """Real time: :meth:`step` every ``dt`` until ``stop``."""
        next_t = time.monotonic()
        while not stop.is_set():
            self.step(dt)
            next_t += dt
            stop.wait(max(0.0, next_t - time.monotonic()))

    def close(self) -> None:
        self.link.close()
