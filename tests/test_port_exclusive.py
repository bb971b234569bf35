"""Ports are opened exclusively, and what is not a serial port is refused (issue C item 6).

Before: two bridges (or gpsd) on one port each got about half the bytes, silently; a FIFO,
``/dev/null`` or ``/dev/zero`` failed with "Inappropriate ioctl for device". Every opener here
is a real process on a real pty (the tests run as root, where ``TIOCEXCL`` stops no one:
pyserial's ``exclusive=True`` is ``flock``, which does).
"""

from __future__ import annotations

import logging
import os
import select
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from drivers.ptypair import PtyPair
from drivers.resilient import ResilientPort
from drivers.transport import SerialSettings, open_port, read_some
from fdi.errors import PortError

ROOT = Path(__file__).resolve().parents[1]
DEADLINE_S = 10.0
ENV = dict(os.environ, PYTHONPATH=str(ROOT))

HOLD = """
import sys
from drivers.transport import SerialSettings, open_port
port = open_port(SerialSettings(url=sys.argv[1]))
print("holding", flush=True)
sys.stdin.read()  # until the test closes our stdin
"""

TRY = """
import sys
from drivers.transport import SerialSettings, open_port
from fdi.errors import PortError
try:
    open_port(SerialSettings(url=sys.argv[1]))
except PortError as err:
    print(err)
    sys.exit(3)
print("opened")
"""


def _ready(proc: subprocess.Popen[str], word: str) -> str:
    """The first line of ``proc``'s stdout (within the deadline), which must hold ``word``."""
    assert proc.stdout is not None
    ready, _, _ = select.select([proc.stdout], [], [], DEADLINE_S)
    assert ready, f"no line from the helper within {DEADLINE_S} s"
    line = proc.stdout.readline()
    assert word in line, line
    return line


@pytest.fixture()
def holder() -> Iterator[tuple[PtyPair, subprocess.Popen[str]]]:
    """A real pty and another process holding its slave through drivers.transport."""
    with PtyPair() as pty:
        proc = subprocess.Popen([sys.executable, "-c", HOLD, pty.url], cwd=ROOT, env=ENV,
                                stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        try:
            _ready(proc, "holding")
            yield pty, proc
        finally:
            assert proc.stdin is not None
            proc.stdin.close()
            proc.wait(DEADLINE_S)


def test_a_second_process_is_refused_naming_the_holder(
        holder: tuple[PtyPair, subprocess.Popen[str]]) -> None:
    pty, proc = holder
    with pytest.raises(PortError) as exc:
        open_port(SerialSettings(url=pty.url))
    text = str(exc.value)
    assert f"is in use by pid {proc.pid} (" in text and "-c" in text, text
    assert "one process only" in text
    # the holder still gets every byte
    pty.write(b"$GPGGA,1*00\r\n")
    assert proc.poll() is None
    assert proc.stdin is not None
    proc.stdin.close()
    proc.wait(DEADLINE_S)
    port = open_port(SerialSettings(url=pty.url))  # free once the holder is gone
    pty.write(b"ok")
    assert read_some(port) == b"ok"
    port.close()


def test_the_first_process_keeps_the_port() -> None:
    """This process holds the pty; another process trying it exits with our pid named."""
    with PtyPair() as pty:
        port = open_port(SerialSettings(url=pty.url))
        try:
            out = subprocess.run([sys.executable, "-c", TRY, pty.url], cwd=ROOT, env=ENV,
                                 capture_output=True, text=True, timeout=DEADLINE_S)
            assert out.returncode == 3, out.stdout + out.stderr
            assert f"is in use by pid {os.getpid()} (" in out.stdout, out.stdout
        finally:
            port.close()
        out = subprocess.run([sys.executable, "-c", TRY, pty.url], cwd=ROOT, env=ENV,
                             capture_output=True, text=True, timeout=DEADLINE_S)
        assert out.returncode == 0 and "opened" in out.stdout, out.stdout + out.stderr


def test_two_openers_in_one_process_are_refused_too() -> None:
    with PtyPair() as pty:
        port = open_port(SerialSettings(url=pty.url))
        with pytest.raises(PortError, match=rf"in use by pid {os.getpid()} \(.*this process\)"):
            open_port(SerialSettings(url=pty.url))
        port.close()


def test_a_pty_kept_open_by_its_creator_still_opens() -> None:
    """A replay (another process) creates a pty and keeps its slave open, as gpsfake does: the
    bridge opens it; only a second *reader* is refused."""
    make = ("from drivers.ptypair import PtyPair; import sys\n"
            "p = PtyPair(); print('slave', p.url, flush=True); sys.stdin.read()")
    proc = subprocess.Popen([sys.executable, "-c", make], cwd=ROOT, env=ENV,
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        path = _ready(proc, "slave").split()[1]
        port = open_port(SerialSettings(url=path))
        port.close()
    finally:
        assert proc.stdin is not None
        proc.stdin.close()
        proc.wait(DEADLINE_S)


def test_a_busy_port_is_retried_counted_and_taken_when_freed(
        holder: tuple[PtyPair, subprocess.Popen[str]], caplog: pytest.LogCaptureFixture
        ) -> None:
    """As any port that is not available: the bridge runs on, retries with backoff, counts
    the failures and takes the port when the other reader lets go."""
    pty, proc = holder
    now = [100.0]
    with caplog.at_level(logging.DEBUG, logger="fdi_bridge.port"):
        port = ResilientPort(SerialSettings(url=pty.url, timeout_s=0.0), name="gps",
                             clock=lambda: now[0])
        assert not port.up and port.open_failures == 1
        warned = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
        assert len(warned) == 1 and f"in use by pid {proc.pid}" in warned[0], warned
        now[0] += 0.1
        assert not port.service() and port.open_failures == 2
        assert proc.stdin is not None
        proc.stdin.close()
        proc.wait(DEADLINE_S)
        now[0] += 0.2
        assert port.service()
        pty.write(b"abc")
        assert port.read_some() == b"abc"
        assert port.counters()["reopens"] == 1
        assert any("is back after" in r.getMessage() for r in caplog.records)
        port.close()


@pytest.mark.parametrize("kind", ["fifo", "/dev/null", "/dev/zero", "file", "directory"])
def test_what_is_not_a_serial_port_is_refused(tmp_path: Path, kind: str) -> None:
    if kind == "fifo":
        path = tmp_path / "gps.fifo"
        os.mkfifo(path)
        expect = "is a FIFO (named pipe), not a serial port"
    elif kind == "file":
        path = tmp_path / "gps.nmea"
        path.write_bytes(b"$GPGGA\r\n")
        expect = "is a regular file, not a serial port"
    elif kind == "directory":
        path = tmp_path
        expect = "is a directory, not a serial port"
    else:
        path = Path(kind)
        expect = "is a character device but not a serial port or tty"
    with pytest.raises(PortError, match="refused") as exc:
        open_port(SerialSettings(url=str(path)))
    assert expect in str(exc.value)


def test_run_on_a_fifo_says_why_and_stops_on_ctrl_c(tmp_path: Path) -> None:
    """``fdi-bridge run`` with a FIFO as its GPS port: one clear warning, the bridge runs on
    (retrying, as for any port that is not there) and ^C stops it at once."""
    fifo = tmp_path / "gps.fifo"
    os.mkfifo(fifo)
    text = (ROOT / "config" / "rover.toml").read_text()
    assert 'url = "/dev/ttyUSB0"' in text
    cfg = tmp_path / "rover.toml"
    cfg.write_text(text.replace('url = "/dev/ttyUSB0"', f'url = "{fifo}"', 1))
    proc = subprocess.Popen([sys.executable, "-m", "firmware_host.cli", "run", "--config",
                             str(cfg)], cwd=tmp_path, env=ENV, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stderr is not None
        deadline = time.monotonic() + DEADLINE_S
        line = ""
        while time.monotonic() < deadline and "FIFO" not in line:
            ready, _, _ = select.select([proc.stderr], [], [], 0.5)
            if ready:
                line = proc.stderr.readline()
        assert "is a FIFO (named pipe), not a serial port" in line, line
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=DEADLINE_S)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0, err
    assert "internal error" not in err and "Traceback" not in err
    assert "open failures" in out


SERIAL_DEVICE = "/dev/ttyS0"
GPSD_LIKE = """
import fcntl, os, sys, termios
fd = os.open(sys.argv[1], os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
fcntl.ioctl(fd, termios.TIOCEXCL)  # what gpsd does; no flock
print("holding", flush=True)
sys.stdin.read()
"""
TIOCGEXCL = 0x80045440  # Linux >= 3.8


def _serial_device_usable() -> bool:
    try:
        fd = os.open(SERIAL_DEVICE, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    except OSError:
        return False
    try:
        return os.isatty(fd)
    finally:
        os.close(fd)


def _tty_exclusive(path: str) -> bool:
    import fcntl
    import struct

    fd = os.open(path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    try:
        return bool(struct.unpack("i", fcntl.ioctl(fd, TIOCGEXCL, b"\0" * 4))[0])
    finally:
        os.close(fd)


@pytest.mark.skipif(not _serial_device_usable(), reason=f"{SERIAL_DEVICE} cannot be opened")
def test_a_serial_device_held_by_gpsd_is_refused_even_as_root() -> None:
    """gpsd holds a serial device with TIOCEXCL and no flock, which root's open passes: the
    bridge refuses a (non-pty) device another process has open, naming it, as gpsd itself
    does ("already opened by another process"), and leaves the holder's TIOCEXCL alone."""
    proc = subprocess.Popen([sys.executable, "-c", GPSD_LIKE, SERIAL_DEVICE], cwd=ROOT,
                            env=ENV, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        _ready(proc, "holding")
        with pytest.raises(PortError, match=rf"is in use by pid {proc.pid} \("):
            open_port(SerialSettings(url=SERIAL_DEVICE, baudrate=115200))
        assert _tty_exclusive(SERIAL_DEVICE)  # the holder's TIOCEXCL is still set
    finally:
        assert proc.stdin is not None
        proc.stdin.close()
        proc.wait(DEADLINE_S)
    port = open_port(SerialSettings(url=SERIAL_DEVICE, baudrate=115200))
    try:
        assert _tty_exclusive(SERIAL_DEVICE)  # ours now: non-root openers get EBUSY
    finally:
        port.close()
    assert not _tty_exclusive(SERIAL_DEVICE)  # and cleared when we let go


def test_a_device_that_appears_held_by_another_is_reported_when_the_reason_changes(
        holder: tuple[PtyPair, subprocess.Popen[str]], tmp_path: Path,
        caplog: pytest.LogCaptureFixture) -> None:
    """Missing at start (warned once), then plugged in but held by another process: the new
    reason is warned once too (before: only at debug level), then no more while it lasts."""
    pty, proc = holder
    link = tmp_path / "gps0"  # a udev-style link, absent at start
    now = [100.0]
    with caplog.at_level(logging.DEBUG, logger="fdi_bridge.port"):
        port = ResilientPort(SerialSettings(url=str(link), timeout_s=0.0), name="gps",
                             clock=lambda: now[0], backoff_max_s=0.4)
        link.symlink_to(pty.slave_path)
        for _ in range(4):
            now[0] += 0.5
            assert not port.service()
        warned = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
        assert len(warned) == 2, warned
        assert "No such file" in warned[0]
        assert f"in use by pid {proc.pid}" in warned[1]
        assert port.open_failures == 5
        port.close()
