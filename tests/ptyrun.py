"""The CLI run on a real pseudo-terminal (100 columns), for the tests where a TTY matters."""

from __future__ import annotations

import fcntl
import os
import re
import select
import struct
import subprocess
import sys
import termios
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def cli_under_pty(argv: list[str], cwd: Path, timeout: float = 120,
                  env: dict[str, str] | None = None) -> tuple[int, str]:
    """``fdi-bridge ARGV`` with stdin/stdout/stderr on a real pty; (exit status, output)."""
    master, slave = os.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 100, 0, 0))  # 100 columns
    proc = subprocess.Popen([sys.executable, "-m", "firmware_host.cli", *argv], cwd=cwd,
                            env=env if env is not None else dict(os.environ,
                                                                 PYTHONPATH=str(ROOT)),
                            stdin=slave, stdout=slave, stderr=slave, close_fds=True)
    os.close(slave)
    chunks: list[bytes] = []
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        ready, _, _ = select.select([master], [], [], 0.5)
        if ready:
            try:
                data = os.read(master, 65536)
            except OSError:  # EIO: the child closed the terminal
                break
            if not data:
                break
            chunks.append(data)
        elif proc.poll() is not None:
            break
    os.close(master)
    return proc.wait(timeout=30), b"".join(chunks).decode("utf-8", "replace")


class StderrOnPty:
    """``fdi-bridge ARGV`` with its standard error on a real pty (where tqdm draws a progress
    bar, as on a user's terminal) and its standard output piped. A thread reads the terminal
    all along, so the command never blocks on it; :meth:`wait_for` waits for the bar (or any
    text) instead of sleeping and hoping the command got that far."""

    def __init__(self, argv: list[str], cwd: Path, env: dict[str, str] | None = None) -> None:
        master, slave = os.openpty()
        fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 100, 0, 0))
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "firmware_host.cli", *argv], cwd=cwd,
            env=env if env is not None else dict(os.environ, PYTHONPATH=str(ROOT)),
            stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=slave, close_fds=True)
        os.close(slave)
        self._master = master
        self._buf = bytearray()
        self._lock = threading.Lock()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        while True:
            try:
                data = os.read(self._master, 65536)
            except OSError:  # EIO: the command closed the terminal (it ended)
                break
            if not data:
                break
            with self._lock:
                self._buf += data

    @property
    def stderr(self) -> str:
        with self._lock:
            return self._buf.decode("utf-8", "replace")

    def wait_for(self, pattern: str, timeout_s: float, what: str) -> None:
        """Until ``pattern`` (a regular expression) is on the terminal; fails after
        ``timeout_s`` or when the command ends first."""
        deadline = time.monotonic() + timeout_s
        while not re.search(pattern, self.stderr):
            if self.proc.poll() is not None:
                raise AssertionError(f"the command ended before {what}: {self.stderr[-500:]}")
            if time.monotonic() > deadline:
                raise AssertionError(f"timed out waiting for {what}: {self.stderr[-500:]}")
            time.sleep(0.05)  # polling the reader thread, bounded by the deadline

    def finish(self, timeout_s: float) -> tuple[int, str, str]:
        """Wait for the command's end: (exit status, standard output, standard error)."""
        out, _ = self.proc.communicate(timeout=timeout_s)
        self._reader.join(10.0)
        os.close(self._master)
        return self.proc.returncode, out.decode("utf-8", "replace"), self.stderr
