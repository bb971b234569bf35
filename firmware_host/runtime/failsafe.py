"""The silence watchdog every vehicle's failsafe is built on: what the bridge does when a
sensor stops giving valid data is the vehicle's own (the rover's no-fix GPS_INPUT:
:class:`firmware_host.rover.failsafe.RoverFailsafe`; the ROV's episodes:
:class:`firmware_host.rov.failsafe.RovFailsafeMonitor`), when it does it is this.

* :class:`SilenceWatchdog`: no valid data for ``silence_s`` on the injected clock -> ``"silent"``
  (once); the next valid data -> ``"back"`` (once).
"""

from __future__ import annotations

import time
from collections.abc import Callable


class SilenceWatchdog:
    """``valid()`` on every valid datum; ``check()`` every loop; each returns an event or None."""

    def __init__(self, silence_s: float, clock: Callable[[], float] = time.monotonic) -> None:
        self.silence_s = silence_s
        self.clock = clock
        self.last_valid = clock()
        self.silent = False
        self.episodes = 0
        self.silent_since: float | None = None

    def valid(self) -> str | None:
        self.last_valid = self.clock()
        if self.silent:
            self.silent = False
            self.silent_since = None
            return "back"
        return None

    def check(self) -> str | None:
        now = self.clock()
        if not self.silent and now - self.last_valid >= self.silence_s:
            self.silent = True
            self.silent_since = now
            self.episodes += 1
            return "silent"
        return None
