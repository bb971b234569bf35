"""Noise scales that follow the sensor: a slow robust variance and a short trimmed one.

Used by both compass witnesses (:mod:`fdi.gyro_witness` and the FIR detector of
:mod:`fdi.lms_fir`) so that a threshold written in sigmas means the same on every vehicle
(an extension of Zhu, Chen & Liu 2009, whose theta of eq. (7) is a fixed number in deg^2).

* :class:`RobustVariance`: an exponentially weighted mean of ``min(x^2, c^2 var)`` (each sample
  clipped at ``c`` sigmas, so a fault or an outlier moves it by a bounded amount; optionally a
  sample beyond ``reject_sigmas`` is left out altogether), frozen by the caller while a fault
  is suspected, with a floor ``var_min``.
* :class:`TrimmedScale`: over the last ``window`` values of a *differenced* signal, the RMS
  without the ``trim`` largest, divided by sqrt(2). A step in the signal shows once in its first
  difference and a ramp only as a small mean, so this scale follows noise (a burst) within a few
  samples and is not raised by a step or a ramp; the trimmed mean square of a Gaussian
  underestimates the variance, by a factor ``bias`` estimated once at start (seeded).
"""

from __future__ import annotations

import math
from collections import deque
from typing import ClassVar


class RobustVariance:
    """EWMA of clipped squares; ``update(x)`` unless :attr:`frozen`."""

    def __init__(self, var0: float, samples: int, clip_sigmas: float, var_min: float,
                 reject_sigmas: float = 0.0) -> None:
        self.var = max(var0, var_min)
        self.alpha = 1.0 / samples
        self.c2 = clip_sigmas * clip_sigmas
        self.r2 = reject_sigmas * reject_sigmas
        self.var_min = var_min
        self.frozen = False

    @property
    def sigma(self) -> float:
        """The current scale estimate (the square root of the variance)."""
        return math.sqrt(self.var)

    def update(self, x: float, alpha: float | None = None) -> None:
        """Take one residual ``x`` (clipped at ``clip_sigmas``, ignored beyond
        ``reject_sigmas``) with weight ``alpha`` (default 1/``samples``); nothing while frozen."""
        if self.frozen:
            return
        a = self.alpha if alpha is None else alpha
        x2 = x * x
        if self.r2 and x2 > self.r2 * self.var:  # an outlier: not noise, left out
            return
        x2 = min(x2, self.c2 * self.var)
        self.var = max(self.var + a * (x2 - self.var), self.var_min)


def _trim_bias(window: int, trim: int) -> float:
    """E[trimmed mean of squares] / var for Gaussian samples (seeded Monte Carlo). numpy is
    imported here, once per (window, trim), so that loading an ``[rov]`` file does not import
    it (issue 19: a rover replay's start-up)."""
    import numpy as np

    rng = np.random.default_rng(0)
    x = np.sort(rng.normal(size=(20000, window)) ** 2, axis=1)[:, : window - trim]
    return float(x.mean())


class TrimmedScale:
    """Short-window noise sigma from the first differences of a signal (see module doc)."""

    _bias_cache: ClassVar[dict[tuple[int, int], float]] = {}

    def __init__(self, window: int = 10, trim: int = 2) -> None:
        if not 0 <= trim < window:
            raise ValueError("trim must be in [0, window)")
        self.window = window
        self.trim = trim
        key = (window, trim)
        if key not in self._bias_cache:
            self._bias_cache[key] = _trim_bias(window, trim)
        self.bias = self._bias_cache[key]
        self._d: deque[float] = deque(maxlen=window)
        self._last: float | None = None

    def push(self, x: float) -> None:
        """Append the newest value of the (undifferenced) signal."""
        if self._last is not None:
            d = x - self._last
            self._d.append(d * d)
        self._last = x

    def restart(self) -> None:
        """Forget the last value (after a gap: the next difference would span it)."""
        self._last = None

    @property
    def full(self) -> bool:
        """Whether the window holds ``window`` differences."""
        return len(self._d) == self.window

    @property
    def sigma(self) -> float:
        """The noise sigma of the signal (not of its differences); 0 until the window is full."""
        if not self.full:
            return 0.0
        sq = sorted(self._d)[: self.window - self.trim]
        return math.sqrt(sum(sq) / len(sq) / self.bias / 2.0)
