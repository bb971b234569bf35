"""Replay a real dive's compass and yaw command offline through the ROV detector.

Reads a QGroundControl ``.tlog`` through :func:`drivers.mavlink.io.iter_tlog` (the one module
that touches pymavlink): heading from ``ATTITUDE.yaw`` (rad, float; ``VFR_HUD.heading`` is whole
degrees and would look stuck), the pilot's yaw command from ``MANUAL_CONTROL.r`` (-1000..1000,
mapped to -100..100 %). Both are sampled at the ROV period (newest value at each tick) and fed to
:class:`~fdi.heading_ft.FaultTolerantHeading` with substitution off (nothing is controlled).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from drivers.mavlink.io import iter_tlog
from fdi.heading_ft import FaultTolerantHeading, HeadingDecision
from firmware_host.rov.config import RovConfig


@dataclass(frozen=True)
class DiveSeries:
    """5 Hz series: time (s from the first heading), heading (deg), yaw command (%)."""

    t_s: list[float]
    heading_deg: list[float]
    yaw_pct: list[float]


def load_dive(path: str | Path, period_s: float = 0.2) -> DiveSeries:
    events: list[tuple[float, str, float]] = []
    for rec in iter_tlog(path):
        m = rec.msg
        if m is None:
            continue
        kind = m.get_type()
        if kind == "ATTITUDE":
            events.append((rec.t_us / 1e6, "h", math.degrees(m.yaw) % 360.0))
        elif kind == "MANUAL_CONTROL":
            events.append((rec.t_us / 1e6, "u", max(-100.0, min(100.0, m.r / 10.0))))
    events.sort(key=lambda e: e[0])
    first = next(e[0] for e in events if e[1] == "h")
    t_s: list[float] = []
    hs: list[float] = []
    us: list[float] = []
    h: float | None = None
    u = 0.0
    tick = first
    for t, kind, v in events:
        while t > tick and h is not None:
            t_s.append(round(tick - first, 6))
            hs.append(h)
            us.append(u)
            tick += period_s
        if kind == "h":
            h = v
        else:
            u = v
    return DiveSeries(t_s, hs, us)


def replay(
    dive: DiveSeries, cfg: RovConfig, drift_deg: float = 0.0, drift_at_s: float | None = None
) -> list[HeadingDecision]:
    """Run the detector over the dive, optionally adding a fixed drift from ``drift_at_s``."""
    ft = FaultTolerantHeading(cfg.detector, cfg.ft, enabled=False)
    out: list[HeadingDecision] = []
    u_prev = 0.0
    for t, h, u in zip(dive.t_s, dive.heading_deg, dive.yaw_pct, strict=True):
        if drift_at_s is not None and t >= drift_at_s - 1e-9:
            h = (h + drift_deg) % 360.0
        out.append(ft.step(u_prev, h))
        u_prev = u
    return out
