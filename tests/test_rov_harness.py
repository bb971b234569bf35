"""Issue 14's "done means" on both simulated plants, 10 seeds each (worst seed asserted).

The numbers come from :mod:`firmware_host.devtools.rov_harness` (the same scenarios as
``docs/rov.md``). Where a goal is not met on a plant, the test asserts the measured bound
instead (marked SHORTFALL with the reason), so that a regression still fails; ``docs/rov.md``
lists the shortfalls. Seeds 1-10 (the witness was tuned on seeds 101-120).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest

from firmware_host.devtools.rov_harness import (
    GOALS,
    Worst,
    hold_floor,
    measure,
    merge,
    step_then_drift,
    table,
)
from firmware_host.rov.config import Plant, RovConfig, load_rov_config, project_root

SEEDS = range(1, 11)
QUICK = ("step", "ramp", "ramp_slow", "stuck", "spike", "burst")

# SHORTFALLS (measured, seeds 1-10; docs/rov.md): the bound asserted instead of the goal.
SHORTFALL: dict[tuple[str, str], tuple[float, str]] = {
    # The heading error itself includes the plant's own hold floor (1.3 deg with no fault on
    # this plant, below); beyond the same seed's no-fault run the step adds 1.04 deg (goal
    # met). Measured 1.91 on seeds 1-10 (seed 3 drift:20@24, a step 4 s after the warm-up:
    # its bias is the warm-up's, 0.031 deg/s off, and the delay line's 2 s fed at the
    # confirmation moved it to 0.038), 1.74 on 201-210; fourth pass 1.85 and 1.88.
    ("nonlinear", "step.err_after_deg"): (1.95, "hold floor 1.3 deg + dead reckoning"),
    # A 3 deg noise burst's first 1.6 s can be a run of one sign that the fast CUSUM takes
    # for a 3-sigma level (seed 2: 8 of 9 samples negative). Seeds 1000-1279 (not the
    # harness's), nonlinear plant: 6 of 280 bursts confirmed with the fourth pass's bias fit,
    # 5 with the fifth's (Nomoto 13 -> 14): a 2 % rate that 10 seeds show or not by chance
    # (fourth pass: 0 on 1-10, 1 on the Nomoto plant of 101-120). Ninth pass (a fast
    # confirmation needs a level of 3.5 deg, gyro_step_min_deg): 1000-1279 nonlinear 5 -> 4,
    # Nomoto 14 -> 3; this one's level was 3.8 deg (8 of 9 samples of one sign).
    ("nonlinear", "burst.confirmations"): (1.0, "a burst's chance run of one sign"),
}


@pytest.fixture(scope="module")
def cfg() -> RovConfig:
    c, _ = load_rov_config(project_root() / "config" / "rov.toml")
    return c


@pytest.fixture(scope="module")
def gyro_results(cfg: RovConfig) -> dict[str, dict[str, dict[str, Any]]]:
    plants: tuple[Plant, ...] = ("nomoto", "nonlinear")
    return {p: measure(cfg, p, SEEDS, gyro=True, which=QUICK) for p in plants}


def _check(plant: str, key: str, res: dict[str, Any]) -> None:
    goal = GOALS[key][1]
    bound, why = SHORTFALL.get((plant, key), (goal, ""))
    worst = res["worst"]
    if bound == float("inf"):
        return  # SHORTFALL without a bound: measured and reported only
    assert worst is not None, f"{plant} {key}: never ({res['where']})"
    assert worst <= bound + 1e-9, f"{plant} {key}: {worst} > {bound} at {res['where']} {why}"


@pytest.mark.slow
@pytest.mark.parametrize("plant", ["nomoto", "nonlinear"])
@pytest.mark.parametrize("key", [k for k in GOALS if not k.startswith("long.")])
def test_done_means_with_gyro(gyro_results: dict[str, dict[str, dict[str, Any]]], plant: str,
                              key: str) -> None:
    res = gyro_results[plant][key]
    assert res["runs"] >= 10
    _check(plant, key, res)


@pytest.mark.slow
@pytest.mark.parametrize("plant", ["nomoto", "nonlinear"])
def test_one_hour_at_2_deg_with_turns_then_a_drift(cfg: RovConfig, plant: Plant) -> None:
    res = measure(cfg, plant, SEEDS, gyro=True, which=("long",))
    assert res["long.false_confirmations"]["worst"] == 0, res
    _check(plant, "long.drift_delay_s", res["long.drift_delay_s"])


@pytest.mark.slow
@pytest.mark.parametrize("plant", ["nomoto", "nonlinear"])
def test_without_gyro_one_hour_no_false_confirmation_after_turns(cfg: RovConfig,
                                                                  plant: Plant) -> None:
    """No gyro, 1 h at 2 deg with a turn every 60 s: theta is raised for 5 s after each
    setpoint change (``turn_window_s``); before, 2 (Nomoto) and 1 (nonlinear) false
    confirmations, each 1 s after a turn. Without the window the same run has them again."""
    res = measure(cfg, plant, SEEDS, gyro=False, which=("long",))
    assert res["long.false_confirmations"]["worst"] == 0, res
    _check(plant, "long.drift_delay_s", res["long.drift_delay_s"])
    # Without the window: seed 1 had its false confirmation at 1261 s (Nomoto) and 1262 s
    # (nonlinear), seeds 2 and 3 at 842/1622 s and 1921/2341 s; half an hour of seed 1 shows it.
    off = replace(cfg, ft=replace(cfg.ft, turn_window_s=0.0))
    assert measure(off, plant, SEEDS[:1], gyro=False, which=("long",), long_s=1800.0)[
        "long.false_confirmations"]["worst"] >= 1


@pytest.mark.slow
@pytest.mark.parametrize("plant", ["nomoto", "nonlinear"])
def test_without_gyro_stuck_is_taken_back_and_spikes_bursts_pass(cfg: RovConfig,
                                                                  plant: Plant) -> None:
    """No gyro: what the FIR alone still does (docs/rov.md: what it cannot do)."""
    res = measure(cfg, plant, SEEDS, gyro=False, which=("stuck", "spike", "burst"))
    assert res["stuck.delay_samples"]["worst"] <= 10
    assert res["stuck.retake_s"]["worst"] is not None and res["stuck.retake_s"]["worst"] <= 5.0
    assert res["stuck.final_err_deg"]["worst"] <= 1.0
    assert res["spike.confirmations"]["worst"] == 0
    # SHORTFALL: the FIR alone cannot tell a 3 deg burst's first seconds from a step (a burst
    # test on e also blocked real steps on the BlueROV2 dive): 1 run of 10, worst seed.
    assert res["burst.confirmations"]["worst"] <= 1


@pytest.mark.slow
def test_hold_floor_is_what_the_shortfall_says(cfg: RovConfig) -> None:
    """The nonlinear plant's no-fault heading error, the reason given above: through the
    thrust-curve inverse (the harness's vehicle PID) and, for comparison, on the raw command."""
    floor = hold_floor(cfg, "nonlinear", SEEDS, gyro=True)["worst"]
    assert 0.5 < floor < 1.5
    raw = hold_floor(cfg, "nonlinear", SEEDS, gyro=True, vehicle_pid=False)["worst"]
    assert 2.0 < raw < 3.5
    assert hold_floor(cfg, "nomoto", SEEDS, gyro=True)["worst"] < 0.5


@pytest.mark.slow
def test_a_drift_after_a_compensated_step_is_confirmed_on_the_nonlinear_plant(
        cfg: RovConfig) -> None:
    """A 10 deg step at 40 s, then +-0.1 deg/s from 60 s (docs/rov.md, seventh pass): the
    drift is confirmed as a second fault in every run (goal 40 s; measured worst 25.0 s,
    seed 4). SHORTFALL: the heading error from the drift's start on, goal 3 deg, measured
    3.09 (seed 3, ramp +0.1): the step's offset learned ~1 deg off, then dead reckoning on a
    bias 0.018 deg/s off (before this pass: never confirmed, 9.26 deg; with the drift
    confirmed but the drifting compass taken back as it crossed the dead reckoning: 3.75)."""
    res = step_then_drift(cfg, "nonlinear", SEEDS)
    assert res["delay_s"]["worst"] is not None and res["delay_s"]["worst"] <= 40.0
    assert res["err_after_deg"]["worst"] <= 3.3


def test_bursts_that_dwelt_on_one_side_are_left_to_the_slow_cusum(cfg: RovConfig) -> None:
    """Nomoto seeds 102, 408 and 506: a 3 deg noise burst's first 4-6 samples on one side,
    at 2.4-3.2 deg, were confirmed as a step by the fast CUSUM. A step of interest is 5 deg
    or more; with ``gyro_step_min_deg`` (3.5) such a level is the slow CUSUM's, and none of
    these bursts confirms. Without it, each does."""
    seeds = (102, 408, 506)
    res = measure(cfg, "nomoto", seeds, gyro=True, which=("burst",))
    assert res["burst.confirmations"]["worst"] == 0, res
    off = replace(cfg, ft=replace(cfg.ft, gyro_step_min_deg=0.0))
    for seed in seeds:
        r = measure(off, "nomoto", (seed,), gyro=True, which=("burst",))
        assert r["burst.confirmations"]["worst"] >= 1, (seed, r)


def test_runs_over_the_goal_are_counted_and_shown() -> None:
    w = Worst(limit=5.0)
    for v, where in ((4.0, "a"), (8.0, "b"), (5.0, "c"), (float("inf"), "d"), (6.0, "e")):
        w.add(v, where)
    d = w.as_dict()
    assert (d["worst"], d["where"], d["runs"], d["over"]) == (None, "d", 5, 3)
    res = {"step.delay_samples": {"worst": 8, "where": "seed 808", "runs": 20, "over": 1},
           "burst.confirmations": {"worst": 0, "where": "seed 807", "runs": 2, "over": 0}}
    text = table({"nonlinear/gyro": res})
    assert "| 8 FAIL (1 of 20 runs) |" in text and "| 0 ok |" in text
    assert "stuck confirmed within" not in text  # not measured by any column: no row
    res2 = {"step.delay_samples": res["step.delay_samples"]}
    assert "| 0 ok | – |" in table({"a": res, "b": res2})  # b measured no bursts


def test_seeds_measured_one_by_one_and_merged_are_the_seeds_measured_at_once(
        cfg: RovConfig) -> None:
    which = ("spike", "burst", "stuck")
    whole = measure(cfg, "nomoto", (1, 2, 3), gyro=True, which=which)
    parts = [measure(cfg, "nomoto", (s,), gyro=True, which=which) for s in (1, 2, 3)]
    assert merge(parts) == whole
    assert set(whole) == {k for k in GOALS if k.split(".")[0] in which}


def test_the_command_prints_the_table_and_writes_measure_s_numbers(cfg: RovConfig,
                                                                    tmp_path: Path) -> None:
    """``fdi-bridge sim rov-harness``: what :func:`measure` gives, as a table and JSON."""
    root = project_root()
    out = subprocess.run(
        [sys.executable, "-m", "firmware_host.cli", "sim", "rov-harness", "--seeds", "1-2",
         "--plants", "nomoto", "--scenarios", "spike,burst", "--json", str(tmp_path / "r.json")],
        cwd=tmp_path, capture_output=True, text=True, timeout=300,
        env=dict(os.environ, PYTHONPATH=str(root)))
    assert out.returncode == 0, out.stderr
    assert out.stdout.splitlines()[0].split() == ["criterion", "goal", "nomoto/gyro"]
    assert "noise bursts: confirmations" in out.stdout
    assert "1 plant/gyro cases x 2 seeds in" in out.stdout
    doc = json.loads((tmp_path / "r.json").read_text())
    assert doc["seeds"] == [1, 2] and doc["partial"] is False
    assert doc["results"]["nomoto/gyro"] == measure(cfg, "nomoto", (1, 2), gyro=True,
                                                    which=("spike", "burst"))
