"""``fdi-bridge record`` shows what it records and says how it stopped (issue 45): on a
terminal a progress line with the bytes and their rate; ^C ends it with the capture complete up
to then, said as such, exit 0. Real parts: the command as a subprocess, its stderr on a real
terminal (a pty), the receiver on another pty."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

from drivers.capture import CaptureReader
from drivers.ptypair import PtyPair
from tests.ptyrun import cli_under_pty

ROOT = Path(__file__).resolve().parents[1]
LINE = b"$GPGGA,120000.00,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,*4F\r\n"


class Feeder(threading.Thread):
    def __init__(self, pty: PtyPair) -> None:
        super().__init__(daemon=True)
        self.pty = pty
        self.halt = threading.Event()

    def run(self) -> None:
        while not self.halt.is_set():
            self.pty.write(LINE * 4)
            self.pty.read(0.0)
            self.halt.wait(0.05)

    def stop(self) -> None:
        self.halt.set()
        self.join(5.0)


def test_record_shows_its_progress_on_a_terminal(tmp_path: Path) -> None:
    with PtyPair(link=tmp_path / "gps") as gps:
        feeder = Feeder(gps)
        feeder.start()
        try:
            rc, text = cli_under_pty(["record", str(tmp_path / "gps"), "--out",
                                      str(tmp_path / "x.cap"), "--duration", "3"], tmp_path,
                                     timeout=30.0)
        finally:
            feeder.stop()
    assert rc == 0, text
    assert "recording " + str(tmp_path / "gps") in text, text
    assert "B/s" in text and "Traceback" not in text
    got = sum(len(r.data) for r in CaptureReader(tmp_path / "x.cap") if r.channel == 0)
    assert f"recorded {got} bytes" in text and got > 0


def test_control_c_keeps_the_capture_and_says_so(tmp_path: Path) -> None:
    with PtyPair(link=tmp_path / "gps") as gps:
        feeder = Feeder(gps)
        feeder.start()
        proc = subprocess.Popen(
            [sys.executable, "-m", "firmware_host.cli", "record", str(tmp_path / "gps"),
             "--out", str(tmp_path / "x.cap")], cwd=tmp_path, stdout=subprocess.PIPE,
            stderr=subprocess.PIPE, env=dict(os.environ, PYTHONPATH=str(ROOT)))
        try:
            deadline = time.monotonic() + 20.0
            cap = tmp_path / "x.cap"
            while time.monotonic() < deadline and (not cap.exists()
                                                   or cap.stat().st_size < 2000):
                time.sleep(0.1)
            proc.send_signal(signal.SIGINT)
            out, err = proc.communicate(timeout=20.0)
        finally:
            feeder.stop()
    assert proc.returncode == 0, err
    assert b"Traceback" not in err
    got = sum(len(r.data) for r in CaptureReader(tmp_path / "x.cap") if r.channel == 0)
    assert out.decode().startswith(f"stopped by ^C: recorded {got} bytes"), out
