"""The rover pipeline with Cai & Shao's strategies (three_zone, combined) beside grey.

Each strategy runs through the same replay contract on the same generated run; the per-axis
zones are recorded, an over-limit axis is replaced (fault), a deviation axis is only
down-weighted (no fault), and the output stays close to the truth on faulty epochs.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from firmware_host.cli import main
from firmware_host.devtools.rover_sim import RoverScenario, write_run
from firmware_host.devtools.score import read_jsonl, score_rover


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("run")
    write_run(RoverScenario(rate_hz=10.0, duration_s=300.0, seed=21), d)
    return d


@pytest.mark.parametrize(
    ("preset", "min_detection"),
    [("rover", 0.99), ("rover-paper", 0.95), ("rover-three-zone-paper", 0.9),
     ("rover-combined-paper", 0.9)],
)
def test_strategy_through_the_replay_contract(
    run_dir: Path, tmp_path: Path, preset: str, min_detection: float
) -> None:
    out = tmp_path / preset
    assert main(["replay", "--config", preset, str(run_dir / "rover.nmea"), "--out", str(out),
                 "--no-pty"]) == 0
    epochs = read_jsonl(out / "epochs.jsonl")
    summary = json.loads((out / "summary.json").read_text())
    strategy = summary["detector"]["strategy"]
    s = score_rover(epochs, read_jsonl(run_dir / "truth.jsonl"))
    assert s.detection_rate >= min_detection, (preset, s.detected_min, s.faulty_min)
    assert s.false_alarm_rate <= 0.005
    assert s.out_rms_faulty_m < 1.0, s.out_rms_faulty_m  # the jumps are 1-7 m
    if strategy == "grey":
        assert all(e["zones"] is None for e in epochs)
        return
    zoned = [e for e in epochs if e["zones"] is not None]
    assert len(zoned) > 0.9 * len(epochs)
    for e in zoned:
        over = 2 in e["zones"]
        if e["action"] in ("accept", "replace"):
            assert e["fault"] == over
        if over and e["action"] == "replace":
            assert e["lat"] != e["raw_lat"] or e["lon"] != e["raw_lon"]
        if not over and e["action"] == "accept":
            assert e["lat"] == e["raw_lat"] and e["lon"] == e["raw_lon"]
    assert any(1 in e["zones"] and not e["fault"] for e in zoned), "no deviation zone seen"
