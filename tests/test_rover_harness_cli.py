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
