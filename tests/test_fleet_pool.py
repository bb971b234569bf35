"""The fleet's default executor (issue 46): a local process pool gives the rows the serial run
gives, in job order, and leaves no worker process behind, also when interrupted.

The Dask executors are compared with these in hil_tests/test_fleet.py (the ``fleet`` extra)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

from firmware_host.commands.replay import load_input
from firmware_host.devtools import fleet
from firmware_host.devtools.eval import run_ours
from firmware_host.devtools.fleet import (
    discover,
    parse_sweeps,
    point_configs,
    replay_rover,
    run_fleet,
)
from firmware_host.devtools.rover_sim import RoverScenario, write_run
from firmware_host.rov.config import RovConfig
from tests.processes import descendants, leftovers


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("fleet-pool")
    for seed in range(1, 7):  # 6 generated runs, 2 min each, 1/5/10 Hz
        write_run(RoverScenario(rate_hz=(1.0, 5.0, 10.0)[seed % 3], duration_s=120.0,
                                seed=200 + seed), root / f"run{seed}")
    (root / "damaged.cap").write_bytes(b"\x00\x01not a capture\xff" * 40)
    return root


pytestmark = pytest.mark.skipif(not Path("/proc/self/stat").is_file(),
                                reason="the leftover-process check reads /proc (Linux)")


def test_the_pool_gives_the_serial_rows_in_job_order_and_leaves_no_worker(runs: Path) -> None:
    logs = discover([str(runs)])
    configs = point_configs("rover", parse_sweeps(["rover.detector.gate_m=0.2,3.0"]))
    before = descendants()
    serial = run_fleet(logs, configs, RovConfig(), workers=1)
    pool = run_fleet(logs, configs, RovConfig(), workers=2)
    assert serial.executor == "serial" and pool.executor == "process pool x2"
    assert len(serial.rows) == 2 * len(logs) == 14
    assert pool.rows == serial.rows
    assert [r["error"] is not None for r in pool.rows].count(True) == 2  # damaged.cap, twice
    assert sum(r.get("epochs", 0) for r in pool.rows) > 0
    assert descendants() <= before


def test_an_interrupted_pool_keeps_the_rows_done_and_leaves_no_worker(runs: Path) -> None:
    logs = discover([str(runs)])
    configs = point_configs("rover", parse_sweeps([]))
    before = descendants()

    def interrupt(done: int, total: int) -> None:  # ^C once the first job is done
        raise KeyboardInterrupt

    result = run_fleet(logs, configs, RovConfig(), workers=2, progress=interrupt)
    assert result.partial and result.jobs == len(logs) == 7
    assert 1 <= len(result.rows) < result.jobs
    full = run_fleet(logs, configs, RovConfig(), workers=1)
    assert all(r in full.rows for r in result.rows)
    assert descendants() <= before


def test_one_job_or_one_worker_runs_in_this_process(runs: Path) -> None:
    logs = discover([str(runs / "run1")])
    configs = point_configs("rover", parse_sweeps([]))
    assert run_fleet(logs, configs, RovConfig(), workers=4).executor == "serial"


def test_the_fleet_command_leaves_no_process_running_after_it_exits(runs: Path) -> None:
    root = str(Path(__file__).resolve().parents[1])
    rc, left = leftovers([sys.executable, "-m", "firmware_host.cli", "fleet", str(runs),
                          "--workers", "2", "--json"], root)
    assert rc == 0
    assert left == []


def test_a_job_keeps_the_records_eval_reads_back_from_epochs_jsonl(runs: Path) -> None:
    cfg = point_configs("rover", parse_sweeps([]))["config"]
    for run in ("run1", "run3"):  # 5 Hz and 1 Hz; faults and replacements in both
        data = b"".join(c for _, c in load_input(runs / run / "rover.cap").chunks)
        ours, summary = run_ours(cfg, data)
        kept, counted = replay_rover(cfg, data, records=True)
        assert len(kept) == summary["epochs"] >= 120
        assert json.dumps(kept) == json.dumps(ours)  # the same values (NaN included)
        assert sum(r["action"] == "replace" for r in kept) > 0
        _, bare = replay_rover(cfg, data, records=False)
        for key in ("epochs", "faults", "alarms", "actions", "reasons", "input", "gate_health"):
            assert bare[key] == counted[key] == summary[key], key


def test_the_tradeoff_plot_labels_in_a_legend_on_a_percentage_axis() -> None:
    """Issue E: points near 100 % detected had their labels written over each other on a
    96-104 % axis; now each marker carries a number, the labels are in the legend, and the
    detection axis ends at 100.5 %."""
    matplotlib = pytest.importorskip("matplotlib", reason="the dev extra's matplotlib")
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    pts = [(f"rover.detector.gate_sigmas={g}", {"false_alarm_pct": 0.01 * g,
                                                "detected_pct": 99.0 + 0.2 * g})
           for g in (4, 5, 6)]
    fig = fleet.tradeoff_figure(plt, pts)
    ax = fig.axes[0]
    try:
        assert [t.get_text() for t in ax.get_legend().get_texts()] == [
            f"{i}: {label}" for i, (label, _) in enumerate(pts, 1)]
        assert [t.get_text() for t in ax.texts] == ["1", "2", "3"]
        assert ax.get_ylim()[1] <= 100.5
    finally:
        plt.close(fig)
