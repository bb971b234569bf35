"""Every gpsd capture in the shared corpus replays through a real pty without a crash.

The replay contract (``fdi-bridge replay --config CONFIG CAPTURE --out DIR``) is exercised
through the CLI entry point, the unmodified driver reading the slave side of a real pty.
"""

from __future__ import annotations

import itertools
import json
from pathlib import Path
from typing import Any

import pytest

from firmware_host.cli import main

CONTRACT = {"utc", "raw_lat", "raw_lon", "lat", "lon", "fault", "action"}
ACTIONS = {"accept", "replace", "alarm", "no_fix"}
MALFORMED = ("triton400", "holux-gm-210", "gp-320fw-2019-04-07-coldboot", "isync")


def replay(
    log: Path, out: Path, config: str = "rover"
) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    rc = main(["replay", "--config", config, str(log), "--out", str(out)])
    assert rc == 0
    epochs = [json.loads(line) for line in (out / "epochs.jsonl").read_text().splitlines()]
    summary = json.loads((out / "summary.json").read_text())
    return epochs, summary




def test_every_gpsd_log_replays(corpus: Path, tmp_path: Path) -> None:
    logs = sorted((corpus / "gpsd").glob("*.log"))
    assert len(logs) >= 17
    for log in logs:
        epochs, summary = replay(log, tmp_path / log.stem)
        assert summary["epochs"] == len(epochs)
        for e in epochs:
            assert e.keys() >= CONTRACT
            assert e["action"] in ACTIONS
            # Nothing invalid is passed on: an output position exists only for accept/replace.
            assert (e["lat"] is not None) == (e["action"] in ("accept", "replace"))
        assert {"p50", "p99"} <= summary["processing_ms"].keys()
        assert "rejected" in summary["input"]


@pytest.mark.parametrize("name", MALFORMED)
def test_malformed_logs_report_bad_lines_by_reason(corpus: Path, tmp_path: Path, name: str) -> None:
    _, summary = replay(corpus / "gpsd" / f"{name}.log", tmp_path)
    rejected = summary["input"]["rejected"]
    assert sum(rejected.values()) >= 1, rejected
    assert set(rejected) <= {"garbage", "too_long", "truncated", "bad_chars", "no_checksum",
                             "bad_checksum", "parse_error", "bad_field", "short"}


def test_gp320_cold_boot_counts(corpus: Path, tmp_path: Path) -> None:
    """The log's header says 38 missing/broken checksums; every one is rejected by reason."""
    _, summary = replay(corpus / "gpsd" / "gp-320fw-2019-04-07-coldboot.log", tmp_path)
    r = summary["input"]["rejected"]
    assert r.get("bad_checksum", 0) + r.get("no_checksum", 0) >= 38, r


def test_nmea_rtk_real_spike_is_flagged(corpus: Path, tmp_path: Path) -> None:
    """The real 1.4 m out-and-back spike at 13:28:19.80 (10 Hz Trimble, DGPS)."""
    epochs, _ = replay(corpus / "gpsd" / "nmea-rtk.log", tmp_path)
    spike_t = 13 * 3600 + 28 * 60 + 19.8
    by_t = {round(e["utc"], 2): e for e in epochs}
    spike = by_t[round(spike_t, 2)]
    assert spike["fault"] and spike["action"] == "replace"
    assert spike["grey_res_h"] > 1.0
    # The epochs around it are clean and passed on unchanged.
    for dt in (-0.2, -0.1, 0.1, 0.2):
        e = by_t[round(spike_t + dt, 2)]
        assert not e["fault"] and e["action"] == "accept"
        assert e["lat"] == e["raw_lat"] and e["lon"] == e["raw_lon"]
    # The replacement is near the neighbours (the spike was out-and-back).
    before, after = by_t[round(spike_t - 0.1, 2)], by_t[round(spike_t + 0.1, 2)]
    assert abs(spike["lat"] - 0.5 * (before["lat"] + after["lat"])) < 2e-6  # ~0.2 m
    assert sum(e["fault"] for e in epochs) == 1


def test_quectel_wild_fixes_are_never_passed_on_as_good(corpus: Path, tmp_path: Path) -> None:
    """A stationary phone with 3-5 satellites whose fixes wander 2-200 m a second."""
    epochs, summary = replay(corpus / "gpsd" / "quectel-eg25-g.log", tmp_path)
    valid_in = [e for e in epochs if e["raw_lat"] is not None]
    assert len(valid_in) >= 20
    assert summary["alarms"] >= 1
    passed_good = [e for e in valid_in if e["action"] == "accept"]
    assert passed_good == [], [e["utc"] for e in passed_good]
    assert all(e["fault"] or e["action"] == "alarm" for e in valid_in)


def test_time_going_backwards_is_handled(corpus: Path, tmp_path: Path) -> None:
    """humminbird-M37: the receiver's time jumps back 194124 -> 194114 while the boat moves."""
    epochs, _ = replay(corpus / "gpsd" / "humminbird-M37.log", tmp_path)
    utcs = [e["utc"] for e in epochs]
    assert any(b < a for a, b in itertools.pairwise(utcs))
    assert any(e["reason"] == "time_reset" for e in epochs)
    assert not any(e["fault"] for e in epochs)
