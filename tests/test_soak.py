"""A short soak: rover (10 Hz) and ROV (5 Hz) together for a few simulated minutes, with GPS
and compass faults, line noise and port drops, on a FakeClock (`fdi-bridge soak` runs an hour)."""

from __future__ import annotations

from pathlib import Path

from firmware_host.devtools.soak import run_soak


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
