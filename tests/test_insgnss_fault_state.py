"""Issue 15: a persistent GNSS fault as a state (strategy ``fault_state``, the default preset),
and the calibrated Table 2 reproduction.

Seeds: subsets of 1-50 (the report command runs all 50: ``fdi-bridge sim insgnss-report
--done-means --seeds 1-50``; docs/insgnss.md has its numbers). The continuous-fault seeds
include the ones on which three-zone locked in before (14, 30, 44 on the default preset; 21 on
the paper preset, 174 m against 90 m for no robust filtering); the rest were picked to spread
over the range, not for their results. ``fdi-bridge eval --suite`` uses 101/202/303, which no
test uses. Each filter run takes about 0.6 s on an idle machine.
"""

from __future__ import annotations

from dataclasses import replace
from functools import cache
from pathlib import Path

import numpy as np
import pytest

from firmware_host.cli import main
from firmware_host.devtools.eval import INSGNSS_EVAL_SEEDS, insgnss_suite, insgnss_table
from firmware_host.devtools.insgnss_report import (
    PAPER_SIGMA_S_M,
    PAPER_TABLE2,
    PAPER_TABLE2_NONE,
    SPAN_TOLERANCE,
)
from firmware_host.devtools.insgnss_sim import (
    CoastRun,
    InsGnssSetup,
    MethodRun,
    NavData,
    generate,
    load_setup,
    run_coast,
    run_method,
)

ROOT = Path(__file__).resolve().parents[1]
FAULTS = slice(9, 200)  # paper-continuous: epochs 10..200 (pos_err row k is epoch k + 1)
AFTER = slice(209, 500)  # from 10 s after the fault's end
CONTINUOUS_SEEDS = (3, 14, 30, 44)
OTHER_SEEDS = (8, 27, 41)
AXES = ("east", "north", "up")


@cache
def _setup(preset: str) -> InsGnssSetup:
    return load_setup(ROOT / "config" / f"{preset}.toml")


@cache
def _data(preset: str, scenario: str, seed: int) -> NavData:
    return generate(_setup(preset), scenario, seed)  # type: ignore[arg-type]


@cache
def _run(preset: str, scenario: str, seed: int, method: str) -> MethodRun:
    return run_method(_data(preset, scenario, seed), _setup(preset).filter, method)  # type: ignore[arg-type]


@cache
def _coast(preset: str, seed: int) -> CoastRun:
    return run_coast(_data(preset, "paper-continuous", seed), _setup(preset).filter)


def _rms3(run: MethodRun) -> float:
    return float(np.sqrt(np.mean(np.sum(run.pos_err**2, axis=1))))


def _horiz(err: np.ndarray) -> float:
    return float(np.hypot(err[:, 0], err[:, 1]).max())


def test_default_preset_is_the_fault_state() -> None:
    flt = _setup("insgnss").filter
    assert flt.strategy == "fault_state"
    assert _setup("insgnss-paper").filter.strategy == "three_zone"  # the paper's, unchanged


# ---------------------------------------------------------------- paper-continuous


@pytest.mark.parametrize("seed", CONTINUOUS_SEEDS)
def test_continuous_fault_is_coasted_through_and_left_by_evidence(seed: int) -> None:
    run = _run("insgnss", "paper-continuous", seed, "fault_state")
    none = _run("insgnss", "paper-continuous", seed, "none")
    coast = _coast("insgnss", seed)
    # below no robust filtering, by far (measured 1.1-2.4 m against 85 m over seeds 1-50)
    assert _rms3(run) < 0.1 * _rms3(none)
    # the bound: the INS coasting over the fault's length, 3σ of the filter told the fault
    bound = 3.0 * float(coast.sigma_h[FAULTS].max())
    assert _horiz(run.pos_err[FAULTS]) <= bound
    # one fault believed through the 190 s (and a few one-epoch false onsets), and let go:
    assert run.faulted is not None
    assert run.faulted[FAULTS][5:].mean() > 0.95
    assert not run.faulted[AFTER].any() or run.faulted[AFTER].mean() < 0.02
    assert _horiz(run.pos_err[AFTER]) < 5.0  # back on the receiver


def test_continuous_no_seed_far_from_the_others() -> None:
    rms = [_rms3(_run("insgnss", "paper-continuous", s, "fault_state")) for s in CONTINUOUS_SEEDS]
    assert max(rms) <= 3.0 * float(np.median(rms))


@pytest.mark.parametrize("seed", [21, 44])
def test_fault_state_ends_the_paper_presets_lock_in(seed: int) -> None:
    # The same logic on the paper preset's data (position only, navigation-grade INS), where the
    # three-zone filter with the jump tracker locked in (seed 21: 174 m, seed 44: 129 m 3-D RMS
    # against 90 m without robust filtering; docs/insgnss-results.md).
    setup = _setup("insgnss-paper")
    params = replace(setup.filter, fault_state=_setup("insgnss").filter.fault_state)
    data = _data("insgnss-paper", "paper-continuous", seed)
    run = run_method(data, params, "fault_state")
    tz = _run("insgnss-paper", "paper-continuous", seed, "three_zone")
    none = _run("insgnss-paper", "paper-continuous", seed, "none")
    assert _rms3(tz) > _rms3(none)  # the lock-in this issue is about
    assert _rms3(run) < 0.1 * _rms3(none)
    assert _horiz(run.pos_err[AFTER]) < 5.0


# ---------------------------------------------------------------- the other scenarios


@pytest.mark.parametrize("scenario", ["paper-random", "paper-single", "paper-deviation"])
def test_no_worse_than_downweighting(scenario: str) -> None:
    fs = [_rms3(_run("insgnss", scenario, s, "fault_state")) for s in OTHER_SEEDS]
    dw = [_rms3(_run("insgnss", scenario, s, "downweight")) for s in OTHER_SEEDS]
    pooled = np.sqrt(np.mean(np.square(fs))) / np.sqrt(np.mean(np.square(dw)))
    assert pooled <= 1.05
    none = [_rms3(_run("insgnss", scenario, s, "none")) for s in OTHER_SEEDS]
    assert all(f < n for f, n in zip(fs, none, strict=True))


def test_clean_data_costs_nothing() -> None:
    # On fault-free data the fault state opens only on 3.5σ outliers and closes at once.
    for seed in (12, 36):
        fs = _run("insgnss", "clean", seed, "fault_state")
        dw = _run("insgnss", "clean", seed, "downweight")
        assert fs.faulted is not None and fs.faulted.mean() < 0.02
        assert _rms3(fs) <= 1.05 * _rms3(dw)


# ---------------------------------------------------------------- Table 2, calibrated


@pytest.mark.parametrize("seed", [4, 37])
def test_table2_calibration_reproduces_the_papers_first_column(seed: int) -> None:
    none = _run("insgnss-table2", "table2-calibrated", seed, "none")
    for i, axis in enumerate(AXES):
        lo, hi = PAPER_TABLE2_NONE[axis]
        span = float(none.pos_err[:, i].max() - none.pos_err[:, i].min())
        assert abs(span / (hi - lo) - 1.0) <= SPAN_TOLERANCE, axis
    # and the innovation size that the paper's §2.2 statistics imply (5.78 m)
    assert none.innovation_sigma[0] == pytest.approx(PAPER_SIGMA_S_M, rel=0.1)
    # the easier scenario is 5-10x easier than the paper's
    easy = _run("insgnss-paper", "paper-deviation", seed, "none")
    span_e = float(easy.pos_err[:, 0].max() - easy.pos_err[:, 0].min())
    assert span_e < 0.2 * (PAPER_TABLE2_NONE["east"][1] - PAPER_TABLE2_NONE["east"][0])


def test_table2_calibrated_downweighting_against_the_papers_robust_column() -> None:
    # On the calibrated footing down-weighting halves the spans of no robust filtering but
    # stays wider than the paper's robust column (measured 1.6-1.9x east/north, 3-4x up).
    for seed in (4, 37):
        dw = _run("insgnss-table2", "table2-calibrated", seed, "downweight")
        none = _run("insgnss-table2", "table2-calibrated", seed, "none")
        for i, axis in enumerate(AXES[:2]):
            span = float(dw.pos_err[:, i].max() - dw.pos_err[:, i].min())
            span_none = float(none.pos_err[:, i].max() - none.pos_err[:, i].min())
            lo, hi = PAPER_TABLE2[axis]
            assert span < 0.7 * span_none
            assert span > hi - lo  # wider than the paper's: no claim of matching it


def test_table2_calibrated_command(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "t2.md"
    rc = main(["sim", "insgnss-report", "--table2-calibrated", "--seeds", "9", "--out", str(out)])
    assert rc == 0
    text = out.read_text(encoding="utf-8")
    console = capsys.readouterr().out  # the same report as aligned tables (issue 17)
    assert "|---" not in console and "Table 2, calibrated" in console
    assert "### Table 2, calibrated" in text and "### Table 2, easier (uncalibrated)" in text
    rows = {ln.split("|")[1].strip(): ln for ln in text.splitlines() if ln.startswith("| ")}
    assert {"none", "downweight", "three_zone", "fault_state"} <= set(rows)
    calibrated, easier = text.split("### Table 2, easier")
    assert "within 25% on every axis: yes; seeds with every axis within: 1/1" in calibrated
    assert "within 25% on every axis: no" in easier


# ---------------------------------------------------------------- eval's held-out seeds


def test_eval_suite_seeds_are_held_out() -> None:
    test_seeds = {*CONTINUOUS_SEEDS, *OTHER_SEEDS, 4, 9, 12, 21, 36, 37, 44, *range(1, 51)}
    assert not set(INSGNSS_EVAL_SEEDS) & test_seeds
    # the suite's INS/GNSS rows (run here on a test seed, not on the held-out ones)
    rows = insgnss_suite(1, ["paper-single"], [47])
    by = {r["method"]: r for r in rows}
    assert set(by) == {"none", "downweight", "replace", "three_zone", "fault_state"}
    assert by["fault_state"]["pooled_rms_3d_m"] < by["none"]["pooled_rms_3d_m"] / 5
    assert "worst seed" in insgnss_table(rows)
