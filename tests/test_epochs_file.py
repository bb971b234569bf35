"""``run --out``'s files on a full, read-only or unreachable disk, and kill-safety (issue C).

Item 3: ``epochs.jsonl`` and ``summary.json`` behave as the flight recorder does (a failure
logged once, counted, retried; resumed when space returns; never a cut line; the summary whole
or not at all, and said on stderr when it cannot be written); ``--out``/``--record`` that cannot
be written do not refuse to start, as ``[recorder] dir`` does not. Item 9: ``epochs.jsonl``
reaches the kernel every 0.25 s of the runner's clock, so a ``SIGKILL`` loses at most that
and one iteration (it lost up to 1.26 s at 10 Hz with an 8 KiB buffer).

The first tests inject the failure into :class:`JsonlFile`'s one write call and run everywhere;
the tmpfs tests use ``tests/diskfull.py`` (skipped with the reason where mounting is refused).
"""

from __future__ import annotations

import errno
import json
import logging
import os
import subprocess
import sys
from pathlib import Path

import pytest

import firmware_host.runtime.records as records
from firmware_host.runtime.loop import FakeClock
from firmware_host.runtime.records import SUMMARY_RESERVE, EpochLog, JsonlFile
from tests.diskfull import fill, remount, small_tmpfs

ROOT = Path(__file__).resolve().parents[1]
PAD = "x" * 400  # a rover record is 400-700 bytes


def _line(k: int) -> str:
    return json.dumps({"k": k, "pad": PAD[: k % 300]}, separators=(",", ":")) + "\n"


def _check_lines(path: Path, sent: int, lost: int) -> list[int]:
    """Every line is whole JSON, sent in this order, none twice; ``lost`` are missing."""
    data = path.read_bytes()
    assert not data or data.endswith(b"\n")
    ks = [json.loads(line)["k"] for line in data.splitlines()]
    assert ks == sorted(ks) and len(ks) == len(set(ks))
    assert sent - len(ks) == lost, (sent, len(ks), lost)
    return ks


def _messages(caplog: pytest.LogCaptureFixture, text: str) -> list[str]:
    return [r.getMessage() for r in caplog.records if text in r.getMessage()]


# --------------------------------------------------------------------------- injected


@pytest.mark.parametrize("buffer_kb", [256, 1])
def test_injected_disk_full_cuts_back_to_whole_lines(tmp_path: Path, buffer_kb: int,
                                                     monkeypatch: pytest.MonkeyPatch,
                                                     caplog: pytest.LogCaptureFixture) -> None:
    """Writes 10-29 fail (ENOSPC), one in four after taking part of its bytes: the file is cut
    back to its last whole line, the outage logged once each way, writing resumes by itself.
    What the disk refused waits for the next try up to the buffer's bound (256 KiB: nothing
    lost over this outage), past it it is dropped and counted (1 KiB)."""
    real = records._write
    calls = {"n": 0}

    def flaky(fd: int, data: bytes) -> int:
        calls["n"] += 1
        if 10 <= calls["n"] < 30:
            if calls["n"] % 4 == 0:
                return real(fd, data[: len(data) // 3])  # a short write, then the error
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(fd, data)

    monkeypatch.setattr(records, "_write", flaky)
    clock = FakeClock()
    f = JsonlFile(tmp_path / "epochs.jsonl", clock=clock, buffer_max=buffer_kb * 1024)
    paused = 0
    with caplog.at_level(logging.WARNING, logger="fdi_bridge.records"):
        for k in range(400):
            clock.now = k * 0.1
            f.write(_line(k))
            f.poll()
            paused += not f.writing
        f.close()
    assert paused > 10 and f.writing and f.outages == 1
    assert f.write_errors == 15  # 20 failing calls, 5 of them after a short write
    assert (f.lost_lines > 0) == (buffer_kb == 1)
    assert len(_messages(caplog, "write failed: No space left on device")) == 1
    assert len(_messages(caplog, "writing again after")) == 1
    ks = _check_lines(tmp_path / "epochs.jsonl", 400, f.lost_lines)
    assert ks[0] == 0 and ks[-1] == 399  # before and after the outage: all there
    assert f.lines_written == len(ks) and f.lost_lines + f.lines_written == 400


def test_summary_is_whole_or_absent_and_said(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                             caplog: pytest.LogCaptureFixture) -> None:
    """A summary that cannot be written leaves no file (never 0 bytes, never an earlier run's)
    and no temporary file, and is said (ERROR, on stderr in the CLI); in a replay
    (``keep_going=False``) the error is raised."""
    out = tmp_path / "out"
    out.mkdir()
    (out / "summary.json").write_text('{"from": "an earlier run"}\n')
    log = EpochLog(out, keep_going=True)
    assert not (out / "summary.json").exists()  # it would pass for this run's
    assert (out / SUMMARY_RESERVE).stat().st_size == records.SUMMARY_RESERVE_BYTES
    log.write({"k": 1})
    log.close()

    def full(fd: int, data: bytes) -> int:
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "write", full)  # the summary's write (JsonlFile is closed)
    with caplog.at_level(logging.ERROR, logger="fdi_bridge.records"):
        assert log.write_summary({"epochs": 1}) is None
    assert _messages(caplog, f"could not write {out / 'summary.json'}: No space left")
    assert sorted(p.name for p in out.iterdir()) == ["epochs.jsonl"]  # no reserve, no temp
    with pytest.raises(OSError):
        EpochLog(tmp_path / "replay").write_summary({"epochs": 1})
    assert sorted(p.name for p in (tmp_path / "replay").iterdir()) == ["epochs.jsonl"]
    monkeypatch.undo()
    assert log.write_summary({"epochs": 1}) == out / "summary.json"
    assert json.loads((out / "summary.json").read_text()) == {"epochs": 1}


# --------------------------------------------------------------------------- tmpfs


def test_full_tmpfs_then_space_returns_and_the_summary_fits(tmp_path: Path,
                                                            caplog: pytest.LogCaptureFixture
                                                            ) -> None:
    """``EpochLog`` of the live bridge on a 256 KiB tmpfs filled at 10 s, freed at 30 s,
    filled again at 50 s to the end: nothing of the first outage is lost, no line is cut, the
    second outage's lines are counted as lost; and the summary is written at the end although
    the disk is full (into the space reserved at the start)."""
    with small_tmpfs(tmp_path / "disk", size_kb=256) as disk:
        clock = FakeClock()
        out = disk / "out"
        log = EpochLog(out, keep_going=True, clock=clock)
        assert log.file is not None
        filler = None
        with caplog.at_level(logging.WARNING, logger="fdi_bridge.records"):
            for k in range(600):  # 60 s at 10 Hz
                clock.now = k * 0.1
                if k in (100, 500):
                    filler = fill(disk)  # full from here ...
                if k == 300:
                    assert filler is not None and not log.file.writing
                    filler.unlink()  # ... to here
                log.write({"k": k, "pad": PAD[:100]})  # 600 lines: 72 kB, as the disk was
                log.poll(clock.now)
            log.close()
            counters = log.counters()
            assert counters is not None
            assert log.write_summary({"epochs": 600, "epochs_file": counters}) is not None
        assert counters["outages"] == 2 and counters["write_errors"] > 0
        assert counters["writing"] is False and counters["lost_lines"] > 0
        ks = _check_lines(out / "epochs.jsonl", 600, counters["lost_lines"])
        assert counters["lines_written"] == len(ks)
        # The 20 s outage: its 200 lines waited in memory (within the 256 KiB bound) and went
        # to the file once space returned, so every line to the last 0.25 s before the second
        # fill is there; the lines of the second outage are lost at the end.
        assert set(range(0, 497)) <= set(ks)
        assert len(_messages(caplog, "write failed: No space left on device")) == 2
        assert len(_messages(caplog, "writing again after")) == 1
        assert json.loads((out / "summary.json").read_text())["epochs"] == 600
        assert not (out / SUMMARY_RESERVE).exists()


def test_read_only_disk_at_start_then_writable(tmp_path: Path,
                                               caplog: pytest.LogCaptureFixture) -> None:
    """``--out`` on a read-only disk (before: exit 2) does not stop the run: said once,
    counted, the file created once the disk is writable; the summary of a disk still
    read-only at the end is said, not raised."""
    with small_tmpfs(tmp_path / "disk", size_kb=256) as disk:
        remount(disk, read_only=True)
        clock = FakeClock()
        with caplog.at_level(logging.WARNING, logger="fdi_bridge.records"):
            log = EpochLog(disk / "out", keep_going=True, clock=clock)
            assert log.file is not None and not log.file.writing
            for k in range(200):
                clock.now = k * 0.1
                if k == 100:
                    remount(disk, read_only=False)
                log.write({"k": k})
                log.poll(clock.now)
            log.close()
        assert _messages(caplog, "could not create") and len(
            _messages(caplog, "Read-only file system")) == 1
        counters = log.file.counters()
        assert counters["outages"] == 1 and counters["writing"] is True
        ks = _check_lines(disk / "out" / "epochs.jsonl", 200, counters["lost_lines"])
        assert set(range(100, 200)) <= set(ks)
        remount(disk, read_only=True)
        with caplog.at_level(logging.ERROR, logger="fdi_bridge.records"):
            assert log.write_summary({"epochs": 200}) is None
        assert _messages(caplog, "could not write")
        assert not (disk / "out" / "summary.json").exists()


# --------------------------------------------------------------------------- the CLI


def _run_cli(*argv: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "firmware_host.cli", *argv], cwd=cwd,
                          capture_output=True, text=True, timeout=120,
                          env=dict(os.environ, PYTHONPATH=str(ROOT)))


def test_run_with_out_and_record_that_cannot_be_written_runs_on(tmp_path: Path) -> None:
    """``--out`` and ``--record`` under a regular file (no directory can be made there; before:
    exit 2 at start) behave as ``[recorder] dir`` does: said, and the run goes on (exit 0)."""
    (tmp_path / "afile").write_text("not a directory\n")
    r = _run_cli("run", "--config", "rover", "--out", str(tmp_path / "afile" / "out"),
                 "--record", str(tmp_path / "afile" / "rec"), "--duration", "1.5", "--json",
                 cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "Traceback" not in r.stderr and "internal error" not in r.stderr
    assert f"could not create {tmp_path / 'afile' / 'out' / 'epochs.jsonl'}" in r.stderr
    assert "Not a directory; records are not written (detection and outputs go on)" in r.stderr
    assert f"recorder directory {tmp_path / 'afile' / 'rec'}" in r.stderr
    assert f"could not write {tmp_path / 'afile' / 'out' / 'summary.json'}" in r.stderr
    summary = json.loads(r.stdout)
    assert summary["runtime"]["stopped_by"] == "duration"
    assert summary["epochs_file"]["writing"] is False
    assert summary["recorder"]["recording"] is False
