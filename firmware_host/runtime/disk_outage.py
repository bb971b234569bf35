"""What a disk error does to a file the bridge writes beside its work (the flight recorder,
``--out``'s epochs file): the one policy both follow.

Never raise: every failed try is counted (``write_errors``, ``last_error``); the first of an
outage starts it (``outages``) and is logged once, saying that detection and outputs go on;
what is lost during it is counted by the writer (:meth:`DiskOutage._lost_now`); when the disk
takes data again that is said once, with how long the outage lasted and how much it lost.
"""

from __future__ import annotations

import logging
from collections.abc import Callable


class DiskOutage:
    """The outage state and counters of a writer (a base class: the writer's own counters and
    log keep their names). ``_outage_stopped`` says what stopped ("recording stopped"),
    ``_outage_unit`` what is counted lost ("records"), ``_outage_name`` names the writer in the
    recovery line; ``_outage_retry_s`` is how often it tries again."""

    clock: Callable[[], float]
    _outage_log: logging.Logger
    _outage_stopped: str
    _outage_unit: str
    _outage_retry_fmt = "%.1f"

    def _init_outage(self) -> None:
        self.write_errors = 0  # failed tries (create, write; the recorder's fsync too)
        self.outages = 0  # times writing stopped for a disk error
        self.last_error = ""
        self._failing_since: float | None = None  # the current outage began (clock)
        self._lost_in_outage = 0

    @property
    def _writing(self) -> bool:
        return self._failing_since is None

    def _outage_name(self) -> str:
        raise NotImplementedError

    def _outage_retry_s(self) -> float:
        raise NotImplementedError

    def _lost_now(self, n: int) -> None:
        self._lost_in_outage += n

    def _failed(self, why: str) -> None:
        self.write_errors += 1
        self.last_error = why
        if self._failing_since is None:
            self._failing_since = self.clock()
            self.outages += 1
            self._outage_log.warning(
                f"%s; {self._outage_stopped} (detection and outputs go on), retrying every "
                f"{self._outage_retry_fmt} s", why, self._outage_retry_s())

    def _recovered(self) -> None:
        if self._failing_since is None:
            return
        self._outage_log.warning("%s after %.1f s (%d %s lost)", self._outage_name(),
                                 self.clock() - self._failing_since, self._lost_in_outage,
                                 self._outage_unit)
        self._failing_since = None
        self._lost_in_outage = 0
