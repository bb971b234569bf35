"""``bench`` interrupted (issue 17: ^C on a long job writes what it has): the figures measured
before ^C are written to the --json file marked partial, exit 130, one line on stderr."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from firmware_host import cli
from firmware_host.devtools import bench


def test_bench_interrupted_writes_the_figures_so_far(monkeypatch: pytest.MonkeyPatch,
                                                    tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    def measured_then_interrupted(*args: Any, step: Any = None,
                                  into: dict[str, Any] | None = None, **kw: Any) -> None:
        assert into is not None  # the rover part measured, then ^C (the measuring not tested)
        strat = {"epoch_ms": {"p50": 0.02, "p99": 0.05, "max": 0.3},
                 "throughput_eps_no_pty": 25000.0}
        into["rover"] = {"strategies": {"grey": strat}, "throughput_eps_no_pty_jsonl": 9000.0,
                         "throughput_eps_pty": 5000.0, "throughput_eps_pty_jsonl": 4000.0}
        raise KeyboardInterrupt

    monkeypatch.setattr(bench, "run_bench", measured_then_interrupted)
    out = tmp_path / "b.json"
    assert cli.main(["bench", "--json", str(out)]) == 130
    cap = capsys.readouterr()
    assert "Traceback" not in cap.err and "interrupted" in cap.err and "(partial)" in cap.err
    doc = json.loads(out.read_text(encoding="utf-8"))
    assert doc["partial"] is True and "end_to_end" not in doc
    names = [f["figure"] for f in doc["figures"]]
    assert "rover per-epoch, grey" in names
