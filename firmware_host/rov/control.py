"""One 200 ms step of the ROV heading hold: telemetry in, thruster command out, an epoch record.

Shared by the simulation (in-process or over a pty) and the real-vehicle mode, so both use the
same detector, substitution, PID and dropout rule. Dropout: when no telemetry arrived, the last
safe command is kept for ``dropout_hold_s``, then all thrusters go neutral (``action`` says so).
"""

from __future__ import annotations

import logging
from dataclasses import replace
from typing import Any

from drivers.outland.link import NEUTRAL, ThrusterCommand
from drivers.ratelog import RateLimitedLog
from fdi.heading_ft import FaultTolerantHeading, HeadingDecision
from fdi.pid import HeadingPid, thrust_to_command
from firmware_host.rov.config import RovConfig

log = logging.getLogger(__name__)


class RovController:
    """Compass FDI + heading PID + dropout policy. ``ft=False`` is the ``--no-ft`` loop."""

    def __init__(self, cfg: RovConfig, ft: bool = True, setpoint_deg: float | None = None):
        self.cfg = cfg
        ft_cfg = cfg.ft
        if cfg.ardusub.heading == "raw_compass":  # its per-sample noise and lag are larger
            raw = ft_cfg.gyro_maneuver_dead_raw_deg
            ft_cfg = replace(ft_cfg, gyro_maneuver_dead_deg=raw, gyro_maneuver_dead_min_deg=raw)
        self.heading = FaultTolerantHeading(cfg.detector, ft_cfg, enabled=ft)
        self.pid = HeadingPid(cfg.pid)
        self.setpoint_deg = cfg.setpoint_deg if setpoint_deg is None else setpoint_deg
        self._setpoint_seen = self.setpoint_deg
        self.command = NEUTRAL
        self._last_safe = NEUTRAL
        self._since_telemetry = 0.0
        self.action = "init"
        # One per controller: a process-wide limiter let one run's reports silence the next's.
        self._ratelog = RateLimitedLog(log)

    def step(
        self, heading_meas: float | None, dt: float, yaw_rate_dps: float | None = None,
        heading_suspect: bool = False,
    ) -> tuple[ThrusterCommand, HeadingDecision]:
        """``heading_meas`` (deg) from this period's telemetry, None when none arrived.

        ``yaw_rate_dps``: the vehicle's yaw-rate gyro for this period (deg/s, positive in the
        direction of increasing heading), None when the vehicle has none or it did not arrive;
        with it the compass is cross-checked against the integrated rate (:mod:`fdi.heading_ft`).
        ``heading_suspect``: the driver's flag (``Telemetry.heading_suspect``: a jump faster
        than the protocol's ``max_rate``); it opens a suspect at once, so this sample is not
        steered on (:meth:`fdi.heading_ft.FaultTolerantHeading.step`).
        """
        if self.setpoint_deg != self._setpoint_seen:  # a commanded turn: the FDI is told
            self._setpoint_seen = self.setpoint_deg
            self.heading.setpoint_changed()
        # The FIR's input is the thrust the last command gave (the command itself unless a
        # thrust curve is configured): then its model of thrust -> heading is the linear one.
        dec = self.heading.step(self.command.yaw_pct, heading_meas, yaw_rate_dps, dt,
                                heading_suspect=heading_suspect)
        if heading_meas is None:
            self._since_telemetry += dt
            if self._since_telemetry <= self.cfg.dropout_hold_s + 1e-9:
                action = "hold"
                cmd = self._last_safe
            else:
                action = "neutral"
                cmd = NEUTRAL
                self.pid.reset()
            if action != self.action:  # rate-limited: line noise can make this flap
                what = "holding last command" if action == "hold" else "neutral thrust"
                self._ratelog.warning(f"compass telemetry lost: {what}",
                                 f"for {self._since_telemetry:.1f} s")
        else:
            self._since_telemetry = 0.0
            assert dec.heading_used is not None
            # the PID asks for thrust; the configured curve's inverse gives the command
            u = thrust_to_command(self.cfg.pid,
                                  self.pid.update(self.setpoint_deg, dec.heading_used, dt))
            s = self.cfg.surge_pct
            cmd = ThrusterCommand(min(max(s + u, -100.0), 100.0), min(max(s - u, -100.0), 100.0))
            self._last_safe = cmd
            action = "control" if dec.source in ("sensor", "fused") else "substitute"
        if dec.event:
            log.info("compass: %s (%s)", dec.event, dec.kind or "-")
        self.action = action
        self.command = cmd
        return cmd, dec


def epoch_record(
    t: float,
    heading_true: float | None,
    heading_meas: float | None,
    setpoint: float,
    cmd: ThrusterCommand,
    dec: HeadingDecision,
    action: str,
    heading_suspect: bool = False,
) -> dict[str, Any]:
    """One line of ``epochs.jsonl`` (the issue's contract; degrees, deg^2, %).

    ``heading_suspect``: the driver flagged this period's reading (a jump faster than the
    vehicle can turn); False where no driver flags (ArduSub, the in-process experiment)."""
    return {
        "t": round(t, 3),
        "heading_true": None if heading_true is None else round(heading_true % 360.0, 4),
        "heading_meas": None if heading_meas is None else round(heading_meas, 4),
        "heading_used": None if dec.heading_used is None else round(dec.heading_used, 4),
        "setpoint": setpoint,
        "e2": round(dec.e2, 6),
        "snr": round(dec.snr, 6),
        "V": round(dec.V, 6),
        "suspect": dec.suspect,
        "fault": dec.fault,
        "fault_kind": dec.kind,
        "source": dec.source,
        "event": dec.event,
        "action": action,
        "port_pct": round(cmd.port_pct, 3),
        "starboard_pct": round(cmd.starboard_pct, 3),
        "lateral_pct": round(cmd.lateral_pct, 3),
        "vertical_pct": round(cmd.vertical_pct, 3),
        "heading_suspect": heading_suspect,
    }
