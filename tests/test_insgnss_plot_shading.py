"""The INS/GNSS error plots shade the receiver's fault periods (issue 17, plots): each shaded
span covers fault epochs and every fault epoch is inside a shaded span."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("matplotlib")

import matplotlib.pyplot as plt

from firmware_host.devtools.insgnss_sim import load_setup, run_scenario, write_plots


@pytest.fixture
def figures(monkeypatch: pytest.MonkeyPatch) -> list[Any]:
    kept: list[Any] = []
    real = plt.close

    def close(fig: Any = None) -> None:
        if fig is not None and not isinstance(fig, str):
            fig.canvas.draw()
            kept.append(fig)
        real(fig)

    monkeypatch.setattr(plt, "close", close)
    return kept


@pytest.mark.parametrize(("scenario", "seed"), [("paper-single", 3), ("paper-random", 8)])
def test_fault_periods_are_shaded(tmp_path: Path, figures: list[Any], scenario: str,
                                  seed: int) -> None:
    _, data, runs = run_scenario(load_setup("insgnss"), scenario, seed)  # type: ignore[arg-type]
    files = write_plots(tmp_path, scenario, runs, data)
    assert [p.name for p in files] == ["position_errors.png", "velocity_errors.png"]
    t = data.gnss_t[1:]
    faulty = t[np.any(data.fault[1:] != 0, axis=1)]
    assert faulty.size > 0
    assert len(figures) == 2
    for fig in figures:
        for ax in fig.axes:
            spans = [(p.get_x(), p.get_x() + p.get_width()) for p in ax.patches]
            assert spans, ax.get_ylabel()
            assert all(any(a <= tk <= b for a, b in spans) for tk in faulty)
            assert all(any(a <= tk <= b for tk in faulty) for a, b in spans)
