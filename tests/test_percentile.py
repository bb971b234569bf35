"""runtime.loop.percentile: numpy.percentile's default method, without numpy on the replay path."""

from __future__ import annotations

import numpy as np
import pytest

from firmware_host.runtime.loop import percentile


@pytest.mark.parametrize("seed", range(8))
def test_percentile_matches_numpy_linear(seed: int) -> None:
    rng = np.random.default_rng(seed)
    for n in (1, 2, 3, 7, 100, 1001):
        values = (rng.lognormal(size=n) * 1e-3).tolist()
        for q in (0, 1, 25, 50, 90, 99, 99.9, 100):
            # timing figures: equal to numpy to rounding (numpy may fuse the interpolation)
            assert percentile(values, q) == pytest.approx(float(np.percentile(values, q)),
                                                          rel=1e-12, abs=0.0), (n, q)


def test_percentile_of_nothing_is_zero() -> None:
    assert percentile([], 99) == 0.0
