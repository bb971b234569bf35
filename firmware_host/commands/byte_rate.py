"""``record``'s progress line: the bytes recorded and their rate, redrawn on standard error at
most twice a second, only when standard error is a terminal and ``-q`` is not given (nothing
under systemd, in a pipe or in a test's capture). The product's own few lines: the developer
jobs' bars (:mod:`firmware_host.devtools.progress`) need tqdm, which only the ``dev`` extra
installs."""

from __future__ import annotations

import logging
import sys
import time
from collections.abc import Callable
from types import TracebackType
from typing import TextIO


def _size(n: float) -> str:
    for unit in ("B", "kB", "MB", "GB"):
        if n < 1000 or unit == "GB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.2f} {unit}"
        n /= 1000
    return f"{n:.2f} GB"  # unreachable: the loop returns at GB


class ByteRate:
    """``with ByteRate("recording URL") as line: line.step(n)``; erased on exit."""

    def __init__(self, desc: str, stream: TextIO | None = None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.desc = desc
        self.stream = sys.stderr if stream is None else stream
        self.clock = clock
        quiet = logging.getLogger().getEffectiveLevel() >= logging.ERROR
        self.shown = not quiet and self.stream.isatty()
        self.total = 0
        self._t0 = clock()
        self._drawn = float("-inf")
        self._width = 0

    def step(self, n: int) -> None:
        self.total += n
        now = self.clock()
        if self.shown and now - self._drawn >= 0.5:
            self._drawn = now
            rate = self.total / max(now - self._t0, 1e-3)
            text = f"{self.desc}: {_size(self.total)}, {_size(rate)}/s"
            self.stream.write("\r" + text.ljust(self._width))
            self.stream.flush()
            self._width = len(text)

    def close(self) -> None:
        if self.shown and self._width:
            self.stream.write("\r" + " " * self._width + "\r")
            self.stream.flush()

    def __enter__(self) -> ByteRate:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()
