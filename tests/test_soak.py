"""A short soak: rover (10 Hz) and ROV (5 Hz) together for a few simulated minutes, with GPS
and compass faults, line noise and port drops, on a FakeClock (`fdi-bridge soak` runs an hour)."""

from __future__ import annotations

import json
import signal
from pathlib import Path

from firmware_host.devtools.soak import run_soak
from tests.ptyrun import StderrOnPty

ROOT = Path(__file__).resolve().parents[1]


def test_short_soak_counters_consistent(tmp_path: Path) -> None:
    r = run_soak(4.0, seed=3, record_dir=tmp_path, gps_drops=2, rov_drops=2)
    assert all(r["checks"].values()), r["checks"]
    rover, rov = r["rover"], r["rov"]
    assert rover["overruns"] == 0 and rov["overruns"] == 0
    # The drops happened and were survived: one loss and one return per unplug.
    assert rover["port"]["losses"] == 2 and rover["port"]["reopens"] == 2
    assert rov["port"]["losses"] == 2 and rov["port"]["reopens"] == 2
    assert rover["failsafe"]["silences"] >= 1 and rover["failsafe"]["no_fix_sent"] >= 1
    assert rov["neutral_episodes"] >= 1
    # Noise reached the framers and was counted, not passed on.
    assert rover["input"]["rejected_total"] > 0 and sum(rov["rejects"].values()) > 0
    # Epochs: 10 Hz for 240 s minus what was unplugged (and a few noisy ones).
    unplugged_s = sum(b - a for a, b in rover["unplugged"])
    assert rover["epochs"] >= 10 * (240 - unplugged_s) - 30
    assert rov["steps"] == 1200
    assert r["recorder"]["files_opened"] >= 1 and r["recorder"]["write_errors"] == 0
    assert r["memory"]["growth_mb"] < 10.0
    assert r["ok"]


def test_a_stopped_soak_reports_what_ran_as_partial(tmp_path: Path) -> None:
    calls = [0]

    def stop() -> bool:  # as a ^C between two steps, after 120 s simulated
        calls[0] += 1
        return calls[0] > 1200

    r = run_soak(10.0, seed=4, record_dir=tmp_path, gps_drops=1, rov_drops=1, stop=stop)
    assert r["partial"] is True and r["ok"] is False
    assert r["simulated_s"] == 120.0
    assert all(r["checks"].values()), r["checks"]  # the byte accounting holds for what ran
    assert 1100 <= r["rover"]["epochs"] <= 1200 and r["rov"]["steps"] == 600


def test_soak_interrupted_by_sigint_writes_partial_figures(tmp_path: Path) -> None:
    out = tmp_path / "soak.json"
    cmd = StderrOnPty(["soak", "--minutes", "600", "--out", str(out)], cwd=ROOT)
    # The progress bar on the terminal counts simulated minutes: well into the run.
    cmd.wait_for(r"soak:.*\| *[1-9]\d*/600 ", 300.0, "the first simulated minutes")
    cmd.proc.send_signal(signal.SIGINT)
    returncode, stdout, stderr = cmd.finish(timeout_s=120.0)
    assert returncode == 130, stderr
    assert "Traceback" not in stderr and "interrupted" in stderr
    doc = json.loads(out.read_text(encoding="utf-8"))
    assert doc["partial"] is True and 0 < doc["simulated_s"] < 36000
    assert all(doc["checks"].values()), doc["checks"]
    assert "PARTIAL" in stdout
