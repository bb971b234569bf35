"""A real pseudo-terminal pair, the virtual serial port of replays and hardware-in-the-loop tests.

The master side is a file descriptor owned by the test harness or the replayer; the slave side
has a path (``/dev/pts/N``) that a driver opens like any serial device, by URL. The slave is put
in raw mode at once, so no byte written before the driver opens it is translated (CR to NL) or
echoed. An optional symlink gives the slave a stable name (like ``socat``'s ``link=``); it is
removed on :meth:`close` (while it still names this pty), which the commands that make one run
on ``SIGTERM`` and ``SIGHUP`` too (``fdi-bridge replay``): a link left behind would name
whichever program gets that ``/dev/pts/N`` next.
"""

from __future__ import annotations

import contextlib
import os
import pty
import select
import termios
import tty
from pathlib import Path


class PtyPair:
    """``openpty()`` with the slave in raw mode; ``write``/``read`` act on the master side."""

    def __init__(self, link: str | os.PathLike[str] | None = None, baudrate: int | None = None):
        self.master_fd, self.slave_fd = pty.openpty()
        tty.setraw(self.slave_fd, termios.TCSANOW)
        tty.setraw(self.master_fd, termios.TCSANOW)
        if baudrate is not None:
            attrs = termios.tcgetattr(self.slave_fd)
            speed = getattr(termios, f"B{baudrate}", None)
            if speed is not None:
                attrs[4] = attrs[5] = speed
                termios.tcsetattr(self.slave_fd, termios.TCSANOW, attrs)
        self.slave_path = os.ttyname(self.slave_fd)
        self.link: Path | None = None
        if link is not None:
            self.link = Path(link)
            with contextlib.suppress(FileNotFoundError):
                self.link.unlink()
            self.link.symlink_to(self.slave_path)
        self.closed = False

    @property
    def url(self) -> str:
        """The path a driver opens (the symlink when one was asked for)."""
        return str(self.link) if self.link is not None else self.slave_path

    def write(self, data: bytes) -> int:
        """Write all of ``data`` to the master side (blocks while the tty buffer is full)."""
        view = memoryview(data)
        while view:
            n = os.write(self.master_fd, view)
            view = view[n:]
        return len(data)

    def read(self, timeout_s: float = 0.0, size: int = 65536) -> bytes:
        """Read what the slave side wrote; ``b""`` if nothing arrives within ``timeout_s``."""
        ready, _, _ = select.select([self.master_fd], [], [], timeout_s)
        if not ready:
            return b""
        try:
            return os.read(self.master_fd, size)
        except OSError:
            return b""

    def close_slave_keepalive(self) -> None:
        """Close the harness's own slave fd (the driver keeps its own)."""
        if self.slave_fd >= 0:
            with contextlib.suppress(OSError):
                os.close(self.slave_fd)
            self.slave_fd = -1

    def close(self) -> None:
        if self.closed:
            return
        self.closed = True
        for fd in (self.master_fd, self.slave_fd):
            if fd >= 0:
                with contextlib.suppress(OSError):
                    os.close(fd)
        if self.link is not None:  # ours only: another program may have taken the name since
            with contextlib.suppress(OSError):
                if os.readlink(self.link) == self.slave_path:
                    self.link.unlink()

    def __enter__(self) -> PtyPair:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
