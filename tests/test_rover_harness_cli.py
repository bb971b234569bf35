"""``sim rover-harness`` on the console (issue 17): aligned tables, a progress bar, and ^C
reports the runs measured so far (partial, exit 130)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from firmware_host import cli
from firmware_host.devtools import rover_harness


def test_rover_harness_prints_aligned_tables(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["sim", "rover-harness", "--seeds", "1", "--models", "gm", "--rates", "1",
                     "--duration", "300"]) == 0
    out = capsys.readouterr().out
    assert "|" not in out and "---" not in out
    lines = out.splitlines()
    assert lines[0].split()[:2] == ["model", "Hz"] and lines[1].split()[:2] == ["gm", "1"]
    assert "1 runs in" in out


def test_rover_harness_interrupted_reports_what_ran(monkeypatch: pytest.MonkeyPatch,
                                                     tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    real = rover_harness.replay
    calls = [0]

    def replay_then_interrupt(*args: Any, **kw: Any) -> Any:
        calls[0] += 1
        if calls[0] == 2:
            raise KeyboardInterrupt
        return real(*args, **kw)

    monkeypatch.setattr(rover_harness, "replay", replay_then_interrupt)
    out = tmp_path / "h.json"
    assert cli.main(["sim", "rover-harness", "--seeds", "1,2", "--models", "gm", "--rates", "1",
                     "--duration", "300", "--json", str(out)]) == 130
    cap = capsys.readouterr()
    assert "Traceback" not in cap.err and "interrupted after 1 runs (partial)" in cap.err
    doc = json.loads(out.read_text(encoding="utf-8"))
    assert doc["partial"] is True and [r["seed"] for r in doc["runs"]] == [1]
    assert doc["rows"][0]["seeds"] == [1]


def test_rover_harness_takes_a_seed_range(monkeypatch: pytest.MonkeyPatch,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    seen: list[tuple[str, int, float]] = []

    def record(cfg: Any, *, models: Any, seeds: Any, rates: Any, duration_s: float,
               out: list[Any], step: Any, offline_calibration: bool) -> None:
        seen.extend((m, s, r) for m in models for s in seeds for r in rates)

    monkeypatch.setattr(rover_harness, "run_matrix", record)
    assert cli.main(["sim", "rover-harness", "--seeds", "801-803,9", "--models", "gm,coarse",
                     "--rates", "1,10", "--duration", "60"]) == 0
    assert sorted({s for _, s, _ in seen}) == [9, 801, 802, 803]
    assert {m for m, _, _ in seen} == {"gm", "coarse"} and {r for _, _, r in seen} == {1.0, 10.0}


@pytest.mark.parametrize("flag, value, found", [
    ("--seeds", "801..805", "801..805"),
    ("--seeds", "5-1", "5-1"),
    ("--models", "gm,rtk", "gm,rtk"),
    ("--rates", "1,0", "0"),
])
def test_rover_harness_bad_lists_are_usage_errors(flag: str, value: str, found: str,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        cli.main(["sim", "rover-harness", flag, value])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert flag in err and found in err and "Traceback" not in err and "internal" not in err
