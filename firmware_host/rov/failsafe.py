"""The ROV's failsafe episodes.

:class:`RovFailsafeMonitor`: the ROV's dropout rule is the controller's
(:class:`firmware_host.rov.control.RovController`: hold the last command for
``dropout_hold_s``, then neutral thrust; it logs each). The monitor counts the episodes and
says when telemetry is back and heading hold resumes.
"""

from __future__ import annotations

import logging
from typing import Any

from drivers.ratelog import RateLimitedLog

log = logging.getLogger("fdi_bridge.failsafe")


class RovFailsafeMonitor:
    """Watches the ROV's epoch records (``action``) and says when heading hold resumes."""

    def __init__(self, period_s: float) -> None:
        self.period_s = period_s
        self.lost_steps = 0
        self.episodes = 0
        self.neutral_episodes = 0
        self._prev = "init"
        # A compass slower than the hold gives an episode at every gap: one line per 10 s.
        self._ratelog = RateLimitedLog(log, interval_s=10.0)

    def observe(self, rec: dict[str, Any]) -> str | None:
        """Return ``"lost"``, ``"neutral"`` or ``"back"`` at a transition (an episode counts
        when the hold lasted at least two periods), else None."""
        action = str(rec.get("action", ""))
        event = None
        if action in ("hold", "neutral"):
            self.lost_steps += 1
            if self.lost_steps == 2:
                self.episodes += 1
                event = "lost"
            if action == "neutral" and self._prev != "neutral":
                self.neutral_episodes += 1
                event = "neutral"
        else:
            if self.lost_steps >= 2:
                self._ratelog.warning(
                    "ROV telemetry back",
                    f"after {self.lost_steps * self.period_s:.1f} s; heading hold resumed")
                event = "back"
            self.lost_steps = 0
        self._prev = action
        return event
