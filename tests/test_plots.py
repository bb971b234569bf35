"""The figures (issue 17): legends beside or above the axes (over no data), the raw fixes drawn
over the output, the error panel, fault periods shaded, e² on a log axis, the eval's small
multiples. Each figure is inspected before it is closed (``plt.close`` is wrapped)."""

from __future__ import annotations

import io
import json
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("matplotlib")

import matplotlib.pyplot as plt

from firmware_host.cli import main
from firmware_host.devtools import plots
from firmware_host.devtools.eval import run_suite
from firmware_host.devtools.rover_sim import RoverScenario, generate
from firmware_host.rover.pipeline import RoverPipeline
from firmware_host.runtime.config import load_config


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


def _overlaps(a: Any, b: Any) -> bool:
    return bool(a.x0 < b.x1 and b.x0 < a.x1 and a.y0 < b.y1 and b.y0 < a.y1)


def legends_clear_of_axes(fig: Any) -> None:
    axes = [a for a in fig.axes if a.get_visible()]
    for ax in axes:
        leg = ax.get_legend()
        if leg is None:
            continue
        box = leg.get_window_extent()
        for other in axes:
            assert not _overlaps(box, other.get_window_extent()), (ax.get_ylabel(), "legend")


def test_rover_plot(tmp_path: Path, figures: list[Any]) -> None:
    sc = RoverScenario(rate_hz=10.0, duration_s=60.0, seed=3, fault_every_s=10.0,
                       min_gap_s=5.0)
    stream = io.StringIO()
    truth: list[dict[str, Any]] = []
    pipe = RoverPipeline(load_config("rover").rover, jsonl=stream)
    for _, data, tr in generate(sc):
        pipe.feed(data)
        truth.append(tr)
    pipe.finish()
    epochs = [json.loads(x) for x in stream.getvalue().splitlines()]
    assert epochs and truth
    plots.plot_rover(epochs, truth, tmp_path / "r.png")
    assert (tmp_path / "r.png").stat().st_size > 10_000
    (fig,) = figures
    legends_clear_of_axes(fig)
    track, err, chi2, grey = fig.axes
    labels = [line.get_label() for line in track.get_lines()]
    assert labels.index("raw fixes") > labels.index("output")  # drawn over it
    assert err.get_yscale() == grey.get_yscale() == chi2.get_yscale() == "log"
    assert sum(1 for p in chi2.patches) >= 3  # the faults, shaded


def test_rov_demo_plots(tmp_path: Path, figures: list[Any]) -> None:
    assert main(["demo", "rov", "--out", str(tmp_path)]) == 0
    detection, _heading = figures
    for fig in figures:
        legends_clear_of_axes(fig)
        assert all(len(ax.patches) == 1 for ax in fig.axes)  # the drift, shaded
    e2 = detection.axes[0]
    assert e2.get_yscale() == "log" and e2.get_ylim()[0] > 0  # not symlog down to -10


def test_eval_plot_is_small_multiples(tmp_path: Path, figures: list[Any]) -> None:
    doc = run_suite(tmp_path, quick=True, plots=True, duration_s=60.0, include_rov=False,
                    include_insgnss=False)
    (fig,) = figures
    methods = [m["name"] for m in doc["rover"][0]["methods"]]
    shown = [ax for ax in fig.axes if ax.get_visible()]
    assert [ax.get_title(loc="left") for ax in shown] == methods  # one panel a method
    assert all(ax.get_yscale() == "log" for ax in shown)
    assert all(ax.patches for ax in shown)  # the injected faults, shaded
