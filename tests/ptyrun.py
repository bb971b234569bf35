"""The CLI run on a real pseudo-terminal (100 columns), for the tests where a TTY matters."""

from __future__ import annotations

import fcntl
import os
import select
import struct
import subprocess
import sys
import termios
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
