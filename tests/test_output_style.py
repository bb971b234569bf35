"""One output style for humans (issue 17): ``soak``, ``mavlink`` (the router alone) and
``sim insgnss`` print aligned tables by default and JSON with ``--json``; the INS/GNSS plots
know the receiver's fault periods."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from firmware_host.cli import main
from firmware_host.devtools.insgnss_sim import fault_spans


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
