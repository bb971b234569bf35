"""What the two ROV vehicles share: a 5 Hz period-paced step, its step marks, its failsafe
count, its records and its summary.

:class:`~firmware_host.rov.vehicle.OutlandRovVehicle` (the Outland link) and
:class:`~firmware_host.rov.ardusub.ArduSubRovVehicle` (an ArduSub autopilot behind the router)
differ in where the heading comes from and where the command goes; everything else of a vehicle
of the runtime (:class:`~firmware_host.runtime.vehicle.Vehicle`) is here, once:

* paced by the period (``"period"``, ``cfg.period_s``, absolute deadlines);
* each step first writes its mark ``{"k": step, "t": seconds since start}`` on the recorder's
  tick channel (:meth:`RovVehicleBase._mark`), so the bytes a step read and wrote lie between
  its mark and the next one: ``fdi-bridge replay`` re-runs the steps on them
  (:mod:`firmware_host.rov.replay`);
* each step's record is counted (``actions``), watched by the failsafe monitor
  (:class:`~firmware_host.rov.failsafe.RovFailsafeMonitor`: dropout episodes, neutral
  thrust) and written to ``epochs.jsonl`` (:meth:`RovVehicleBase._account`, then
  ``self.epochs.write``);
* nothing beyond the step on ``check`` (the dropout rule runs in the controller every period),
  no idle wait, nothing pending at ``finish``;
* the summary: ``actions``, the vehicle's own fields (:meth:`RovVehicleBase._summary_fields`),
  ``failsafe``.
"""

from __future__ import annotations

import json
from collections import Counter
from typing import Any, Literal

from firmware_host.rov.config import RovConfig
from firmware_host.rov.failsafe import RovFailsafeMonitor
from firmware_host.runtime.records import EpochLog
from firmware_host.runtime.vehicle import Tap


class RovVehicleBase:
    """See the module docstring. A subclass sets ``name`` and implements ``ports``,
    ``mavlink``, ``start``, ``step`` and :meth:`_summary_fields`."""

    pacing: Literal["period"] = "period"

    def __init__(self, cfg: RovConfig) -> None:
        self.cfg = cfg
        self.period_s = cfg.period_s
        self.monitor = RovFailsafeMonitor(cfg.period_s)
        self.epochs = EpochLog(None)
        self.actions: Counter[str] = Counter()
        self.t0 = 0.0
        self.steps = 0
        self.tick: Tap | None = None

    def _mark(self, t: float) -> None:
        """The step's mark on the recorder's tick channel (before any read of the step)."""
        if self.tick is not None:
            self.tick(json.dumps({"k": self.steps, "t": t - self.t0}).encode("ascii"))

    def _account(self, rec: dict[str, Any]) -> None:
        """A step's record into the failsafe monitor and the action counts."""
        self.monitor.observe(rec)
        self.actions[rec["action"]] += 1

    def check(self, now: float) -> None:
        """Nothing beyond the step: the dropout rule runs in the controller every period."""

    def idle_s(self) -> float:
        return 0.0

    def finish(self) -> None:
        """Nothing pending: every period's record is written in its step."""

    def _summary_fields(self) -> dict[str, Any]:
        """The vehicle's own summary fields (between ``actions`` and ``failsafe``)."""
        return {}

    def summary(self) -> dict[str, Any]:
        out: dict[str, Any] = {"actions": dict(sorted(self.actions.items()))}
        out.update(self._summary_fields())
        out["failsafe"] = {"episodes": self.monitor.episodes,
                           "neutral": self.monitor.neutral_episodes}
        return out
