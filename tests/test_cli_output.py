"""What the commands print for people (issue 17): aligned tables with units and rounding,
``--json`` for machines, the damaged-input and wrong-port cases on the console, ``bench``'s
goals with a verdict, progress bars on a terminal only (a real pty), ^C keeping a partial
``summary.json``."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from firmware_host import cli
from firmware_host.commands import doctor
from firmware_host.commands.replay import run_replay
from firmware_host.commands.tables import fields, fmt, summary_rows, table
from firmware_host.devtools import bench
from firmware_host.devtools.rover_sim import RoverScenario, write_run
from firmware_host.runtime.config import load_config
from tests.ptyrun import cli_under_pty

ROOT = Path(__file__).resolve().parents[1]
ENV = dict(os.environ, PYTHONPATH=str(ROOT))


def _cli(*argv: str, cwd: Path, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "firmware_host.cli", *argv], cwd=cwd,
                          capture_output=True, text=True, timeout=timeout, env=ENV,
                          stdin=subprocess.DEVNULL)


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("out") / "run"
    write_run(RoverScenario(rate_hz=10.0, duration_s=30.0, seed=2), d)
    return d


# --------------------------------------------------------------------------- tables


@pytest.mark.parametrize(("value", "text"), [
    (0.6202000000000112, "0.62"), (1714.7, "1715"), (0.0465, "0.0465"), (12.345, "12.3"),
    (0.0, "0"), (3, "3"), (None, "-"), (float("nan"), "-"), (100.0, "100"), (True, "yes"),
    ({"accept": 5915, "replace": 12}, "accept 5915, replace 12"), ({}, "-"),
])
def test_fmt_rounds_for_people(value: Any, text: str) -> None:
    assert fmt(value) == text


def test_table_aligns_columns_numbers_right() -> None:
    out = table(["name", "p99", "n"], [["grey", 0.0465, 3], ["three_zone", 12.5, 100]])
    lines = out.splitlines()
    assert lines[0].split() == ["name", "p99", "n"]
    assert len({len(line) for line in lines}) == 1  # every line as wide
    assert lines[1].endswith("  3") and lines[2].endswith("100")
    assert lines[1].index("0.0465") + len("0.0465") == lines[2].index("12.5") + len("12.5")


def test_fields_puts_units_after_values() -> None:
    out = fields([("epochs", 200, ""), ("p99", 0.1483, "ms/epoch")])
    assert out.splitlines() == ["epochs    200", "p99     0.148 ms/epoch"]


def test_summary_rows_take_the_unit_from_the_key() -> None:
    assert summary_rows({"first_fault_t": 70.6, "max_abs_err_after_fault_deg": 0.6202000000000112,
                         "epochs": 651}) == [("first fault", 70.6, "s"),
                                             ("max abs err after fault", 0.6202000000000112,
                                              "deg"), ("epochs", 651, "")]


@pytest.mark.parametrize("kind", ["rover", "rov"])
def test_sim_prints_a_table_or_json(kind: str, tmp_path: Path) -> None:
    extra = ["--duration", "20"]
    text = _cli("sim", kind, *extra, "--out", str(tmp_path / "t"), cwd=tmp_path)
    js = _cli("sim", kind, *extra, "--out", str(tmp_path / "j"), "--json", cwd=tmp_path)
    assert text.returncode == 0 and js.returncode == 0, text.stderr + js.stderr
    doc = json.loads(js.stdout)
    first = text.stdout.splitlines()[0].split()
    assert first == ["epochs", str(doc["epochs"])]
    assert "{" not in text.stdout


# --------------------------------------------------------------------------- replay


def test_replay_prints_a_table_not_a_dict(run_dir: Path, tmp_path: Path) -> None:
    proc = _cli("replay", str(run_dir / "rover.nmea"), "--out", str(tmp_path / "o"), cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    out = proc.stdout
    assert "{" not in out and "'" not in out  # no Python dict print
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    epochs = next(ln for ln in out.splitlines() if ln.startswith("epochs "))
    assert epochs.split() == ["epochs", str(summary["epochs"]), "at", "10", "Hz"]
    line = next(ln for ln in out.splitlines() if ln.startswith("processing p99"))
    assert line.endswith("ms/epoch")
    assert f"accept {summary['actions']['accept']}" in out


def test_replay_json_is_the_summary(run_dir: Path, tmp_path: Path) -> None:
    proc = _cli("replay", str(run_dir / "rover.nmea"), "--out", str(tmp_path / "o"), "--json",
                cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    printed = json.loads(proc.stdout)
    assert printed == json.loads((tmp_path / "o" / "summary.json").read_text())


def test_replay_epochs_contract_unchanged_by_the_cli(run_dir: Path, tmp_path: Path) -> None:
    """The CLI's new checks and printing leave epochs.jsonl as run_replay writes it."""
    run_replay(load_config("rover"), run_dir / "rover.nmea", tmp_path / "lib")
    proc = _cli("replay", "--config", "rover", str(run_dir / "rover.nmea"), "--out",
                str(tmp_path / "cli"), cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "cli" / "epochs.jsonl").read_bytes() == (
        tmp_path / "lib" / "epochs.jsonl").read_bytes()


def _sentence(body: str) -> bytes:
    ck = 0
    for ch in body.encode():
        ck ^= ch
    return f"${body}*{ck:02X}\r\n".encode()


def test_nmea_without_a_position_is_said_not_an_error(tmp_path: Path) -> None:
    """A heading-only log (an autopilot's HDM) is NMEA: exit 0, with a warning, 0 epochs."""
    log = tmp_path / "heading.nmea"
    log.write_bytes(b"".join(_sentence(f"APHDM,{h:.1f},M") for h in range(0, 50, 5)))
    proc = _cli("replay", str(log), "--out", str(tmp_path / "o"), cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "no position sentences (GGA, RMC, GLL), only APHDM 10" in proc.stderr
    assert "no NMEA sentences found" not in proc.stderr


def test_damaged_capture_is_reported_on_the_console(run_dir: Path, tmp_path: Path) -> None:
    data = bytearray((run_dir / "rover.cap").read_bytes())
    data[len(data) // 2] ^= 0x10  # one flipped bit in the middle
    bad = tmp_path / "bad.cap"
    bad.write_bytes(bytes(data))
    proc = _cli("replay", str(bad), "--out", str(tmp_path / "o"), cwd=tmp_path)
    assert "Traceback" not in proc.stderr
    notes = json.loads((tmp_path / "o" / "summary.json").read_text())["input"]["notes"]
    assert notes, "the capture reader saw no damage: the test flipped nothing it checks"
    for note in notes:
        assert f"warning: {bad}: {note}" in proc.stderr


def test_replay_interrupted_keeps_a_partial_summary(run_dir: Path, tmp_path: Path) -> None:
    """^C during a paced replay: summary.json written, marked partial, exit 130."""
    out = tmp_path / "o"
    proc = subprocess.Popen([sys.executable, "-m", "firmware_host.cli", "replay",
                             str(run_dir / "rover.nmea"), "--out", str(out), "--speed", "1"],
                            cwd=tmp_path, env=ENV, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while not (out / "epochs.jsonl").exists() or not (out / "epochs.jsonl").stat().st_size:
        assert time.monotonic() < deadline and proc.poll() is None
        time.sleep(0.1)
    proc.send_signal(signal.SIGINT)
    _stdout, stderr = proc.communicate(timeout=60)
    assert "Traceback" not in stderr
    assert proc.returncode == 130, stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["partial"] is True
    assert 0 < summary["epochs"] < 300  # 30 s at 10 Hz, interrupted early
    assert "partial" in stderr


# --------------------------------------------------------------------------- record


def test_record_waits_for_a_missing_port_only_with_wait(tmp_path: Path) -> None:
    missing = str(tmp_path / "ttyUSB9")
    bad = _cli("record", missing, "--out", str(tmp_path / "a.cap"), "--duration", "0.5",
               cwd=tmp_path)
    assert bad.returncode == 1 and "cannot open the port" in bad.stderr
    assert not (tmp_path / "a.cap").exists()  # no empty capture left behind
    ok = _cli("record", missing, "--out", str(tmp_path / "b.cap"), "--duration", "0.5",
              "--wait", cwd=tmp_path)
    assert ok.returncode == 0, ok.stderr
    assert (tmp_path / "b.cap").exists()


# --------------------------------------------------------------------------- bench


def _bench_result(e2e_p99: float, overruns: int) -> dict[str, Any]:
    strat = {"epoch_ms": {"p50": 0.02, "p99": 0.05, "max": 0.3}, "throughput_eps_no_pty": 25000.0}
    return {
        "machine": {"cpu": "x", "cores": 2, "python": "3.11", "system": "Linux"},
        "rover": {"strategies": {"grey": strat}, "throughput_eps_no_pty_jsonl": 9000.0,
                  "throughput_eps_pty": 5000.0, "throughput_eps_pty_jsonl": 4000.0},
        "rov_step": {"p50_ms": 0.01, "p99_ms": 0.03, "max_ms": 0.1},
        "insgnss_step": {"p50_ms": 0.007, "p99_ms": 0.03},
        "end_to_end": {"latency_ms": {"p50": 0.8, "p99": e2e_p99, "max": 4.0}},
        "loop": {"10hz": {"steps": 600, "overruns": overruns,
                          "jitter_ms": {"p50": 0.1, "p99": 0.6202000000000112, "max": 1.0}}},
        "mavlink_forwarding": {},
        "seconds": 1.0,
    }


def test_bench_prints_each_figure_against_its_goal() -> None:
    good = bench.figures(_bench_result(1.5, 0))
    assert all(f["ok"] is not False for f in good)
    bad = {f["figure"]: f["ok"] for f in bench.figures(_bench_result(3.84, 2))}
    assert bad["GGA into pty -> GPS_INPUT on UDP"] is False
    assert bad["loop 10hz jitter (600 steps, 2 overruns)"] is False  # overruns miss the goal
    assert bad["ROV step"] is None  # no goal, no verdict
    text = bench.table(_bench_result(3.84, 0))
    e2e = next(ln for ln in text.splitlines() if ln.startswith("GGA into pty"))
    assert e2e.split()[-1] == "MISS" and "3.84" in e2e and "p99 < 2" in e2e
    loop = next(ln for ln in text.splitlines() if ln.startswith("loop 10hz"))
    assert loop.split()[-1] == "pass" and "0.62 " in loop  # rounded, not 0.6202000000000112
    header = text.splitlines()[0].split()
    assert header == ["figure", "p50", "p99", "max", "unit", "goal", "result"]


@pytest.mark.parametrize(("strict", "status"), [(False, 0), (True, 1)])
def test_bench_strict_fails_on_a_miss(monkeypatch: pytest.MonkeyPatch, tmp_path: Path,
                                      capsys: pytest.CaptureFixture[str], strict: bool,
                                      status: int) -> None:
    def fake(*args: Any, step: Any = None, into: dict[str, Any] | None = None,
             **kw: Any) -> dict[str, Any]:  # the measuring is not under test here
        assert into is not None
        into.update(_bench_result(3.84, 0))
        return into

    monkeypatch.setattr(bench, "run_bench", fake)
    argv = ["bench", "--json", str(tmp_path / "b.json"), *(["--strict"] if strict else [])]
    args = cli.build_parser(argv).parse_args(argv)
    assert bench.run(args) == status
    assert "1 of 4 goals missed" in capsys.readouterr().out
    doc = json.loads((tmp_path / "b.json").read_text())
    assert [f["figure"] for f in doc["figures"] if f["ok"] is False] == [
        "GGA into pty -> GPS_INPUT on UDP"]


# --------------------------------------------------------------------------- doctor


def test_doctor_lists_ports_under_column_labels(capsys: pytest.CaptureFixture[str]) -> None:
    rep = doctor.Report(ports=[{"device": "/dev/ttyUSB0", "description": "CP2102 USB to UART",
                                "hwid": "USB VID:PID=10C4:EA60"},
                               {"device": "/dev/ttyS0", "description": "n/a", "hwid": "n/a"}])
    lines = "\n".join(rep.lines()).splitlines()
    assert lines[1].split() == ["DEVICE", "DESCRIPTION", "HWID"]
    assert lines[2].index("CP2102") == lines[1].index("DESCRIPTION")
    assert lines[3].split() == ["/dev/ttyS0", "-", "-"]
    assert rep.as_dict()["ports"][0]["device"] == "/dev/ttyUSB0"


def test_doctor_json(tmp_path: Path) -> None:
    proc = _cli("doctor", "--config", "rover", "--json", "--record", str(tmp_path / "r"),
                cwd=tmp_path)
    doc = json.loads(proc.stdout)
    assert set(doc) == {"ports", "ok", "warnings", "problems"}
    assert proc.returncode == (1 if doc["problems"] else 0)


# --------------------------------------------------------------------------- progress


def _under_pty(argv: list[str], cwd: Path, timeout: float = 120) -> tuple[int, str]:
    return cli_under_pty(argv, cwd, timeout, env=ENV)


def test_progress_bar_on_a_terminal_not_in_a_pipe(tmp_path: Path) -> None:
    """``eval --suite`` draws its bar on a terminal, not in a pipe; ``-q`` turns it off on a
    terminal too. Every command's bar is one :class:`Progress`, which decides by the
    terminal and the log level alone: the pipe and ``-q`` are checked on ``demo`` (a few
    seconds), not on two more runs of the whole suite (``test_console_tables.py::
    test_demo_progress_bar_on_a_terminal_only`` checks ``demo`` on a terminal too)."""
    argv = ["eval", "--suite", "--quick", "--no-plots", "--duration", "30"]
    status, tty = _under_pty(argv, tmp_path)
    assert status == 0, tty
    assert "eval --suite" in tty and "case" in tty and "\r" in tty  # a refreshing tqdm bar
    demo = ["demo", "--duration", "20", "--presets", "rover", "--out"]
    piped = _cli(*demo, "p", cwd=tmp_path)
    assert piped.returncode == 0, piped.stderr
    assert "demo:" not in piped.stderr and "\r" not in piped.stderr
    quiet, tty_q = _under_pty([*demo, "q", "-q"], tmp_path)
    assert quiet == 0 and "Rover demo:" in tty_q
    assert not re.search(r"demo: +\d+%\|", tty_q)  # no bar (its text is "demo:  50%|...")
