"""One output style for humans (issue 17): ``soak``, ``mavlink`` (the router alone) and
``sim insgnss`` print aligned tables by default and JSON with ``--json``; the INS/GNSS plots
know the receiver's fault periods."""

from __future__ import annotations

import json
import re
import signal
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from firmware_host.cli import main
from firmware_host.devtools import eval as eval_mod
from firmware_host.devtools import insgnss_report
from firmware_host.devtools.insgnss_sim import fault_spans
from tests.ptyrun import StderrOnPty

ROOT = Path(__file__).resolve().parents[1]


def test_soak_prints_tables_and_json_on_request(capsys: pytest.CaptureFixture[str],
                                                tmp_path: Path) -> None:
    assert main(["-q", "soak", "--minutes", "2", "--out", str(tmp_path / "s.json")]) == 0
    text = capsys.readouterr().out
    assert text.startswith("soak: 2 min simulated in ") and ", seed 1: ok" in text
    assert "{" not in text and len(text.splitlines()) < 45
    header = next(x for x in text.splitlines() if x.split() == ["rover", "rov", "unit"])
    assert header.index("rover") < header.index("rov  ")
    saved = json.loads((tmp_path / "s.json").read_text())
    assert f"epochs / steps         {saved['rover']['epochs']}" in text
    assert all(f"{name}  " in text for name in saved["checks"])
    assert main(["-q", "soak", "--minutes", "2", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["ok"] is True and doc["rover"]["epochs"] == saved["rover"]["epochs"]


def test_router_alone_says_what_it_routes_and_ends_with_a_table(
        capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["mavlink", "--autopilot", "udpin:127.0.0.1:0", "--gcs",
                 "udpout:127.0.0.1:9", "--seconds", "0.3"]) == 0
    cap = capsys.readouterr()
    assert "routing udpin:127.0.0.1:0 <-> udpout:127.0.0.1:9, for 0.3 s" in cap.err
    lines = cap.out.splitlines()
    assert lines[0].split()[:3] == ["stopped", "by", "duration"]
    header = next(x for x in lines if x.startswith("link"))
    assert header.split()[:5] == ["link", "rx", "packets", "tx", "packets"]
    assert any(x.startswith("autopilot") for x in lines) and "{" not in cap.out


def test_sim_insgnss_prints_its_result_table(capsys: pytest.CaptureFixture[str],
                                            tmp_path: Path) -> None:
    assert main(["sim", "insgnss", "--out", str(tmp_path), "--no-plots"]) == 0
    out = capsys.readouterr().out
    summary = json.loads((tmp_path / "summary.json").read_text())
    lines = out.splitlines()
    assert lines[0] == (f"paper-random, seed 1: {summary['epochs']} GNSS epochs, "
                        f"{summary['fault_epochs']} with a fault")
    header = next(x for x in lines if x.startswith("method"))
    rows = {x.split()[0]: x.split() for x in lines[lines.index(header) + 1:]
            if x and not x.startswith("wrote")}
    assert set(rows) == set(summary["methods"])
    for name, m in summary["methods"].items():
        assert float(rows[name][4]) == pytest.approx(m["position_rms_3d_m"], rel=0.01)
        assert int(rows[name][-2]) == m["fault_epochs_flagged"]
    assert lines[-1].startswith("wrote ") and "summary.json" in lines[-1]


def test_fault_spans_cover_consecutive_faulty_epochs() -> None:
    t = np.arange(10.0)
    faulty = np.array([0, 1, 1, 0, 0, 1, 0, 0, 1, 1], dtype=bool)
    assert fault_spans(t, faulty) == [(0.5, 2.5), (4.5, 5.5), (7.5, 9.5)]
    assert fault_spans(t, np.zeros(10, dtype=bool)) == []


# ---------------------------------------------------------------- ^C writes what it has


def test_eval_suite_interrupted_writes_what_it_has(monkeypatch: pytest.MonkeyPatch,
                                                   tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    """^C while the ROV part runs: the rover tables done so far, in eval.json/eval.md marked
    partial, on stdout too; exit 130."""
    def interrupted(**_: Any) -> Any:
        raise KeyboardInterrupt

    monkeypatch.setattr(eval_mod, "rov_suite", interrupted)
    rc = main(["eval", "--suite", "--quick", "--no-plots", "--duration", "60",
               "--out", str(tmp_path)])
    cap = capsys.readouterr()
    assert rc == 130 and "interrupted: partial results written" in cap.err
    doc = json.loads((tmp_path / "eval.json").read_text())
    assert doc["partial"] is True and "rov" not in doc and "insgnss" not in doc
    n = len(list(eval_mod.rover_cases(True)))
    assert len(doc["rover"]) == n  # every rover case was done before the ROV part
    md = (tmp_path / "eval.md").read_text()
    assert md.startswith(f"**Partial (interrupted):** only what was done before ^C ({n} rover")
    # the console: the same report as aligned tables (issue 17), the partial mark first
    assert cap.out.startswith(f"Partial (interrupted): only what was done before ^C ({n} rover")
    assert "|---" not in cap.out


def test_insgnss_report_interrupted_keeps_the_runs_done(monkeypatch: pytest.MonkeyPatch,
                                                        tmp_path: Path) -> None:
    calls = {"n": 0}
    real = insgnss_report.run_scenario

    def third_interrupts(*a: Any, **kw: Any) -> Any:
        calls["n"] += 1
        if calls["n"] == 3:
            raise KeyboardInterrupt
        return real(*a, **kw)

    monkeypatch.setattr(insgnss_report, "run_scenario", third_interrupts)
    out = tmp_path / "report.md"
    rc = main(["sim", "insgnss-report", "--seeds", "1,2,3", "--scenario", "paper-single",
               "--out", str(out)])
    text = out.read_text()
    assert rc == 130
    assert text.startswith(f"{insgnss_report.PARTIAL} only the runs done before ^C")
    rows = [x for x in text.splitlines()
            if re.match(r"\| insgnss-paper \| paper-single \| \d \|", x)]
    assert len(rows) == 2  # seeds 1 and 2 of the 3-D RMS table; the third was interrupted


def test_insgnss_report_sigint_as_a_user_sends_it(tmp_path: Path) -> None:
    """A real SIGINT to the command: exit 130, the report file written and marked partial."""
    out = tmp_path / "report.md"
    cmd = StderrOnPty(["sim", "insgnss-report", "--seeds", "1,2,3,4,5", "--out", str(out)],
                      cwd=tmp_path)
    # The progress bar on the terminal counts a finished run (the whole report: 40 runs).
    cmd.wait_for(r"insgnss-report:.*\| *[1-9]\d*/40 ", 300.0, "the first run done")
    assert cmd.proc.poll() is None, "the report finished before the signal"
    cmd.proc.send_signal(signal.SIGINT)
    rc, stdout, stderr = cmd.finish(timeout_s=120.0)
    assert rc == 130, stderr
    assert "Traceback" not in stderr and "partial report written" in stderr
    text = out.read_text()
    assert text.startswith(insgnss_report.PARTIAL)
    # the console: the same report as aligned tables (issue 17)
    assert stdout.startswith("Partial (interrupted):") and "|---" not in stdout
