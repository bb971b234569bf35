"""``fdi-bridge bench``'s issue-19 figures: throughput against a commit, the pty replay's
process time. Speed is never asserted here: only that the figures are made and judged."""

from __future__ import annotations

import argparse
import subprocess
from pathlib import Path

import pytest

from firmware_host import cli
from firmware_host.devtools import bench


def test_against_rows_judge_the_ratio_and_the_process_time() -> None:
    res = {"against": {"commit": "abc1234", "ref_eps": [9000, 10000], "new_eps": [14000, 16000],
                       "ratio": 1.6},
           "startup": {"runs": 5, "new_worst_s": 0.25, "commit": "abc1234",
                       "ref_worst_s": 0.33}}
    rows = {r["figure"]: r for r in bench.against_rows(res)}
    (ratio,) = [r for name, r in rows.items() if name.startswith("throughput")]
    (startup,) = [r for name, r in rows.items() if name.startswith("nmea-rtk")]
    assert ratio["value"] == 1.6 and ratio["ok"] is True and "16000 against 10000" in \
        next(n for n in rows if n.startswith("throughput"))
    assert startup["value"] == 0.25 and startup["ok"] is False and "0.330 s" in \
        next(n for n in rows if n.startswith("nmea-rtk"))
    # The default goal: no slower than the commit, within the noise (0.95).
    res["against"]["ratio"] = 0.97
    assert bench.against_rows(res)[0]["ok"] is True
    res["against"]["ratio"] = 0.9
    assert bench.against_rows(res)[0]["ok"] is False
    # A speed-up goal travels with the measurement (--ratio-goal 1.5: issue 19's).
    res["against"].update(ratio=1.2, goal=1.5)
    row = bench.against_rows(res)[0]
    assert row["ok"] is False and row["goal"] == ">= 1.5"
    assert bench.against_rows({"against": {"error": "no git"}, "startup": {"error": "x"}}) == []


def test_startup_figure_replays_the_corpus_log(corpus: Path) -> None:
    st = bench.bench_startup(corpus, rev=None, runs=1)
    assert st["new_worst_s"] > 0 and len(st["new_cpu_s"]) == 1 and "ref_worst_s" not in st


def test_startup_figure_without_the_corpus(tmp_path: Path) -> None:
    assert "error" in bench.bench_startup(tmp_path, rev=None, runs=1)


def test_export_tree_of_a_commit_and_of_a_directory(tmp_path: Path) -> None:
    if subprocess.run(["git", "-C", str(bench.TREE), "rev-parse", "HEAD"], capture_output=True,
                      check=False).returncode != 0:
        pytest.skip("not a git checkout")
    short = bench.export_tree("HEAD", tmp_path / "a")
    assert short and (tmp_path / "a" / "firmware_host" / "devtools" / "bench.py").is_file()
    assert bench.export_tree(str(tmp_path / "a"), tmp_path / "b") == str(tmp_path / "a")
    assert (tmp_path / "b" / "pyproject.toml").is_file()
    with pytest.raises(RuntimeError, match="cannot export"):
        bench.export_tree("no-such-revision-xyz", tmp_path / "c")


def test_a_figure_that_measured_nothing_exits_1_with_its_reason(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Issue E: ``--only startup`` with no corpus (as outside a checkout: nothing to replay)
    printed "(nothing measured)" and exited 0; now the reason is on stderr and the exit is 1."""
    assert cli.main(["bench", "--only", "startup", "--against", "none",
                     "--corpus", str(tmp_path)]) == 1
    got = capsys.readouterr()
    assert "(nothing measured)" in got.out and "fdi-bridge bench:" in got.err


@pytest.mark.parametrize(("argv", "long_s"), [
    ([], 86400.0),  # the default: a 24 h log
    (["--replay-duration", "30"], 4320.0),  # the short options: a short bench
    (["--replay-duration", "1"], 600.0),  # never under 10 min
    (["--replay-duration", "30", "--memory-duration", "7200"], 7200.0),
])
def test_the_memory_figure_s_long_log_follows_the_short_options(argv: list[str],
                                                                long_s: float) -> None:
    """Issue E: ``bench --duration 5 --replay-duration 30`` still replayed a 24 h log (7.6 min)."""
    parser = argparse.ArgumentParser()
    bench.add_arguments(parser)
    assert bench.memory_duration(parser.parse_args(argv)) == long_s
