"""^C in ``sim rover`` and ``demo`` (issue 45): the partial files are said to be partial and no
comparison of part of a run is printed as if complete; exit 130. Real parts: the command as a
subprocess, SIGINT once its files are being written."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _interrupt(argv: list[str], cwd: Path, ready: Callable[[], bool]
               ) -> tuple[int, str, str]:
    proc = subprocess.Popen([sys.executable, "-m", "firmware_host.cli", *argv], cwd=cwd,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            env=dict(os.environ, PYTHONPATH=str(ROOT)))
    deadline = time.monotonic() + 60.0
    while time.monotonic() < deadline and not ready() and proc.poll() is None:
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=60.0)
    return proc.returncode, out.decode(), err.decode()


def _grown(path: Path, size: int = 20000) -> Callable[[], bool]:
    return lambda: path.exists() and path.stat().st_size > size


def test_sim_rover_says_its_files_are_partial(tmp_path: Path) -> None:
    out = tmp_path / "sim"
    rc, stdout, err = _interrupt(["sim", "rover", "--duration", "86400", "--out", str(out)],
                                 tmp_path, _grown(out / "rover.nmea"))
    assert rc == 130, err
    assert "interrupted; the files in" in err and "are partial" in err, err
    assert "Traceback" not in err and stdout == ""  # no summary of a run that did not end


def test_demo_prints_no_comparison_of_a_partial_replay(tmp_path: Path) -> None:
    out = tmp_path / "demo"
    rc, stdout, err = _interrupt(["demo", "--duration", "3600", "--presets", "rover",
                                  "--out", str(out)], tmp_path,
                                 _grown(out / "rover" / "epochs.jsonl"))
    assert rc == 130, err
    assert "interrupted during the rover replay; no comparison" in err, err
    assert "Rover demo:" not in stdout and "Traceback" not in err
