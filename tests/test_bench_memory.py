"""``fdi-bridge bench``'s child measurements (issue 46): a child's own peak RSS, not the bench's,
as ``/usr/bin/time -f %M`` reads it; the replay against gpsd's ``gpsdecode``. Speed is never
asserted here: only that the figures are made, are the child's own, and are judged."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from firmware_host.devtools import bench

MIB = 1 << 20
# A child that touches 150 MiB (bytes * n writes every page), then exits.
BIG = [sys.executable, "-S", "-c", "b = b'x' * (150 << 20); print(len(b))"]
SMALL = [sys.executable, "-S", "-c", "pass"]


def _gnu_time_mib(cmd: list[str]) -> float:
    proc = subprocess.run(["/usr/bin/time", "-f", "%M", *cmd], capture_output=True, text=True,
                          check=True)
    return int(proc.stderr.strip().splitlines()[-1]) / 1024.0


def test_a_child_peak_is_its_own_not_the_measuring_process() -> None:
    ballast = b"y" * (200 * MIB)  # this process is now above 200 MiB
    small = bench.measure_child(SMALL)
    big = bench.measure_child(BIG)
    assert len(ballast) == 200 * MIB
    assert small.returncode == 0 and big.returncode == 0
    assert small.peak_rss_mib < 40.0  # not this process's 200+ MiB
    assert 150.0 <= big.peak_rss_mib < 150.0 + 40.0
    assert big.cpu_s > 0.0


@pytest.mark.skipif(not Path("/usr/bin/time").is_file(), reason="GNU time not installed")
def test_the_peak_is_within_20_percent_of_gnu_time() -> None:
    for cmd in (BIG, [sys.executable, "-c", "import json, decimal, email.parser"]):
        ours = bench.measure_child(cmd).peak_rss_mib
        theirs = _gnu_time_mib(cmd)
        assert abs(ours - theirs) <= 0.2 * theirs, (cmd, ours, theirs)


def test_a_failing_command_gives_its_status() -> None:
    assert bench.measure_child([sys.executable, "-S", "-c", "raise SystemExit(3)"]
                               ).returncode == 3
    assert bench.measure_child(["/nonexistent/command"]).returncode == 127


def test_gpsdecode_rows_judge_the_ratios() -> None:
    res = {"gpsdecode": {"config": "rover", "epochs": 36000, "pairs": 3,
                         "cpu_s": {"gpsdecode": [0.3, 0.31, 0.29], "records": [1.5, 1.6, 1.4],
                                   "no_pty": [1.2, 1.2, 1.3], "no_records": [1.0, 1.0, 0.9]},
                         "peak_rss_mib": {"gpsdecode": 6.6, "records": 26.1, "no_pty": 25.0,
                                          "no_records": 24.0},
                         "ratio": {"records": 5.0, "no_pty": 4.1, "no_records": 3.3},
                         "floor_rss_mib": 5.1}}
    rows = bench.gpsdecode_rows(res)
    by = {r["figure"].split(":")[0]: r for r in rows}
    recs = next(r for n, r in by.items() if "through a pty" in n)
    assert recs["value"] == 5.0 and recs["ok"] is True and recs["goal"] == "<= 5"
    nore = next(r for n, r in by.items() if "--no-records" in n)
    assert nore["ok"] is False and nore["goal"] == "<= 3"
    assert "1.50 CPU-s against gpsdecode's 0.300" in recs["figure"]
    assert rows[-1]["value"] == round(26.1 / 6.6, 2) and "`true`: 5.1 MiB" in rows[-1]["figure"]
    assert bench.gpsdecode_rows({"gpsdecode": {"error": "not installed"}}) == []


@pytest.mark.skipif(shutil.which("gpsdecode") is None, reason="gpsd's gpsdecode not installed")
def test_the_replay_against_gpsdecode_on_a_short_log() -> None:
    g = bench.bench_gpsdecode(duration_s=20.0, pairs=1)
    assert g["epochs"] == 200 and len(g["cpu_s"]["gpsdecode"]) == 1
    assert {"records", "no_pty"} <= set(g["ratio"])
    assert all(r > 0 for r in g["ratio"].values())
    # The replay's own memory: a Python process with its imports, far below the bench's.
    assert 10.0 < g["peak_rss_mib"]["records"] < 60.0
    assert g["floor_rss_mib"] < g["peak_rss_mib"]["records"]
