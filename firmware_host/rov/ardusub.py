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

MANUAL_CONTROL from a :class:`~drivers.outland.link.ThrusterCommand` (ArduSub's pilot axes):
``x = 10 (port + starboard) / 2`` (forward), ``r = 10 (port - starboard) / 2`` (yaw, positive
clockwise), ``y = 10 lateral``, ``z = 500 + 5 vertical`` (0..1000, 500 neutral), all in
-1000..1000 and clamped.
"""

from __future__ import annotations

import math
import threading
from collections import Counter
from collections.abc import Callable
from typing import Any, Literal

from drivers.mavlink import io as mio
from drivers.mavlink.framer import MavFrame
from drivers.outland.link import ThrusterCommand
from fdi.errors import ConfigError
from firmware_host.mavlink.router import Router
from firmware_host.rov.config import RovConfig
from firmware_host.rov.control import RovController, epoch_record
from firmware_host.runtime.failsafe import RovFailsafeMonitor
from firmware_host.runtime.mavout import MavlinkOutput, RouterOutput
from firmware_host.runtime.records import EpochLog
from firmware_host.runtime.vehicle import Context, MavlinkSpec, PortSpec

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
        self.router = router
        self.vehicle = vehicle_system_id
        self.ctl = RovController(cfg, ft=ft)
        self.heading = AutopilotHeading(router, (vehicle_system_id, 1))
        self.output = RouterOutput(router)
        self.operator = RovOperatorSink(self.output)
        self.on_epoch = on_epoch
        self.t = 0.0

    def step(self) -> dict[str, Any]:
        """One period: newest heading in, controller, MANUAL_CONTROL out, operator telemetry."""
        meas = self.heading.take()
        cmd, dec = self.ctl.step(meas, self.cfg.period_s)
        x, y, z, r = manual_control_axes(cmd)
        self.output.send_manual_control(self.vehicle, x, y, z, r)
        rec = epoch_record(self.t, None, meas, self.ctl.setpoint_deg, cmd, dec, self.ctl.action)
        self.t += self.cfg.period_s
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
            out["attitude_received"] = self.loop.heading.received
        out["failsafe"] = {"episodes": self.monitor.episodes,
                           "neutral": self.monitor.neutral_episodes}
        return out
