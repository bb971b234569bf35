"""What a port path names, and who holds it (Linux ``/proc``; best effort elsewhere).

:func:`drivers.transport.open_port` asks this module before it opens a device path:

* :func:`refusal` -- a FIFO, a regular file, a directory, a socket or a character device that
  is not a tty (``/dev/null``, ``/dev/zero``) is refused **before any open**: opening a FIFO
  can block, and opening some devices acts on its own (``/dev/watchdog``). A tty is a
  character device whose major number a tty driver owns (``/proc/tty/drivers``). A missing
  path is left to the open (a USB adapter comes and goes; the caller retries).
* :func:`is_pty` -- a pseudo-terminal's slave (``/dev/pts/N``), which a replay or a test
  harness keeps open itself.
* :func:`holders` -- the processes that hold the path open or locked, to name them when a
  port is busy: the ``flock`` owners in ``/proc/locks`` first, else every process with a
  descriptor on the device (``/proc/PID/fd``); :func:`other_openers` -- the latter without
  this process (gpsd's ``fusercount``).
"""

from __future__ import annotations

import contextlib
import os
import stat
from dataclasses import dataclass
from pathlib import Path

_PROC = Path("/proc")


@dataclass(frozen=True)
class Holder:
    """A process holding a device: its pid and its command line (shortened)."""

    pid: int
    command: str

    def __str__(self) -> str:
        own = ", this process" if self.pid == os.getpid() else ""
        return f"pid {self.pid} ({self.command}{own})"


def _tty_majors() -> tuple[set[int], set[int]] | None:
    """(majors of every tty driver, majors of pty slaves) from ``/proc/tty/drivers``; None when
    it cannot be read."""
    try:
        lines = (_PROC / "tty" / "drivers").read_text().splitlines()
    except OSError:
        return None
    ttys: set[int] = set()
    ptys: set[int] = set()
    for line in lines:
        fields = line.split()
        if len(fields) < 5 or not fields[2].isdigit():
            continue
        major = int(fields[2])
        ttys.add(major)
        if fields[4] == "pty:slave":
            ptys.add(major)
    return ttys, ptys


def _is_tty_device(path: str, st: os.stat_result) -> bool:
    majors = _tty_majors()
    if majors is not None:
        return os.major(st.st_rdev) in majors[0]
    try:  # no /proc/tty/drivers: ask the device itself (non-blocking, no controlling tty)
        fd = os.open(path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    except OSError:
        return True  # let the open report why
    try:
        return os.isatty(fd)
    finally:
        os.close(fd)


def refusal(path: str) -> str | None:
    """Why ``path`` cannot be a serial port (what it is instead), or None when it is a tty or
    is missing (the open reports that)."""
    try:
        st = os.stat(path)
    except OSError:
        return None
    mode = st.st_mode
    if stat.S_ISCHR(mode):
        if _is_tty_device(path, st):
            return None
        return (f"is a character device but not a serial port or tty (device "
                f"{os.major(st.st_rdev)}:{os.minor(st.st_rdev)})")
    if stat.S_ISFIFO(mode):
        return "is a FIFO (named pipe), not a serial port"
    if stat.S_ISREG(mode):
        return "is a regular file, not a serial port (a capture is played with `fdi-bridge replay`)"
    if stat.S_ISDIR(mode):
        return "is a directory, not a serial port"
    if stat.S_ISSOCK(mode):
        return "is a Unix socket, not a serial port"
    return "is not a serial port"


def is_pty(path: str) -> bool:
    """True when ``path`` names a pseudo-terminal's slave side."""
    try:
        st = os.stat(path)
    except OSError:
        return False
    if not stat.S_ISCHR(st.st_mode):
        return False
    majors = _tty_majors()
    if majors is not None:
        return os.major(st.st_rdev) in majors[1]
    return os.path.realpath(path).startswith("/dev/pts/")


def command(pid: int) -> str:
    """A process's command line, shortened to 80 characters (its name if it has none)."""
    try:
        raw = (_PROC / str(pid) / "cmdline").read_bytes()
    except OSError:
        raw = b""
    text = raw.replace(b"\0", b" ").decode("utf-8", "replace").strip()
    if not text:
        with contextlib.suppress(OSError):
            text = (_PROC / str(pid) / "comm").read_text().strip()
    return (text[:77] + "...") if len(text) > 80 else (text or "?")


def _lock_owners(st: os.stat_result) -> list[int]:
    """pids holding a ``flock``/``fcntl`` lock on the file ``st`` describes (``/proc/locks``)."""
    want = f"{os.major(st.st_dev):02x}:{os.minor(st.st_dev):02x}:{st.st_ino}"
    pids: list[int] = []
    try:
        lines = (_PROC / "locks").read_text().splitlines()
    except OSError:
        return pids
    for line in lines:
        fields = line.split()
        if "->" in fields or len(fields) < 6:
            continue  # a waiter, not an owner
        if fields[5] == want and fields[4].isdigit():
            pids.append(int(fields[4]))
    return pids


def openers(target: str) -> list[int]:
    """pids with a descriptor whose link is ``target``: a device's real path (what gpsd's
    ``fusercount`` counts), or a socket's ``socket:[INODE]``."""
    pids: list[int] = []
    try:
        procs = [p for p in _PROC.iterdir() if p.name.isdigit()]
    except OSError:
        return pids
    for proc in procs:
        try:
            fds = list((proc / "fd").iterdir())
        except OSError:
            continue  # gone, or not ours to read
        for fd in fds:
            try:
                if os.readlink(fd) == target:
                    pids.append(int(proc.name))
                    break
            except OSError:
                continue
    return pids


def holders(path: str) -> list[Holder]:
    """The processes holding ``path``: its lock owners if any, else every process with it open.
    Empty when none is found or ``/proc`` cannot tell."""
    try:
        st = os.stat(path)
    except OSError:
        return []
    pids = _lock_owners(st) or openers(os.path.realpath(path))
    return [Holder(pid, command(pid)) for pid in dict.fromkeys(pids)]


def other_openers(path: str) -> list[Holder]:
    """The processes other than this one with ``path`` open (gpsd's ``fusercount`` less one)."""
    me = os.getpid()
    pids = [p for p in openers(os.path.realpath(path)) if p != me]
    return [Holder(pid, command(pid)) for pid in pids]


def describe(found: list[Holder]) -> str:
    """``"pid 123 (gpsd -N /dev/ttyUSB0)"``, several joined with commas."""
    return ", ".join(str(h) for h in found) if found else "another process (not found in /proc)"
