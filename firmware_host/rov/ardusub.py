"""The ROV behind the MAVLink router: heading hold through an autopilot, FDI to the operator.

Where the vehicle is driven through an autopilot (ArduSub) instead of the Outland link, the
heading-hold loop (:class:`~firmware_host.rov.control.RovController`: compass FDI, substitution,
PID) reads the vehicle's heading from the autopilot's ATTITUDE (``yaw``, via
:meth:`Router.listen <firmware_host.mavlink.router.Router.listen>`) and sends its thrust as
MANUAL_CONTROL with the ground station's system id (``pilot_system_id``) and the vehicle as
target: ArduSub takes pilot input only from its ground station (``SYSID_MYGCS``).

:class:`RovOperatorSink` is the ``on_epoch`` sink of an ROV loop (this module's
:class:`RovAutopilotLoop`, or :func:`firmware_host.rov.app.run_rov` on the Outland link, whose
``on_epoch`` takes it as it is): per epoch the corrected heading and the detector's statistics
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
import time
from collections.abc import Callable
from typing import Any

from drivers.mavlink import io as mio
from drivers.mavlink.framer import MavFrame
from drivers.outland.link import ThrusterCommand
from firmware_host.mavlink.router import Router
from firmware_host.rov.config import RovConfig
from firmware_host.rov.control import RovController, epoch_record
from firmware_host.runtime.loop import FixedRateLoop

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

    def __init__(self, router: Router) -> None:
        self.router = router
        self._action = "init"

    def __call__(self, rec: dict[str, Any]) -> None:
        r = self.router
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
                r.set_named_value(name, float(value))
        event = str(rec.get("event") or "")
        if event in EVENT_TEXT:
            severity, text = EVENT_TEXT[event]
            kind = rec.get("fault_kind") or ""
            r.post_statustext(severity, f"{text} ({kind})" if kind else text)
        action = str(rec.get("action", ""))
        if action != self._action and action in ACTION_TEXT:
            r.post_statustext(*ACTION_TEXT[action])
        elif self._action in ACTION_TEXT and action not in ACTION_TEXT:
            r.post_statustext(mio.MAV_SEVERITY_NOTICE, "FDI compass: telemetry back")
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
        self.operator = RovOperatorSink(router)
        self.on_epoch = on_epoch
        self.t = 0.0

    def step(self) -> dict[str, Any]:
        """One period: newest heading in, controller, MANUAL_CONTROL out, operator telemetry."""
        meas = self.heading.take()
        cmd, dec = self.ctl.step(meas, self.cfg.period_s)
        self.router.send_manual_control(*manual_control_axes(cmd), target_system=self.vehicle)
        rec = epoch_record(self.t, None, meas, self.ctl.setpoint_deg, cmd, dec, self.ctl.action)
        self.t += self.cfg.period_s
        self.operator(rec)
        if self.on_epoch is not None:
            self.on_epoch(rec)
        return rec

    def run(
        self,
        stop: threading.Event,
        clock: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], None] = time.sleep,
        max_steps: int | None = None,
    ) -> dict[str, Any]:
        """Step at ``period_s`` on absolute deadlines until ``stop`` is set; timing summary."""
        loop = FixedRateLoop(self.cfg.period_s, clock=clock, sleep=sleep)

        def step(k: int, t: float) -> bool:
            self.step()
            return not stop.is_set()

        return dict(loop.run(step, max_steps=max_steps).summary())
