"""Console output of the report commands (issue 17): aligned tables like the other commands'
(``firmware_host/commands/tables.py``), no Markdown on the console; Markdown only in the files
(``--out``), unchanged; ``--json`` unchanged.

A console table is checked for alignment: every line of it has the same cells (runs separated by
two or more spaces), and each column's cells all start (text) or all end (numbers) at the same
offset. The Markdown files are checked against their header and separator lines as they were
before the console tables (so a change in the files fails here), and hold the same cells as
the console."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from firmware_host.cli import main
from firmware_host.commands.tables import Table, plain, report_console, report_markdown
from firmware_host.devtools import eval as eval_mod
from firmware_host.devtools import insgnss_report
from firmware_host.devtools.bench import replay_memory_table
from firmware_host.devtools.rover_sim import RoverScenario, write_run
from tests.ptyrun import cli_under_pty

ROOT = Path(__file__).resolve().parent.parent
CELL = re.compile(r"\S+(?: \S+)*")  # a cell: words separated by single spaces
AFTER = re.compile(r"(wrote |figures: |- |\(install)")  # the commands' lines after a table

# The Markdown header and separator lines of the files, as written before this change.
EVAL_MD_HEAD = (
    "| scenario | method | detected / faulty | missed | events | false alarms / clean "
    "| delay ep (s) | out RMS clean / faulty / all (m) | out max faulty (m) "
    "| raw RMS clean / faulty (m) |")
FLEET_MD_HEAD = (
    "| point | logs | errors | epochs | faults | alarms | replaced | detected % "
    "| false alarms % | events | mean delay (s) | raw RMS (m) | out RMS (m) |")
INSGNSS_MD_HEAD = (
    "| preset | scenario | seed | none | downweight | replace | three_zone | fault_state "
    "| three_zone max horiz. (m) | fault_state max horiz. (m) |")
INSGNSS_MD_SEP = "|---|---|---|---:|---:|---:|---:|---:|---:|---:|"


def spans(line: str) -> list[tuple[int, int, str]]:
    return [(m.start(), m.end(), m.group()) for m in CELL.finditer(line)]


def assert_aligned(lines: list[str]) -> list[list[str]]:
    """``lines`` (a header and its rows) form one aligned table; its cells back."""
    assert len(lines) >= 2, lines
    rows = [spans(line) for line in lines]
    width = len(rows[0])
    assert width >= 2 and all(len(r) == width for r in rows), lines
    for k in range(width):
        starts = {r[k][0] for r in rows[1:]}
        ends = {r[k][1] for r in rows[1:]}
        assert len(starts) == 1 or len(ends) == 1, (k, lines)
        # the label over its column: flush with the column's left or right edge
        assert rows[0][k][0] in starts or rows[0][k][1] in ends, (k, lines)
    return [[c for _, _, c in r] for r in rows]


def console_tables(text: str, *first: str) -> list[list[list[str]]]:
    """Every table of ``text`` whose header's first labels are ``first`` (up to a blank
    line)."""
    lines = text.splitlines()
    out = []
    for i, line in enumerate(lines):
        if [c for _, _, c in spans(line)][:len(first)] == list(first) and line.startswith(
                first[0]):
            block = [line]
            for nxt in lines[i + 1:]:
                if not nxt.strip() or AFTER.match(nxt):
                    break
                block.append(nxt)
            out.append(assert_aligned(block))
    assert out, f"no table starting {first!r} in:\n{text}"
    return out


def no_markdown(text: str) -> None:
    assert "|---" not in text and "---|" not in text
    assert not any(line.startswith("| ") for line in text.splitlines())
    assert "**" not in text and not re.search(r"^#+ ", text, re.M)


def md_rows(text: str, head: str) -> list[list[str]]:
    """The cells of the Markdown table under ``head`` (the header row included)."""
    lines = text.splitlines()
    i = lines.index(head)
    rows = []
    for line in [lines[i], *lines[i + 2:]]:
        if not line.startswith("|"):
            break
        rows.append([plain(c.strip()) for c in line.strip("|").split("|")])
    return rows


# ---------------------------------------------------------------- the renderer


def test_table_markdown_and_console() -> None:
    tab = Table(["name", "value (m)", "note"], right=(1,))
    tab.add("a", "0.35", "**best**")
    tab.add("longer name", "12.1", "")
    tab.add("c", 3, "*x*")
    assert tab.markdown().splitlines() == [
        "| name | value (m) | note |",
        "|---|---:|---|",
        "| a | 0.35 | **best** |",
        "| longer name | 12.1 | |",
        "| c | 3 | *x* |",
    ]
    lines = tab.console().splitlines()
    assert lines == [
        "name         value (m)  note",
        "a                 0.35  best",
        "longer name       12.1",
        "c                    3  x",
    ]
    with pytest.raises(ValueError):
        tab.add("too", "few")


def test_text_column_stays_left_aligned_on_the_console() -> None:
    """A column right-aligned in the Markdown but holding text is left-aligned on the console."""
    tab = Table(["k", "span"], right=(1,))
    tab.add("a", "4.7 (4.7-4.7) / 58.4 = 0.08")
    tab.add("b", "46.3 (46.3-46.3) / 58.4 = 0.79")
    body = tab.console().splitlines()
    assert body[1].index("4.7") == body[2].index("46.3")


def test_report_blocks() -> None:
    tab = Table(["a", "b"])
    tab.add("x", "1")
    blocks = ["### Title with `code`", "", "**Partial:** text", tab]
    assert report_markdown(blocks) == "### Title with `code`\n\n**Partial:** text\n| a | b |\n" \
        "|---|---|\n| x | 1 |"
    assert report_console(blocks) == "Title with code\n\nPartial: text\na  b\nx  1"


# ---------------------------------------------------------------- the commands


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A generated rover run (capture, NMEA log, truth) and its replay."""
    root = tmp_path_factory.mktemp("run")
    write_run(RoverScenario(rate_hz=10.0, duration_s=60.0, seed=3), root / "sim")
    assert main(["replay", "--config", "rover", str(root / "sim" / "rover.nmea"),
                 "--out", str(root / "rep")]) == 0
    return root


def test_eval_run_console_json_and_files(run_dir: Path, tmp_path: Path,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    capsys.readouterr()
    args = ["eval", str(run_dir / "rep"), "--truth", str(run_dir / "sim" / "truth.jsonl"),
            "--input", str(run_dir / "sim" / "rover.nmea")]
    assert main([*args, "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    no_markdown(out)
    (table,) = console_tables(out, "scenario", "method")
    assert table[0][:3] == ["scenario", "method", "detected / faulty"]
    methods = [row[1] for row in table[1:]]
    assert methods[0] == "this run" and "ours:grey (default)" in methods
    md = (tmp_path / "eval.md").read_text(encoding="utf-8")
    assert md.splitlines()[1] == "|" + "---|" * 10
    assert md_rows(md, EVAL_MD_HEAD) == table  # the same cells in the file and on the console
    assert "**ours:grey (default)**" in md
    assert main([*args, "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc == json.loads((tmp_path / "eval.json").read_text(encoding="utf-8"))
    assert [m["name"] for m in doc["methods"]] == methods


def test_eval_suite_console_and_files(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                      capsys: pytest.CaptureFixture[str]) -> None:
    # A small ROV part: one fault on one plant (4 runs instead of 156).
    monkeypatch.setattr(eval_mod, "ROV_FAULTS", (("drift:30@70",),))
    monkeypatch.setattr(eval_mod, "ROV_PLANTS", (("nomoto", 0.5),))
    capsys.readouterr()
    assert main(["eval", "--suite", "--quick", "--no-plots", "--duration", "60",
                 "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    no_markdown(out)
    (rover,) = console_tables(out, "scenario", "method", "detected / faulty")
    (rov,) = console_tables(out, "plant")
    (ins,) = console_tables(out, "scenario", "method", "seeds")
    assert len(rov) == 1 + 4 and rov[0][1] == "compass noise (deg)"
    assert "Rover: every baseline beside each of our strategies (same data)" in out
    md = (tmp_path / "eval.md").read_text(encoding="utf-8")
    assert md.startswith("## Rover: every baseline beside each of our strategies")
    assert md_rows(md, EVAL_MD_HEAD) == rover
    doc = json.loads((tmp_path / "eval.json").read_text(encoding="utf-8"))
    assert doc["markdown"] + "\n" == md and "console" not in doc
    assert len(ins) == 1 + len(doc["insgnss"])
    # --json: the document without its Markdown (and without the console text)
    assert main(["eval", "--suite", "--quick", "--no-plots", "--duration", "60",
                 "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert set(printed) == set(doc) - {"markdown"}
    assert printed["rover"][0]["methods"] == doc["rover"][0]["methods"]


def test_fleet_console_and_files(run_dir: Path, tmp_path: Path,
                                 capsys: pytest.CaptureFixture[str]) -> None:
    capsys.readouterr()
    assert main(["fleet", str(run_dir / "sim"), "--workers", "1", "--sweep",
                 "rover.detector.gate_sigmas=4,6", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    no_markdown(out)
    assert out.startswith("Fleet evaluation: 1 logs, 2 point(s), serial")
    (pooled,) = console_tables(out, "point")
    assert [r[0] for r in pooled[1:]] == ["rover.detector.gate_sigmas=4",
                                          "rover.detector.gate_sigmas=6"]
    per_log = console_tables(out, "log")
    assert len(per_log) == 2 and all(len(t) == 2 for t in per_log)
    md = (tmp_path / "fleet.md").read_text(encoding="utf-8")
    assert md.startswith("# Fleet evaluation:") and "|" + "---|" * 13 in md
    assert md_rows(md, FLEET_MD_HEAD) == pooled
    doc = json.loads((tmp_path / "fleet.json").read_text(encoding="utf-8"))
    assert set(doc["points"]) == {r[0] for r in pooled[1:]}


def test_fleet_error_row_keeps_its_columns(tmp_path: Path) -> None:
    """A log that failed: empty cells in the file, its error as the note on the console."""
    from firmware_host.devtools.fleet import FleetResult, console, markdown

    row = {"point": "config", "log": "/x/bad.nmea", "kind": "nmea", "truth": False,
           "error": "FdiBridgeError: no NMEA sentences found"}
    result = FleetResult([row], ["config"], "serial", 0.0)
    md = markdown(result)
    assert "| /x/bad.nmea | nmea | | | | | | | | | **FdiBridgeError: no NMEA sentences " \
           "found** |" in md
    text = console(result)
    no_markdown(text)
    assert re.search(r"^/x/bad\.nmea\s+nmea\s+FdiBridgeError: no NMEA sentences found$",
                     text, re.M)


def test_insgnss_report_console_and_file(tmp_path: Path,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    out_md = tmp_path / "r.md"
    assert main(["sim", "insgnss-report", "--seeds", "2", "--scenario", "paper-single",
                 "--config", str(ROOT / "config" / "insgnss.toml"), "--out", str(out_md)]) == 0
    out = capsys.readouterr().out
    no_markdown(out)
    (rms,) = console_tables(out, "preset", "scenario", "seed")
    assert [r[:3] for r in rms[1:]] == [["insgnss", "paper-single", "2"]]
    console_tables(out, "preset", "scenario", "method")
    md = out_md.read_text(encoding="utf-8")
    assert md.startswith("### 3-D position RMS (m), every seed\n")
    assert md.splitlines()[3] == INSGNSS_MD_SEP
    assert md_rows(md, INSGNSS_MD_HEAD) == rms


def test_demos_print_aligned_tables(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    capsys.readouterr()
    assert main(["demo", "--duration", "20", "--out", str(tmp_path / "rover")]) == 0
    out = capsys.readouterr().out
    no_markdown(out)
    (table,) = console_tables(out, "preset")
    assert [r[0] for r in table[1:]] == ["rover", "rover-paper"]
    assert table[0][-1] == "p99 (ms/epoch)"
    assert main(["demo", "rov", "--out", str(tmp_path / "rov")]) == 0
    out = capsys.readouterr().out
    no_markdown(out)
    (table,) = console_tables(out, "fault tolerance")
    assert [r[0] for r in table[1:]] == ["off", "on"]
    assert table[2][2] == "70.6"  # confirmed 0.6 s after the 30 deg drift (the paper's Fig. 3)


def test_fuzz_checksums_table(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["fuzz", "--checksums", "--inputs", "500", "--seed", "1"]) == 0
    out = capsys.readouterr().out
    no_markdown(out)
    (table,) = console_tables(out, "checksum")
    assert {r[0] for r in table[1:]} >= {"xor8", "crc32"}


def test_no_console_markdown_left_in_the_commands() -> None:
    """No command module prints a Markdown table row by hand (they build a Table)."""
    offenders = []
    for path in [*(ROOT / "firmware_host" / "commands").glob("*.py"),
                 *(ROOT / "firmware_host" / "devtools").glob("*.py")]:
        # The harnesses' Markdown tables are for docs/ (their consoles print Table.console());
        # so are the generated reference pages (docs/reference: reference.py, docgen.py).
        if path.stem in ("rover_harness", "rov_harness", "reference", "docgen"):
            continue
        text = path.read_text(encoding="utf-8")
        if path.stem == "tables":
            continue
        for line in text.splitlines():
            if re.search(r"""(print\(|\[|\+=|append\()\s*f?["']\|[ -]""", line):
                offenders.append(f"{path.name}: {line.strip()}")
    assert offenders == []


# ---------------------------------------------------------------- --json on these commands


def test_fleet_json_is_the_file_document(run_dir: Path, tmp_path: Path,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    capsys.readouterr()
    assert main(["fleet", str(run_dir / "sim"), "--workers", "1", "--json",
                 "--out", str(tmp_path)]) == 0
    cap = capsys.readouterr()
    doc = json.loads(cap.out)  # stdout is the JSON alone ("wrote ..." on stderr)
    assert "wrote" in cap.err
    assert doc == json.loads((tmp_path / "fleet.json").read_text(encoding="utf-8"))
    assert [r["kind"] for r in doc["rows"]] == ["capture"] and doc["rows"][0]["error"] is None


def test_demo_json(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    capsys.readouterr()
    assert main(["demo", "--duration", "20", "--presets", "rover", "--json",
                 "--out", str(tmp_path / "rover")]) == 0
    cap = capsys.readouterr()
    doc = json.loads(cap.out)
    score = doc["presets"]["rover"]["score"]
    assert doc["epochs"] == 200 and score["clean"] + score["faulty"] == 200
    assert main(["demo", "rov", "--json", "--out", str(tmp_path / "rov")]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["drift_deg"] == 30.0 and doc["ft"]["first_fault_t"] == pytest.approx(70.6)
    assert abs(doc["ft"]["mean_err_104_130_s_deg"]) < 1.0 < abs(
        doc["no_ft"]["mean_err_104_130_s_deg"])


def test_insgnss_report_json(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out_md = tmp_path / "r.md"
    assert main(["sim", "insgnss-report", "--seeds", "2", "--scenario", "paper-single",
                 "--config", str(ROOT / "config" / "insgnss.toml"), "--json",
                 "--out", str(out_md)]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["partial"] is False
    (run,) = doc["runs"]
    assert (run["preset"], run["scenario"], run["seed"]) == ("insgnss", "paper-single", 2)
    md = out_md.read_text(encoding="utf-8")  # the file is the Markdown report either way
    rms = md_rows(md, INSGNSS_MD_HEAD)[1]
    assert rms[3] == f"{run['methods']['none']['position_rms_3d_m']:.2f}"
    with pytest.raises(SystemExit):
        main(["sim", "insgnss-report", "--done-means", "--json", "--seeds", "x"])
    assert main(["sim", "insgnss-report", "--done-means", "--json", "--seeds", "1"]) == 2


# ---------------------------------------------------------------- checked before the work


def test_demo_presets_and_fleet_truth_dir_checked_before_any_work(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "demo"
    assert main(["demo", "--presets", "rover,nosuch", "--out", str(out)]) == 2
    assert "nosuch" in capsys.readouterr().err and not out.exists()  # nothing generated
    assert main(["demo", "--presets", ",", "--out", str(out)]) == 2
    assert "no preset named" in capsys.readouterr().err
    with pytest.raises(SystemExit) as info:
        main(["fleet", str(tmp_path), "--truth-dir", str(tmp_path / "missing")])
    assert info.value.code == 2
    assert "--truth-dir" in capsys.readouterr().err


# ---------------------------------------------------------------- ^C in the long report parts


def test_done_means_interrupted_keeps_the_seeds_done(monkeypatch: pytest.MonkeyPatch,
                                                     tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    """^C in the second seed of --done-means: the first seed's row, marked partial, exit 130."""
    calls = {"n": 0}
    real = insgnss_report.run_coast

    def second_interrupts(*a: Any, **kw: Any) -> Any:
        calls["n"] += 1
        if calls["n"] == 2:
            raise KeyboardInterrupt
        return real(*a, **kw)

    monkeypatch.setattr(insgnss_report, "run_coast", second_interrupts)
    out = tmp_path / "dm.md"
    assert main(["sim", "insgnss-report", "--done-means", "--seeds", "1,2",
                 "--config", str(ROOT / "config" / "insgnss.toml"), "--out", str(out)]) == 130
    cap = capsys.readouterr()
    assert "interrupted: partial report written" in cap.err
    text = out.read_text(encoding="utf-8")
    assert text.startswith(f"{insgnss_report.PARTIAL} insgnss: 1 of 2 seeds")
    rows = [ln for ln in text.splitlines() if re.match(r"\| \d \| ", ln)]
    assert [r.split("|")[1].strip() for r in rows] == ["1"]
    assert "against plain down-weighting" not in text  # not started
    no_markdown(cap.out)
    assert cap.out.startswith("Partial (interrupted): insgnss: 1 of 2 seeds")


def test_table2_interrupted_keeps_the_first_section(monkeypatch: pytest.MonkeyPatch,
                                                    tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    calls = {"n": 0}
    real = insgnss_report.generate

    def second_section_interrupts(*a: Any, **kw: Any) -> Any:
        calls["n"] += 1
        if calls["n"] == 2:  # one seed: the second call is the easier scenario's
            raise KeyboardInterrupt
        return real(*a, **kw)

    monkeypatch.setattr(insgnss_report, "generate", second_section_interrupts)
    out = tmp_path / "t2.md"
    assert main(["sim", "insgnss-report", "--table2-calibrated", "--seeds", "9",
                 "--out", str(out)]) == 130
    text = out.read_text(encoding="utf-8")
    assert text.startswith(f"{insgnss_report.PARTIAL} 1 of 2 Table 2 sections")
    assert "### Table 2, calibrated" in text and "### Table 2, easier" not in text
    capsys.readouterr()


# ---------------------------------------------------------------- the demo's bar, on a terminal


def _under_pty(argv: list[str], cwd: Path, timeout: float = 120) -> tuple[int, str]:
    return cli_under_pty(argv, cwd, timeout)


def test_demo_progress_bar_on_a_terminal_only(tmp_path: Path) -> None:
    argv = ["demo", "--duration", "20", "--presets", "rover", "--out", "d"]
    status, tty = _under_pty(argv, tmp_path)
    assert status == 0, tty
    assert "demo:" in tty and "step" in tty and "\r" in tty  # a refreshing tqdm bar
    assert re.search(r"^rover +\d+/\d+ ", tty.replace("\r\n", "\n"), re.M)  # and the table
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    piped = subprocess.run([sys.executable, "-m", "firmware_host.cli", *argv[:-1], "p"],
                           cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120,
                           check=False)
    assert piped.returncode == 0, piped.stderr
    assert "demo:" not in piped.stderr and "\r" not in piped.stderr


def test_fleet_interrupted_writes_the_jobs_done(run_dir: Path, tmp_path: Path,
                                               monkeypatch: pytest.MonkeyPatch,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    """^C during the second of two jobs (two sweep points): the first job's row is written,
    marked partial, exit 130."""
    from firmware_host.devtools import fleet

    calls = {"n": 0}
    real = fleet.evaluate_log

    def second_interrupts(job: Any) -> Any:
        calls["n"] += 1
        if calls["n"] == 2:
            raise KeyboardInterrupt
        return real(job)

    monkeypatch.setattr(fleet, "evaluate_log", second_interrupts)
    capsys.readouterr()
    assert main(["fleet", str(run_dir / "sim"), "--workers", "1", "--sweep",
                 "rover.detector.gate_sigmas=4,6", "--out", str(tmp_path)]) == 130
    cap = capsys.readouterr()
    assert "interrupted: the 1 of 2 jobs done are written" in cap.err
    no_markdown(cap.out)
    assert "Partial (interrupted): 1 of 2 jobs done before ^C." in cap.out
    doc = json.loads((tmp_path / "fleet.json").read_text(encoding="utf-8"))
    assert doc["partial"] is True and len(doc["rows"]) == 1
    assert doc["rows"][0]["point"] == "rover.detector.gate_sigmas=4"
    md = (tmp_path / "fleet.md").read_text(encoding="utf-8")
    assert "**Partial (interrupted):** 1 of 2 jobs done before ^C." in md


def test_bench_replay_memory_prints_an_aligned_table() -> None:
    mem = {"rate_hz": 1.0, "short_s": 60.0, "long_s": 86400.0,
           "nmea": {"short_mib": 56.6, "long_mib": 56.7, "ratio": 1.0018}}
    text = replay_memory_table(mem).console()
    assert "|" not in text
    lines = text.splitlines()
    assert lines[0].startswith("replay peak RSS, 1 Hz") and "24 h log (MiB)" in lines[0]
    assert lines[1].split() == ["nmea", "56.6", "56.7", "1.002", "<=", "1.5"]


def test_a_wide_table_wraps_to_the_width_repeating_its_key_columns() -> None:
    t = Table(["scenario", "method", "detected / faulty", "missed", "false alarms / clean",
               "out RMS (m)", "raw RMS (m)"], keep=2)
    t.add("jumps", "this run", "33/33 (100.0 %)", 0, "0/2967", 0.44, 4.32)
    t.add("jumps", "ekf3", "21/33 (63.6 %)", 12, "0/2967", 0.5, 4.32)
    assert "\n\n" not in t.console()  # not a terminal here: never wrapped into a pipe
    wrapped = t.console(width=60)
    parts = wrapped.split("\n\n")
    assert len(parts) == 3  # 18 + 43, 18 + 35, 18 + 13 columns wide
    for part in parts:
        lines = part.splitlines()
        assert all(len(ln) <= 60 for ln in lines)
        assert lines[0].split()[:2] == ["scenario", "method"]
        assert [ln.split()[1] for ln in lines[1:]] == ["this", "ekf3"]
    headers = " ".join(p.splitlines()[0] for p in parts)
    for h in t.headers:
        assert h in headers  # every column shown once wrapped


def test_eval_on_a_100_column_terminal_wraps_its_table(run_dir: Path, tmp_path: Path) -> None:
    argv = ["eval", str(run_dir / "rep"), "--truth", str(run_dir / "sim" / "truth.jsonl"),
            "--no-plots"]
    status, tty = _under_pty(argv, tmp_path)
    assert status == 0, tty
    lines = tty.replace("\r\n", "\n").splitlines()
    heads = [ln for ln in lines if ln.startswith("scenario  method")]
    assert len(heads) >= 2  # wrapped into several tables, each with its key columns
    assert all(len(ln) <= 100 for ln in lines)
    piped = subprocess.run([sys.executable, "-m", "firmware_host.cli", *argv], cwd=tmp_path,
                           env=dict(os.environ, PYTHONPATH=str(ROOT)), capture_output=True,
                           text=True, timeout=120, check=False)
    assert piped.returncode == 0, piped.stderr
    assert sum(ln.startswith("scenario  method") for ln in piped.stdout.splitlines()) == 1
