"""The rover track panel (issue 17): at field scale the output and the raw fixes overlap, so the
panel zooms into fault periods beside the track (the largest, the longest and the smallest
fault), each showing the raw fixes, the output and the line from a replaced fix to its output.
The figure is inspected before it is closed, as in tests/test_plots.py."""

from __future__ import annotations

import io
import json
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("matplotlib")

import matplotlib.pyplot as plt

from firmware_host.devtools import plots
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


def _run(seed: int, duration_s: float = 120.0) -> tuple[list[dict[str, Any]],
                                                       list[dict[str, Any]]]:
    sc = RoverScenario(rate_hz=10.0, duration_s=duration_s, seed=seed, fault_every_s=12.0,
                       min_gap_s=5.0)
    stream = io.StringIO()
    truth: list[dict[str, Any]] = []
    pipe = RoverPipeline(load_config("rover").rover, jsonl=stream)
    for _, data, tr in generate(sc):
        pipe.feed(data)
        truth.append(tr)
    pipe.finish()
    return [json.loads(x) for x in stream.getvalue().splitlines()], truth


def _overlaps(a: Any, b: Any) -> bool:
    return bool(a.x0 < b.x1 - 1 and b.x0 < a.x1 - 1 and a.y0 < b.y1 - 1 and b.y0 < a.y1 - 1)


@pytest.mark.parametrize("seed", [3, 11])
def test_track_zooms_into_the_faults(tmp_path: Path, figures: list[Any], seed: int) -> None:
    epochs, truth = _run(seed)
    plots.plot_rover(epochs, truth, tmp_path / "r.png")
    (fig,) = figures
    track, err, _chi2, _grey = fig.axes  # the zooms are the track's children, not panels
    zooms = track.child_axes
    assert 1 <= len(zooms) <= 3
    t0 = epochs[0]["utc"]
    faulty = {round(r["utc"] - t0, 1) for r in truth if r.get("fault")}
    (x0, x1), (y0, y1) = track.get_xlim(), track.get_ylim()
    boxes = [z.get_window_extent() for z in zooms]
    fig_box = fig.bbox
    for zoom, box in zip(zooms, boxes, strict=True):
        title = zoom.get_title(loc="left")
        assert any(w in title for w in ("largest", "longest", "smallest")), title
        # a zoom: at most a fifth of the track's extent across
        zx0, zx1 = zoom.get_xlim()
        zy0, zy1 = zoom.get_ylim()
        assert zx1 - zx0 <= (x1 - x0) / 5 and zy1 - zy0 <= (y1 - y0) / 5
        # beside the track, over none of the panels, inside the figure
        for other in fig.axes:
            assert not _overlaps(box, other.get_window_extent())
        assert fig_box.x0 <= box.x0 and box.x1 <= fig_box.x1
        # the raw fixes of the zoomed fault period are inside the zoom
        span = title.split("t = ")[1].split(" s")[0]
        a, b = (float(v) for v in span.split("-"))
        assert any(a - 1e-6 <= t <= b + 1e-6 for t in faulty), (a, b)
        labels = {line.get_marker() for line in zoom.get_lines()}
        assert {"+", "o", "x"} <= labels  # raw fixes, the output, the replaced fixes
    for i, a_box in enumerate(boxes):
        for b_box in boxes[i + 1:]:
            assert not _overlaps(a_box, b_box)
    # the time panels keep the whole width; the track shares its row with the zooms
    assert err.get_window_extent().width > 1.4 * track.get_window_extent().width


def test_zoom_periods_pick_largest_longest_smallest() -> None:
    t = [0.1 * k for k in range(100)]
    err: list[float | None] = [0.3] * 100
    spans = [(1.0, 1.0), (3.0, 3.5), (6.0, 6.0)]
    for k, e in ((10, 7.0), (30, 1.5), (31, 1.6), (32, 1.5), (33, 1.5), (34, 1.4), (35, 1.5),
                 (60, 1.1)):
        err[k] = e
    picks = plots._zoom_periods(spans, t, err)
    assert picks == [("largest", (1.0, 1.0)), ("longest", (3.0, 3.5)),
                     ("smallest", (6.0, 6.0))]
    assert plots._zoom_periods([], t, err) == []
