"""``fdi-bridge replay`` stopped by SIGTERM or SIGHUP (issue C item 9).

Before: the default action killed it, leaving no ``summary.json`` and its ``--nmea-out
pty:PATH`` link dangling (a later ``run`` opened that name onto whichever program got the pty
next). Now both stop it as ^C does: the partial summary written (``interrupted_by``), the link
removed, exit 128 + the signal's number. A real replay in a child process, paced at its
recorded times (``--speed 1``), its output read on the link until epochs flow.
"""

from __future__ import annotations

import json
import os
import select
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from drivers.ptypair import PtyPair
from firmware_host.devtools.rover_sim import RoverScenario, generate

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP], ids=["SIGTERM", "SIGHUP"])
def test_replay_stopped_by_a_signal_writes_the_partial_summary_and_removes_its_link(
        tmp_path: Path, sig: signal.Signals) -> None:
    log = tmp_path / "in.nmea"
    log.write_bytes(b"".join(d for _, d, _ in generate(
        RoverScenario(rate_hz=10.0, duration_s=60.0, seed=8))))
    link, out = tmp_path / "nmea-out", tmp_path / "out"
    child = subprocess.Popen(
        [sys.executable, "-m", "firmware_host.cli", "replay", str(log), "--out", str(out),
         "--speed", "1", "--nmea-out", f"pty:{link}"],
        cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        env=dict(os.environ, PYTHONPATH=str(ROOT)))
    fd = -1
    try:
        deadline = time.monotonic() + 30.0
        while not link.is_symlink():
            assert time.monotonic() < deadline and child.poll() is None, "no pty link"
            select.select([], [], [], 0.01)
        fd = os.open(link, os.O_RDWR | os.O_NOCTTY)
        got = b""
        while got.count(b"GGA,") < 5:  # the replay is under way: epochs on its output
            assert time.monotonic() < deadline, got
            ready, _, _ = select.select([fd], [], [], 0.1)
            if ready:
                got += os.read(fd, 4096)
        child.send_signal(sig)
        stdout, stderr = child.communicate(timeout=30)
    finally:
        if fd >= 0:
            os.close(fd)
        if child.poll() is None:
            child.kill()
            child.wait(10)
    assert child.returncode == 128 + sig, stderr
    assert "Traceback" not in stderr and "internal error" not in stderr
    assert f"interrupted ({sig.name}) after" in stderr and "summary.json is partial" in stderr
    assert not link.is_symlink()  # removed: no name left for another program's pty
    summary = json.loads((out / "summary.json").read_text())
    assert summary["partial"] is True and summary["interrupted_by"] == sig.name
    assert 5 <= summary["epochs"] < 600
    lines = (out / "epochs.jsonl").read_text().splitlines()
    assert len(lines) == summary["epochs"]
    row = [x for x in stdout.splitlines() if x.startswith("partial")]
    assert row and row[0].endswith(f"interrupted: only what was read before {sig.name}"), stdout


def test_pty_link_is_removed_only_while_it_names_this_pty(tmp_path: Path) -> None:
    """A link another program has taken since (a second replay with the same PATH) stays."""
    link = tmp_path / "gps"
    first = PtyPair(link=link)
    second = PtyPair(link=link)  # takes the name over
    first.close()
    assert link.is_symlink() and os.readlink(link) == second.slave_path
    second.close()
    assert not link.is_symlink()
