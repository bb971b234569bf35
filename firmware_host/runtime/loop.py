"""The loop owns time: fixed-rate scheduling on absolute deadlines, with an injected clock.

``FixedRateLoop`` runs a step function every ``period_s`` seconds on absolute deadlines
(``next += period``), never accumulating drift. Its clock and sleep are arguments, so tests drive
it with :class:`FakeClock` and never wait on the wall clock. It counts overruns (a step that ended
after the next deadline) and keeps the step processing times and the start-time jitter.

``EpochTimer`` is the rover's counterpart: the rover is paced by the receiver's epochs, not by a
timer, so it measures each epoch's processing time and counts an overrun when an epoch took longer
than the receiver's period.
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any, SupportsIndex, overload

Clock = Callable[[], float]
Sleep = Callable[[float], None]


class FakeClock:
    """A clock for tests: ``sleep`` advances time instantly; ``advance`` moves it by hand."""

    def __init__(self, start: float = 0.0) -> None:
        self.now = start

    def __call__(self) -> float:
        return self.now

    def sleep(self, seconds: float) -> None:
        if seconds > 0:
            self.now += seconds

    def advance(self, seconds: float) -> None:
        self.now += seconds


KEEP_SAMPLES = 65536


def percentile(values: Iterable[float], q: float) -> float:
    """The ``q``-th percentile (0-100) of ``values``, as ``numpy.percentile``'s default
    ("linear": the virtual index ``(n - 1) q / 100`` between the two nearest order statistics,
    with numpy's two-sided interpolation); 0.0 for no values. Pure Python, so the loop and the
    rover's summary do not import numpy (issue 19: start-up)."""
    a = sorted(values)
    n = len(a)
    if n == 0:
        return 0.0
    qf = q / 100.0
    h = n * qf + (1.0 + qf * -1.0) - 1.0  # numpy's virtual index, alpha = beta = 1
    lo = math.floor(h)
    t = h - lo
    lo = min(max(lo, 0), n - 1)
    x, y = float(a[lo]), float(a[min(lo + 1, n - 1)])
    diff = y - x
    return y - diff * (1.0 - t) if t >= 0.5 else x + diff * t


_deque_append = deque.append


class RecentSamples(deque[float]):
    """The last ``KEEP_SAMPLES`` timing samples (bounded memory on a run of days), with the
    count and the maximum over the whole run. Percentiles are over the samples kept."""

    def __init__(self, values: Iterable[float] = (), maxlen: int = KEEP_SAMPLES) -> None:
        super().__init__((), maxlen)
        self.total = 0
        self.peak = 0.0
        for v in values:
            self.append(v)

    def append(self, value: float) -> None:
        _deque_append(self, value)  # super().append, without building the super object
        self.total += 1
        if value > self.peak:
            self.peak = value

    @overload
    def __getitem__(self, index: SupportsIndex) -> float: ...

    @overload
    def __getitem__(self, index: slice) -> list[float]: ...

    def __getitem__(self, index: Any) -> Any:
        if isinstance(index, slice):
            return list(self)[index]
        return super().__getitem__(index)


@dataclass
class TimingStats:
    """Processing times (s) and start jitter (s) of a loop, with overrun count."""

    proc_s: RecentSamples = field(default_factory=RecentSamples)
    jitter_s: RecentSamples = field(default_factory=RecentSamples)
    overruns: int = 0
    steps: int = 0

    def summary(self) -> dict[str, float | int]:
        """p50/p99/max of processing time and jitter, in milliseconds."""
        out: dict[str, float | int] = {"steps": self.steps, "overruns": self.overruns}
        for name, values in (("proc", self.proc_s), ("jitter", self.jitter_s)):
            if values:
                arr = [v * 1e3 for v in values]
                out[f"{name}_p50_ms"] = percentile(arr, 50)
                out[f"{name}_p99_ms"] = percentile(arr, 99)
                out[f"{name}_max_ms"] = values.peak * 1e3
        return out


class FixedRateLoop:
    """Call ``step(k, t)`` every ``period_s`` on absolute deadlines until it returns False.

    ``t`` is the step's deadline on the injected clock. A step that finishes after the next
    deadline counts as an overrun; the loop then skips the missed deadlines (it does not try to
    catch up with a burst of late steps) and the skipped count is added to ``overruns``.
    """

    def __init__(
        self,
        period_s: float,
        clock: Clock = time.monotonic,
        sleep: Sleep = time.sleep,
    ) -> None:
        if period_s <= 0:
            raise ValueError("period_s must be > 0")
        self.period_s = period_s
        self.clock = clock
        self.sleep = sleep
        self.stats = TimingStats()

    def run(self, step: Callable[[int, float], bool], max_steps: int | None = None) -> TimingStats:
        next_deadline = self.clock()
        k = 0
        while max_steps is None or k < max_steps:
            now = self.clock()
            if now < next_deadline:
                self.sleep(next_deadline - now)
                now = self.clock()
            self.stats.jitter_s.append(max(0.0, now - next_deadline))
            t0 = now
            keep_going = step(k, next_deadline)
            t1 = self.clock()
            self.stats.proc_s.append(t1 - t0)
            self.stats.steps += 1
            k += 1
            next_deadline += self.period_s
            # A step that ends after the next deadline overran it; skip every deadline it
            # overran (one overrun each) rather than running a burst of late steps.
            while t1 > next_deadline:
                self.stats.overruns += 1
                next_deadline += self.period_s
            if not keep_going:
                break
        return self.stats


class EpochTimer:
    """Per-epoch processing time and overruns for an event-paced loop (the rover)."""

    def __init__(self, clock: Clock = time.perf_counter) -> None:
        self.clock = clock
        self.stats = TimingStats()
        self._t0 = 0.0

    def start(self) -> None:
        self._t0 = self.clock()

    def stop(self, period_s: float | None) -> float:
        """End the epoch; ``period_s`` is the receiver's epoch period (None if not known yet)."""
        dt = self.clock() - self._t0
        stats = self.stats
        stats.proc_s.append(dt)
        stats.steps += 1
        if period_s is not None and dt > period_s:
            stats.overruns += 1
        return dt
