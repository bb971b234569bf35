"""The issue's done-means on the paper's scenarios, over seeds 1-5.

``config/insgnss-paper.toml``: position-only GNSS (white; 3 m east/north, and 1.15 m up: the
ratio of up to horizontal in the paper's own Table 2, see the preset), navigation-grade IMU,
501 epochs at 1 s, the paper's α1, α2, n. ``config/insgnss.toml``: MEMS IMU, GNSS velocity,
5 m up. 3-D position RMS (m) over epochs 1..500, measured with
``fdi-bridge sim insgnss-report`` (every method, axis, seed and preset, as in docs/insgnss.md):

    paper preset       seed   none       downweight  replace   three_zone
    paper-continuous   1-5    90.0-90.3  152-162     9.6-29.3  5.5-19.5
    paper-random       1-5    28.9-30.6  0.9-1.4     1.1-1.4   1.1-1.6
    paper-single       1-5    14.0-14.5  0.9-1.4     1.0-1.5   1.0-1.6
    paper-deviation    1-5     2.8-3.2   0.9-1.4     1.0-1.5   1.0-1.6

Time: each filter run takes 0.6 s, so the multi-seed checks run only three-zone on every seed
(the lock-in depends on the seed) and compare it with the baselines of seed 1 where those are
fault-dominated and do not depend on the seed (none on paper-continuous: 90.0-90.3 m, on
paper-single 14.0-14.5 m; down-weighting on paper-continuous 152-162 m). On paper-random and
paper-deviation both run on every seed. ``_run`` caches per preset, scenario, seed and method.
"""

from __future__ import annotations

import json
import re
from functools import cache
from pathlib import Path

import numpy as np
import pytest

from firmware_host.cli import main
from firmware_host.devtools.insgnss_sim import (
    InsGnssSetup,
    MethodRun,
    NavData,
    generate,
    load_setup,
    run_method,
)

ROOT = Path(__file__).resolve().parents[1]
SEEDS = (1, 2, 3, 4, 5)
PRESETS = ("insgnss-paper", "insgnss")
# Cai & Shao, Table 2 (20 m faults), with robust filtering, m: (min, max) east, north, up
PAPER_TABLE2 = {"east": (-11.8, 6.06), "north": (-6.64, 7.54), "up": (-2.62, 2.57)}
# ... and without robust filtering
PAPER_TABLE2_NONE = {"east": (-25.8, 32.6), "north": (-20.5, 34.9), "up": (-7.9, 13.9)}
FAULTS = slice(9, 200)  # epochs 10..200 (pos_err row k is epoch k + 1)
AFTER = slice(299, 500)  # epochs 300..500


@cache
def _setup(preset: str) -> InsGnssSetup:
    return load_setup(ROOT / "config" / f"{preset}.toml")


@cache
def _data(preset: str, scenario: str, seed: int) -> NavData:
    return generate(_setup(preset), scenario, seed)  # type: ignore[arg-type]


@cache
def _run(preset: str, scenario: str, seed: int, method: str) -> MethodRun:
    return run_method(_data(preset, scenario, seed), _setup(preset).filter, method)  # type: ignore[arg-type]


def _rms3(run: MethodRun) -> float:
    return float(np.sqrt(np.mean(np.sum(run.pos_err**2, axis=1))))


def _horiz(run: MethodRun, rows: slice) -> float:
    e = run.pos_err[rows]
    return float(np.hypot(e[:, 0], e[:, 1]).max())


# ---------------------------------------------------------------- paper-continuous: lock-in


@pytest.mark.parametrize("seed", SEEDS)
def test_continuous_paper_preset_bounded_where_downweighting_drifts(seed: int) -> None:
    none = _run("insgnss-paper", "paper-continuous", 1, "none")
    dw = _run("insgnss-paper", "paper-continuous", 1, "downweight")
    tz = _run("insgnss-paper", "paper-continuous", seed, "three_zone")
    assert _rms3(tz) < 0.25 * _rms3(none)  # measured 5.5-19.5 m against 90 m
    # Through the 190 s of 100 m faults (141 m horizontally) the INS coasts and is never dragged
    # onto the fault: less than half of it (measured 9-51 m: the INS's own drift) ...
    assert _horiz(tz, FAULTS) < 70.0
    # ... where down-weighting alone is taken most of the way (measured 280 m on seed 1)
    assert _horiz(dw, FAULTS) > 4.0 * _horiz(tz, FAULTS)
    # and no lock-in: once the faults stop the receiver is accepted again (measured 1.8-3.4 m,
    # the level of fault-free data). Before the jump tracker, seed 3 ended 600 m off.
    assert _horiz(tz, AFTER) < 5.0


@pytest.mark.parametrize("seed", SEEDS)
def test_continuous_velocity_aided_preset_bounded(seed: int) -> None:
    none = _run("insgnss", "paper-continuous", 1, "none")  # 84.6-84.9 m on seeds 1-5
    tz = _run("insgnss", "paper-continuous", seed, "three_zone")
    assert _rms3(tz) < 0.1 * _rms3(none)  # measured 1.8-5.5 m against 85 m
    assert _horiz(tz, FAULTS) < 10.0  # velocity aiding holds the INS (measured 3.2-6.9 m)
    assert _horiz(tz, AFTER) < 5.0


def test_continuous_velocity_aided_downweighting_is_dragged() -> None:
    dw = _run("insgnss", "paper-continuous", 1, "downweight")
    tz = _run("insgnss", "paper-continuous", 1, "three_zone")
    assert _rms3(dw) > 4.0 * _rms3(tz)  # measured 14.1 vs 2.1 m


def test_continuous_without_jump_tracker_locks_in() -> None:
    # The paper's method alone (track_jumps = false) on the seed that exposed the lock-in: the
    # drifted INS takes the fault in near 185 s and rejects the good fixes afterwards.
    from dataclasses import replace

    setup = _setup("insgnss-paper")
    params = replace(setup.filter, three_zone=replace(setup.filter.three_zone, track_jumps=False))
    run = run_method(_data("insgnss-paper", "paper-continuous", 3), params, "three_zone")
    assert _horiz(run, AFTER) > 100.0  # measured 600 m at the end
    assert _horiz(_run("insgnss-paper", "paper-continuous", 3, "three_zone"), AFTER) < 5.0


# ---------------------------------------------------------------- the other scenarios


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("scenario", ["paper-random", "paper-deviation"])
def test_three_zone_beats_no_robust_filtering(scenario: str, seed: int) -> None:
    none = _run("insgnss-paper", scenario, seed, "none")
    tz = _run("insgnss-paper", scenario, seed, "three_zone")
    assert _rms3(tz) < _rms3(none)
    # and on every axis (per-axis RMS ratio three-zone / none measured 0.03-0.09 on
    # paper-random, 0.32-0.91 on paper-deviation: up on seed 4 is 0.91, its start-up error)
    for i in range(3):
        assert np.sqrt(np.mean(tz.pos_err[:, i] ** 2)) < np.sqrt(np.mean(none.pos_err[:, i] ** 2))


@pytest.mark.parametrize("seed", SEEDS)
def test_single_faults_downweight_and_replace_far_better(seed: int) -> None:
    none = _rms3(_run("insgnss-paper", "paper-single", 1, "none"))
    methods = ("downweight", "replace", "three_zone") if seed == 1 else ("downweight", "replace")
    for method in methods:  # three-zone on seed 2: test_cli_writes_summary
        assert _rms3(_run("insgnss-paper", "paper-single", seed, method)) < none / 5  # 14 vs < 2


def test_random_faults_detected() -> None:
    data = _data("insgnss-paper", "paper-random", 1)
    run = _run("insgnss-paper", "paper-random", 1, "three_zone")
    faulty = np.any(data.fault[1:] != 0, axis=1)
    assert int(faulty.sum()) == 100
    assert int(np.sum(run.flagged & faulty)) >= 99  # 100 m faults: every one found
    assert _rms3(run) < 0.1 * _rms3(_run("insgnss-paper", "paper-random", 1, "none"))


@pytest.mark.parametrize("seed", SEEDS)
def test_deviation_ranges_vs_paper_table2(seed: int) -> None:
    # Three-zone inside Table 2's robust ranges on every axis and seed, and at least 30 % tighter
    # (the goal): spans measured east 3.6-6.9 m (Table 2: 17.9), north 2.6-3.7 (14.2), up
    # 1.2-2.5 (5.2); up's widest is seed 4's start (initial error -1.78 m, a 1.8σ draw).
    tz = _run("insgnss-paper", "paper-deviation", seed, "three_zone")
    for i, axis in enumerate(("east", "north", "up")):
        lo, hi = PAPER_TABLE2[axis]
        e = tz.pos_err[:, i]
        assert lo <= e.min() and e.max() <= hi, axis
        assert e.max() - e.min() <= 0.7 * (hi - lo), axis


def test_paper_preset_vertical_noise_follows_the_papers_ratio() -> None:
    # The paper gives no GNSS noise. Its own errors without robust filtering (Table 2) span
    # 21.8 m up against 58.4 m east and 55.4 m north; the preset keeps that ratio to its 3 m
    # horizontal noise, in the generator and in the filter alike. Pinned here so that the
    # vertical noise cannot drift to whatever passes: with 5 m (a real receiver's vertical,
    # kept in config/insgnss.toml) the up range is noise, not faults, and even fault-free data
    # without robust filtering leaves Table 2 (docs/insgnss.md, the sweep).
    span = {a: hi - lo for a, (lo, hi) in PAPER_TABLE2_NONE.items()}
    ratio = span["up"] / ((span["east"] + span["north"]) / 2)
    setup = _setup("insgnss-paper")
    for block in (setup.sim, setup.filter):
        assert block.gnss_sigma_h_m == 3.0
        assert block.gnss_sigma_v_m == pytest.approx(ratio * block.gnss_sigma_h_m, abs=0.01)
    assert _setup("insgnss").sim.gnss_sigma_v_m == 5.0


# ---------------------------------------------------------------- the command


def test_cli_writes_summary(tmp_path: Path) -> None:
    rc = main(["sim", "insgnss", "--scenario", "paper-single", "--seed", "2",
               "--out", str(tmp_path), "--no-plots"])
    assert rc == 0
    doc = json.loads((tmp_path / "summary.json").read_text(encoding="utf-8"))
    assert set(doc["methods"]) == {"none", "downweight", "replace", "three_zone", "fault_state"}
    m = doc["methods"]["three_zone"]
    assert set(m["position_m"]) == {"east", "north", "up"}
    assert {"min", "max", "rms"} <= set(m["velocity_m_s"]["east"])
    assert set(m["zones"]) == {"no_fault", "deviation", "over_limit"}
    assert doc["fault_epochs"] == 50
    assert m["position_rms_3d_m"] < doc["methods"]["none"]["position_rms_3d_m"] / 5


def test_report_command_prints_the_tables(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "report.md"
    rc = main(["sim", "insgnss-report", "--seeds", "2", "--scenario", "paper-deviation",
               "--config", str(ROOT / "config" / "insgnss-paper.toml"),
               "--sweep-sigma-v", "5", "--out", str(out)])
    assert rc == 0
    text = out.read_text(encoding="utf-8")
    console = capsys.readouterr().out  # the same report as aligned tables (issue 17)
    assert "|---" not in console and re.search(r"^insgnss-paper +2 ", console, re.M)
    rows = [ln for ln in text.splitlines() if ln.startswith("| insgnss-paper | 2 |")]
    assert len(rows) == 1  # the Table 2 row: every axis inside and 30 % tighter
    assert rows[0].count("✓✓") == 3
    # the sweep row at 5 m up: seed 2 leaves Table 2 (measured -3.08 … 1.95 m), no mark
    sweep = [ln for ln in text.splitlines() if ln.startswith("| 5 | 2 |")]
    assert len(sweep) == 1 and "✓" not in sweep[0]


def test_report_seed_lists() -> None:
    from firmware_host.commands.checks import seed_list
    from firmware_host.devtools.insgnss_report import range_verdict

    assert seed_list("1-3,7") == [1, 2, 3, 7]
    pos = {"up": {"min": -1.0, "max": 1.0}}
    assert range_verdict(pos, "up").endswith("✓✓")  # span 2.0 <= 0.7 × 5.19
    assert range_verdict({"up": {"min": -2.6, "max": 2.5}}, "up").endswith(" ✓")
    assert "✓" not in range_verdict({"up": {"min": -3.0, "max": 1.0}}, "up")
