"""The ROV behind the MAVLink router: heading hold through an autopilot, FDI to the operator.

Where the vehicle is driven through an autopilot (ArduSub) instead of the Outland link, the
heading-hold loop (:class:`~firmware_host.rov.control.RovController`: compass FDI, substitution,
PID) reads the vehicle's heading from the autopilot's ATTITUDE (``yaw``, via
:meth:`Router.listen <firmware_host.mavlink.router.Router.listen>`) and sends its thrust as
MANUAL_CONTROL with the ground station's system id (``pilot_system_id``) and the vehicle as
target: ArduSub takes pilot input only from its ground station (``SYSID_MYGCS``).

:class:`ArduSubRovVehicle` is this loop as a vehicle of the runtime
(:class:`~firmware_host.runtime.runner.Runner`, period-paced, no port of its own: the router's
autopilot link is its input and output).

:class:`RovOperatorSink` is the per-epoch sink of an ROV vehicle (this module's, or
:class:`~firmware_host.rov.vehicle.OutlandRovVehicle` on the Outland link when a ``[mavlink]``
router is attached), writing to a :class:`~firmware_host.runtime.mavout.MavlinkOutput`: per
epoch the corrected heading and the detector's statistics
as NAMED_VALUE_FLOAT (:data:`STAT_NAMES`, sent at the router's ``stats_hz``), and STATUSTEXT for
each detector event and for a telemetry dropout, with severities.

ArduSub's rules (docs/rov-ardusub.md; ``[rov.ardusub]``,
:class:`~firmware_host.runtime.config_rov.ArduSubConfig`):

* ArduSub takes MANUAL_CONTROL only from its ground station (``SYSID_MYGCS``): the router sends
  it from ``[mavlink] pilot_system_id``;
* ``steer = false``: detect only (the detector runs on the pilot's yaw, nothing is sent);
* the bridge steers (:data:`STEERING`) only while the autopilot's HEARTBEAT is fresh
  (``heartbeat_timeout_s``), says it is armed, and its mode is one of ``modes`` (modes whose
  pilot yaw is MANUAL_CONTROL ``r``: MANUAL, STABILIZE, ACRO, ALT_HOLD, POSHOLD; in AUTO, GUIDED,
  CIRCLE, SURFACE the autopilot owns the heading). Otherwise it sends nothing of its own and the
  pilot's MANUAL_CONTROL passes unchanged; each change of state is logged and sent as a
  STATUSTEXT once;
* the pilot's MANUAL_CONTROL from a ground station is intercepted by the router
  (:meth:`Router.intercept <firmware_host.mavlink.router.Router.intercept>`): while the bridge
  steers, its ``x``, ``y``, ``z`` and buttons go out unchanged with the bridge's ``r``, at the
  bridge's 5 Hz; a pilot ``|r|`` above ``yaw_dead_band`` takes over at once (the pilot's frames
  pass unchanged, "pilot" in the records, logged), and after the stick has been back within the
  dead band for ``pilot_release_s`` the bridge holds the heading the pilot left it on;
* never mask ArduSub's pilot-input failsafe (``FS_PILOT_INPUT``, after ``FS_PILOT_TIMEOUT``,
  3 s by default): once a pilot has been seen, the bridge stops sending when the pilot's
  MANUAL_CONTROL has been silent for ``pilot_timeout_s`` (< 3 s). Without a pilot at all (an
  unattended heading hold) the bridge's own MANUAL_CONTROL keeps the autopilot's failsafe quiet
  while the bridge is running and steering; it stops when the bridge stops;
* heading silence (no ATTITUDE): the controller's dropout rule holds the last command for
  ``dropout_hold_s``, then neutral yaw (``r = 0``, the pilot's other axes still passed), with a
  STATUSTEXT; ATTITUDE back: resumes, said (:class:`RovOperatorSink`).

MANUAL_CONTROL from a :class:`~drivers.outland.link.ThrusterCommand` (ArduSub's pilot axes):
``x = 10 (port + starboard) / 2`` (forward), ``r = 10 (port - starboard) / 2`` (yaw, positive
clockwise), ``y = 10 lateral``, ``z = 500 + 5 vertical`` (0..1000, 500 neutral), all in
-1000..1000 and clamped.
"""

from __future__ import annotations

import logging
import math
import threading
from collections import Counter
from collections.abc import Callable
from typing import Any, Literal

from drivers.mavlink import io as mio
from drivers.mavlink.framer import MavFrame
from drivers.mavlink.modes import MODES
from drivers.outland.link import ThrusterCommand
from fdi.errors import ConfigError
from firmware_host.mavlink.router import Router
from firmware_host.rov.config import RovConfig
from firmware_host.rov.control import RovController, epoch_record
from firmware_host.runtime.failsafe import RovFailsafeMonitor
from firmware_host.runtime.mavout import MavlinkOutput, RouterOutput
from firmware_host.runtime.records import EpochLog
from firmware_host.runtime.vehicle import Context, MavlinkSpec, PortSpec

log = logging.getLogger(__name__)

STEERING = "steer"
"""The bridge's state while it commands the yaw (others: :data:`STATE_TEXT`)."""

STATE_TEXT: dict[str, tuple[int, str]] = {
    STEERING: (mio.MAV_SEVERITY_NOTICE, "FDI heading hold: steering yaw"),
    "no_heartbeat": (mio.MAV_SEVERITY_WARNING, "FDI heading hold: no autopilot heartbeat"),
    "disarmed": (mio.MAV_SEVERITY_INFO, "FDI heading hold: vehicle disarmed, not steering"),
    "mode": (mio.MAV_SEVERITY_WARNING, "FDI heading hold: mode {mode} not steered"),
    "pilot": (mio.MAV_SEVERITY_NOTICE, "FDI heading hold: pilot yaw, yielding"),
    "pilot_silent": (mio.MAV_SEVERITY_WARNING, "FDI heading hold: pilot input lost, not sending"),
    "detect_only": (mio.MAV_SEVERITY_INFO, "FDI heading hold: detect only, not steering"),
}
_SUB_MODE_NAMES = {n: name for name, n in MODES["sub"].items()}

STAT_NAMES = {
    "HDG": "heading used by the hold (corrected), deg",
    "HDG_MEAS": "compass heading as measured, deg",
    "HDG_E2": "LMS prediction error e², deg²",
    "HDG_R": "R(k), the detector's signal-to-noise criterion",
    "HDG_V": "V(k), the detector's second criterion",
    "HDG_FAULT": "1 while a confirmed compass fault is handled",
    "HDG_SUBST": "1 while the heading is substituted (not the sensor's)",
}
"""NAMED_VALUE_FLOAT names (at most 10 characters) and what they carry."""

# Detector events -> (MAV_SEVERITY, text).
EVENT_TEXT: dict[str, tuple[int, str]] = {
    "suspect": (mio.MAV_SEVERITY_WARNING, "FDI compass: suspect"),
    "confirmed": (mio.MAV_SEVERITY_CRITICAL, "FDI compass: fault confirmed, heading substituted"),
    "stuck": (mio.MAV_SEVERITY_CRITICAL, "FDI compass: sensor stuck, heading substituted"),
    "dismissed": (mio.MAV_SEVERITY_INFO, "FDI compass: suspicion dismissed"),
    "compensating": (mio.MAV_SEVERITY_WARNING, "FDI compass: compensating the fault"),
    "fallback": (mio.MAV_SEVERITY_ALERT, "FDI compass: fallback, check the heading"),
    "recovered": (mio.MAV_SEVERITY_NOTICE, "FDI compass: sensor recovered"),
}
ACTION_TEXT: dict[str, tuple[int, str]] = {
    "hold": (mio.MAV_SEVERITY_WARNING, "FDI compass: telemetry lost, holding last command"),
    "neutral": (mio.MAV_SEVERITY_CRITICAL, "FDI compass: telemetry lost, neutral thrust"),
}


def _axis(value: float, lo: int = -1000, hi: int = 1000) -> int:
    return min(max(round(value), lo), hi)


def manual_control_axes(cmd: ThrusterCommand) -> tuple[int, int, int, int]:
    """``(x, y, z, r)`` of MANUAL_CONTROL for ``cmd`` (see the module docstring)."""
    return (
        _axis(10.0 * (cmd.port_pct + cmd.starboard_pct) / 2.0),
        _axis(10.0 * cmd.lateral_pct),
        _axis(500.0 + 5.0 * cmd.vertical_pct, 0, 1000),
        _axis(10.0 * (cmd.port_pct - cmd.starboard_pct) / 2.0),
    )


class RovOperatorSink:
    """``on_epoch`` sink: heading, statistics and events to the operator (module docstring)."""

    def __init__(self, output: MavlinkOutput) -> None:
        self.output = output
        self._action = "init"

    def __call__(self, rec: dict[str, Any]) -> None:
        out = self.output
        values = {
            "HDG": rec.get("heading_used"),
            "HDG_MEAS": rec.get("heading_meas"),
            "HDG_E2": rec.get("e2"),
            "HDG_R": rec.get("snr"),
            "HDG_V": rec.get("V"),
            "HDG_FAULT": float(bool(rec.get("fault"))),
            "HDG_SUBST": float(rec.get("source", "sensor") != "sensor"),
        }
        for name, value in values.items():
            if value is not None and math.isfinite(float(value)):
                out.send_named_value(name, float(value))
        event = str(rec.get("event") or "")
        if event in EVENT_TEXT:
            severity, text = EVENT_TEXT[event]
            kind = rec.get("fault_kind") or ""
            out.send_statustext(severity, f"{text} ({kind})" if kind else text)
        action = str(rec.get("action", ""))
        if self._action == "init" and action == "hold":
            return  # the first periods before the first telemetry: nothing was lost yet
        if action != self._action and action in ACTION_TEXT:
            out.send_statustext(*ACTION_TEXT[action])
        elif self._action in ACTION_TEXT and action not in ACTION_TEXT:
            out.send_statustext(mio.MAV_SEVERITY_NOTICE, "FDI compass: telemetry back")
        self._action = action


class AutopilotHeading:
    """The newest ATTITUDE yaw from the autopilot (deg, 0..360), taken once per period."""

    def __init__(self, router: Router, autopilot: tuple[int, int] = (1, 1)) -> None:
        self.autopilot = autopilot
        self._lock = threading.Lock()
        self._latest: float | None = None
        self.received = 0
        router.listen("ATTITUDE", self._on_attitude)

    def _on_attitude(self, frame: MavFrame) -> None:
        if (frame.sysid, frame.compid) != self.autopilot:
            return
        msg = mio.decode_packet(frame.raw)
        if msg is None:
            return
        with self._lock:
            self._latest = math.degrees(float(msg.yaw)) % 360.0
            self.received += 1

    def take(self) -> float | None:
        """The heading received since the last call, None when none came (a dropout)."""
        with self._lock:
            value, self._latest = self._latest, None
        return value


class AutopilotState:
    """The newest HEARTBEAT of the autopilot (armed flag, custom mode), taken once per period."""

    def __init__(self, router: Router, autopilot: tuple[int, int] = (1, 1)) -> None:
        self.autopilot = autopilot
        self._lock = threading.Lock()
        self._latest: tuple[bool, int] | None = None
        self.received = 0
        router.listen("HEARTBEAT", self._on_heartbeat)

    def _on_heartbeat(self, frame: MavFrame) -> None:
        if (frame.sysid, frame.compid) != self.autopilot:
            return
        msg = mio.decode_packet(frame.raw)
        if msg is None:
            return
        armed = bool(int(msg.base_mode) & mio.MAV_MODE_FLAG_SAFETY_ARMED)
        with self._lock:
            self._latest = (armed, int(msg.custom_mode))
            self.received += 1

    def take(self) -> tuple[bool, int] | None:
        with self._lock:
            value, self._latest = self._latest, None
        return value


class PilotInput:
    """The pilot's MANUAL_CONTROL from the ground stations, intercepted in the router.

    A frame passes unchanged when the bridge is not steering or the pilot's ``|r|`` is above the
    dead band; otherwise it is kept (the bridge sends its axes with its own yaw).
    """

    def __init__(self, router: Router, vehicle: int, dead_band: int) -> None:
        self.vehicle = vehicle
        self.dead_band = dead_band
        self.steering = False  # set by the loop each period
        self._lock = threading.Lock()
        self._latest: tuple[int, int, int, int, int] | None = None
        self.received = 0
        router.intercept("MANUAL_CONTROL", self._on_manual_control)

    def _on_manual_control(self, frame: MavFrame) -> bool:
        msg = mio.decode_packet(frame.raw)
        if msg is None or int(msg.target) != self.vehicle:
            return True  # not for this vehicle (ArduSub ignores it too): forwarded as it is
        axes = (int(msg.x), int(msg.y), int(msg.z), int(msg.r), int(msg.buttons))
        with self._lock:
            self._latest = axes
            self.received += 1
        return not self.steering or abs(axes[3]) > self.dead_band

    def take(self) -> tuple[int, int, int, int, int] | None:
        with self._lock:
            value, self._latest = self._latest, None
        return value


class RovAutopilotLoop:
    """The ROV heading hold driven through an autopilot (see the module docstring)."""

    def __init__(
        self,
        cfg: RovConfig,
        router: Router,
        *,
        ft: bool = True,
        vehicle_system_id: int = 1,
        on_epoch: Callable[[dict[str, Any]], None] | None = None,
    ) -> None:
        self.cfg = cfg
        self.acfg = cfg.ardusub
        self.router = router
        self.vehicle = vehicle_system_id
        self.ctl = RovController(cfg, ft=ft)
        self.heading = AutopilotHeading(router, (vehicle_system_id, 1))
        self.autopilot = AutopilotState(router, (vehicle_system_id, 1))
        self.pilot = PilotInput(router, vehicle_system_id, self.acfg.yaw_dead_band)
        self.output = RouterOutput(router)
        self.operator = RovOperatorSink(self.output)
        self.on_epoch = on_epoch
        self.t = 0.0
        self.armed = False
        self.mode: int | None = None
        self._hb_age: float | None = None  # s since the last HEARTBEAT; None: none yet
        self._pilot_axes: tuple[int, int, int, int, int] | None = None
        self._pilot_age = 0.0
        self._pilot_has = False  # the pilot is steering (yaw above the dead band)
        self._centred_s = 0.0
        self.state = "init"
        self.states: Counter[str] = Counter()
        self.takeovers = 0
        self.sent = 0

    def _gate(self) -> str:
        """Why the bridge may not steer now, or :data:`STEERING`."""
        a = self.acfg
        if not a.steer:
            return "detect_only"
        if self._hb_age is None or self._hb_age > a.heartbeat_timeout_s + 1e-9:
            return "no_heartbeat"
        if not self.armed:
            return "disarmed"
        name = _SUB_MODE_NAMES.get(self.mode if self.mode is not None else -1)
        if name not in a.modes:
            return "mode"
        if self._pilot_axes is not None and self._pilot_age > a.pilot_timeout_s + 1e-9:
            return "pilot_silent"
        return STEERING

    def _pilot_yaw(self, dt: float) -> bool:
        """True while the pilot steers the yaw (takeover, then ``pilot_release_s`` centred)."""
        r = self._pilot_axes[3] if self._pilot_axes is not None else 0
        if abs(r) > self.acfg.yaw_dead_band:
            if not self._pilot_has and self.acfg.steer:
                self.takeovers += 1
                log.warning("pilot yaw %d above the dead band %d: the pilot steers", r,
                            self.acfg.yaw_dead_band)
            self._pilot_has = True
            self._centred_s = 0.0
        elif self._pilot_has:
            self._centred_s += dt
            if self._centred_s >= self.acfg.pilot_release_s - 1e-9:
                self._pilot_has = False
        return self._pilot_has

    def _set_state(self, state: str) -> None:
        if state == self.state:
            return
        severity, text = STATE_TEXT[state]
        if state == "mode":
            mode = self.mode if self.mode is not None else -1
            text = text.format(mode=_SUB_MODE_NAMES.get(mode, str(mode)))
        log.info("ardusub: %s", text)
        self.output.send_statustext(severity, text)
        self.state = state

    def step(self) -> dict[str, Any]:
        """One period: heading, heartbeat and pilot in; controller; MANUAL_CONTROL out when
        the bridge steers (module docstring); operator telemetry."""
        dt = self.cfg.period_s
        meas = self.heading.take()
        hb = self.autopilot.take()
        if hb is not None:
            self.armed, self.mode = hb
            self._hb_age = 0.0
        elif self._hb_age is not None:
            self._hb_age += dt
        pilot = self.pilot.take()
        if pilot is not None:
            self._pilot_axes, self._pilot_age = pilot, 0.0
        else:
            self._pilot_age += dt
        was_pilot = self._pilot_has
        pilot_yaw = self._pilot_axes is not None and self._pilot_yaw(dt)
        cmd, dec = self.ctl.step(meas, dt)
        if was_pilot and not pilot_yaw and dec.heading_used is not None:  # handed back
            self.ctl.setpoint_deg = dec.heading_used % 360.0
            self.ctl.pid.reset()
            log.info("pilot yaw centred %.1f s: holding %.1f deg", self.acfg.pilot_release_s,
                     self.ctl.setpoint_deg)
        gate = self._gate()
        state = "pilot" if gate == STEERING and pilot_yaw else gate
        self._set_state(state)
        steering = state == STEERING
        self.pilot.steering = steering
        x, y, z, r = manual_control_axes(cmd)
        buttons = 0
        if self._pilot_axes is not None and self._pilot_age <= self.acfg.pilot_timeout_s + 1e-9:
            x, y, z, pr, buttons = self._pilot_axes  # the pilot's other axes, unchanged
            if not steering:
                r = pr
        if steering:
            self.output.send_manual_control(self.vehicle, x, y, z, r, buttons)
            self.sent += 1
        else:
            # Not ours: the yaw the vehicle gets is the pilot's (0 without one), and that is
            # the detector's next input; the PID does not wind up meanwhile.
            if self._pilot_axes is None or self._pilot_age > self.acfg.pilot_timeout_s + 1e-9:
                r = 0
            self.ctl.command = ThrusterCommand(r / 10.0, -r / 10.0)
            self.ctl.pid.reset()
        self.states[state] += 1
        rec = epoch_record(self.t, None, meas, self.ctl.setpoint_deg, cmd, dec, self.ctl.action)
        rec["ardusub"] = state
        rec["r_sent"] = r if steering else None
        self.t += dt
        self.operator(rec)
        if self.on_epoch is not None:
            self.on_epoch(rec)
        return rec


class ArduSubRovVehicle:
    """The ROV through an ArduSub autopilot as a vehicle of the runtime (module docstring).

    Needs the runner's router (a ``[mavlink]`` table): ATTITUDE in, MANUAL_CONTROL out.
    """

    name = "rov-ardusub"
    pacing: Literal["period"] = "period"

    def __init__(self, cfg: RovConfig, *, ft: bool = True, vehicle_system_id: int | None = None,
                 on_epoch: Callable[[dict[str, Any]], None] | None = None) -> None:
        self.cfg = cfg
        self.period_s = cfg.period_s
        self.ft = ft
        self.vehicle_system_id = (cfg.ardusub.vehicle_system_id if vehicle_system_id is None
                                  else vehicle_system_id)
        self.on_epoch = on_epoch
        self.loop: RovAutopilotLoop | None = None
        self.monitor = RovFailsafeMonitor(cfg.period_s)
        self.epochs = EpochLog(None)
        self.actions: Counter[str] = Counter()

    def ports(self) -> list[PortSpec]:
        return []  # the router's autopilot link is the vehicle's

    def mavlink(self) -> MavlinkSpec | None:
        return None

    def start(self, ctx: Context) -> None:
        if ctx.router is None:
            raise ConfigError("(config)", "mavlink", "a [mavlink] table: the ArduSub ROV's "
                              "heading comes from the autopilot", "none")
        self.loop = RovAutopilotLoop(self.cfg, ctx.router, ft=self.ft,
                                     vehicle_system_id=self.vehicle_system_id,
                                     on_epoch=self.on_epoch)  # before the router starts
        self.epochs = ctx.epochs

    def step(self, t: float) -> int:
        assert self.loop is not None
        rec = self.loop.step()
        self.monitor.observe(rec)
        self.actions[rec["action"]] += 1
        self.epochs.write(rec)
        return 1

    def check(self, now: float) -> None:
        """Nothing beyond the step: the dropout rule runs in the controller every period."""

    def idle_s(self) -> float:
        return 0.0

    def finish(self) -> None:
        """Nothing pending: every period's record is written in its step."""

    def summary(self) -> dict[str, Any]:
        out: dict[str, Any] = {"actions": dict(sorted(self.actions.items()))}
        if self.loop is not None:
            lp = self.loop
            out["attitude_received"] = lp.heading.received
            out["heartbeat_received"] = lp.autopilot.received
            out["pilot_received"] = lp.pilot.received
            out["manual_control_sent"] = lp.sent
            out["pilot_takeovers"] = lp.takeovers
            out["ardusub_states"] = dict(sorted(lp.states.items()))
        out["failsafe"] = {"episodes": self.monitor.episodes,
                           "neutral": self.monitor.neutral_episodes}
        return out
