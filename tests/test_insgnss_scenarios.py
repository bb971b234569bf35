"""The issue's done-means on the paper's scenarios (config/insgnss-paper.toml, seed 1).

Position-only GNSS (3 m east/north, 5 m up, white), navigation-grade IMU, 501 epochs at 1 s.
Measured on seed 1 (RMS = 3-D position RMS over epochs 1..500, m):

    scenario           none   downweight  replace  three_zone
    paper-random      28.86      2.07       2.03      2.15
    paper-single      14.07      1.82       1.86      2.02
    paper-continuous  90.29    155.87      18.49     20.03
    paper-deviation    2.98      1.70       1.77      1.97
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from firmware_host.cli import main
from firmware_host.insgnss_sim import MethodRun, load_setup, run_scenario

ROOT = Path(__file__).resolve().parents[1]
SEED = 1
# Cai & Shao, Table 2 (20 m faults), robust filtering, m: (min, max) east, north, up
PAPER_TABLE2 = {"east": (-11.8, 6.06), "north": (-6.64, 7.54), "up": (-2.62, 2.57)}


@pytest.fixture(scope="module")
def results() -> dict[str, tuple[dict[str, Any], dict[str, MethodRun]]]:
    setup = load_setup(ROOT / "config" / "insgnss-paper.toml")
    out = {}
    for scenario in ("paper-random", "paper-single", "paper-continuous", "paper-deviation"):
        summary, _data, runs = run_scenario(setup, scenario, SEED)  # type: ignore[arg-type]
        out[scenario] = (summary, runs)
    return out


def _rms(summary: dict[str, Any], method: str) -> float:
    return float(summary["methods"][method]["position_rms_3d_m"])


@pytest.mark.parametrize(
    "scenario", ["paper-random", "paper-single", "paper-continuous", "paper-deviation"]
)
def test_three_zone_beats_no_robust_filtering(results: dict, scenario: str) -> None:
    summary, _ = results[scenario]
    # The done-means is on position RMS; per axis, up is not always better (deviation: 0.97
    # vs 0.92 m, the 4 m up faults are under the 5 m noise; continuous: the 20 m up fault is
    # absorbed by every method), so only east and north are asserted per axis.
    assert _rms(summary, "three_zone") < _rms(summary, "none")
    for axis in ("east", "north"):
        tz = summary["methods"]["three_zone"]["position_m"][axis]["rms"]
        assert tz < summary["methods"]["none"]["position_m"][axis]["rms"]


def test_single_faults_downweight_and_replace_far_better(results: dict) -> None:
    summary, _ = results["paper-single"]
    none = _rms(summary, "none")
    assert _rms(summary, "downweight") < none / 4
    assert _rms(summary, "replace") < none / 4


def test_random_faults_detected(results: dict) -> None:
    summary, _ = results["paper-random"]
    m = summary["methods"]["three_zone"]
    assert summary["fault_epochs"] == 100
    assert m["fault_epochs_flagged"] >= 99  # 100 m faults: every one found
    assert _rms(summary, "three_zone") < 0.1 * _rms(summary, "none")


def test_continuous_faults_bounded_where_downweighting_drifts(results: dict) -> None:
    _, runs = results["paper-continuous"]

    def horiz(run: MethodRun, lo: int, hi: int) -> float:
        e = run.pos_err[lo - 1 : hi]  # epochs lo..hi
        return float(np.hypot(e[:, 0], e[:, 1]).max())

    tz, dw = horiz(runs["three_zone"], 10, 200), horiz(runs["downweight"], 10, 200)
    assert tz < 40.0  # INS coasting through 190 s of 100 m faults (measured 30 m)
    assert dw > 5 * tz  # down-weighting alone is dragged off (measured 281 m)
    assert horiz(runs["three_zone"], 300, 500) < 5.0  # and recovers once the faults stop


def test_deviation_ranges_vs_paper_table2(results: dict) -> None:
    summary, _ = results["paper-deviation"]
    ours = summary["methods"]["three_zone"]["position_m"]
    for axis in ("east", "north"):
        lo, hi = PAPER_TABLE2[axis]
        assert lo <= ours[axis]["min"] and ours[axis]["max"] <= hi
        assert ours[axis]["max"] - ours[axis]["min"] <= 0.7 * (hi - lo)  # the 30 % goal
    # Up: the span is within the paper's (5.02 vs 5.19 m) but not 30 % tighter, and the
    # maximum (3.20 m) is above the paper's 2.57 m: the up range here is set by the 5 m
    # vertical GNSS noise (no robust filtering gives -2.03..2.84 m), not by the faults.
    lo, hi = PAPER_TABLE2["up"]
    assert ours["up"]["max"] - ours["up"]["min"] <= hi - lo


def test_velocity_aided_default_preset_bounded_on_continuous_faults() -> None:
    setup = load_setup(ROOT / "config" / "insgnss.toml")  # MEMS IMU, GNSS velocity used
    _summary, _data, runs = run_scenario(setup, "paper-continuous", SEED,
                                         strategies=("downweight", "three_zone"))
    tz = np.hypot(*runs["three_zone"].pos_err[:, :2].T).max()
    dw = np.hypot(*runs["downweight"].pos_err[:, :2].T).max()
    assert tz < 8.0 and dw > 2 * tz


def test_cli_writes_summary(tmp_path: Path) -> None:
    rc = main(["sim", "insgnss", "--scenario", "paper-single", "--seed", "2",
               "--out", str(tmp_path), "--no-plots"])
    assert rc == 0
    doc = json.loads((tmp_path / "summary.json").read_text(encoding="utf-8"))
    assert set(doc["methods"]) == {"none", "downweight", "replace", "three_zone"}
    m = doc["methods"]["three_zone"]
    assert set(m["position_m"]) == {"east", "north", "up"}
    assert {"min", "max", "rms"} <= set(m["velocity_m_s"]["east"])
    assert set(m["zones"]) == {"no_fault", "deviation", "over_limit"}
    assert doc["fault_epochs"] == 50
