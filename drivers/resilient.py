"""A port that outlives its device: loss reported once, the same URL reopened with capped backoff.

:class:`ResilientPort` wraps whatever :func:`drivers.transport.open_port` returns (any pyserial
URL) and looks like a port to the drivers (``read``, ``write``, ``in_waiting``, ``port``,
``reset_input_buffer``), so :func:`drivers.transport.read_some` and
:class:`drivers.outland.link.OutlandLink` use it unchanged. Its reads and writes never raise:

* a read or write error (USB unplugged, the pty's far end closed, a socket reset) closes the
  port, is logged **once** (``... lost: ...``) and counted in ``losses``;
* while the port is down, reads return ``b""`` at once and writes are dropped and counted
  (``tx_dropped``): the vehicle is not reachable, and the caller's loop keeps running its
  failsafes;
* the same settings (the same URL: a device path, a udev symlink, a pty link) are reopened on
  the injected clock after ``backoff_min_s``, doubling up to ``backoff_max_s``; the return is
  logged once (``... back after N s``).

* a device path that is **re-pointed** while the old device stays open (a udev symlink such as
  ``/dev/gps0`` now naming another adapter, a pty link moved to a new pty) is noticed: every
  ``repoint_check_s`` of the injected clock the path's device and inode (``stat``) are compared
  with the open descriptor's (``fstat``); when they differ the port is reopened at once on the
  new device, logged once (``... now names another device; reopening``) and counted
  (``repoints``). A path that is missing is left to the reads (they fail when the device goes).

Every byte read and written goes to the ``on_rx``/``on_tx`` taps (the flight recorder).
"""

from __future__ import annotations

import logging
import os
import re
import stat
import time
from collections.abc import Callable
from typing import Any

from drivers.transport import Port, SerialSettings, open_port, read_some
from fdi.errors import PortError

log = logging.getLogger("fdi_bridge.port")

Tap = Callable[[bytes], None]
Opener = Callable[[SerialSettings], Any]


class ResilientPort:
    """See the module docstring. ``name`` is used in the log lines (``gps``, ``rov link``)."""

    def __init__(
        self,
        settings: SerialSettings,
        *,
        name: str = "port",
        backoff_min_s: float = 0.1,
        backoff_max_s: float = 5.0,
        clock: Callable[[], float] = time.monotonic,
        opener: Opener = open_port,
        on_rx: Tap | None = None,
        on_tx: Tap | None = None,
        logger: logging.Logger = log,
        repoint_check_s: float = 1.0,
    ) -> None:
        if backoff_min_s <= 0 or backoff_max_s < backoff_min_s:
            raise ValueError("need 0 < backoff_min_s <= backoff_max_s")
        self.settings = settings
        self.name = name
        self.backoff_min_s = backoff_min_s
        self.backoff_max_s = backoff_max_s
        self.clock = clock
        self.opener = opener
        self.on_rx = on_rx
        self.on_tx = on_tx
        self.log = logger
        self.repoint_check_s = repoint_check_s
        self._path = _device_path(settings.url)
        self._identity: tuple[int, int] | None = None  # (st_dev, st_ino) of what is open
        self._next_check = clock()
        self._port: Any = None
        self._backoff = backoff_min_s
        self._next_attempt = clock()
        self._down_since: float | None = None
        self._open_reason = ""  # the last open failure's kind (a new one is logged once)
        self._closed = False
        # Counters.
        self.bytes_rx = 0
        self.bytes_tx = 0
        self.tx_dropped = 0
        self.losses = 0
        self.reopens = 0
        self.repoints = 0
        self.open_attempts = 0
        self.open_failures = 0
        self.service()
        if self._port is None and self._down_since is None:
            self._down_since = clock()

    # ------------------------------------------------------------------ state

    @property
    def up(self) -> bool:
        return self._port is not None

    @property
    def port(self) -> str:
        """The URL (what pyserial calls ``port``)."""
        return self.settings.url

    def wait_s(self) -> float:
        """Seconds until the next reopen attempt (0 when the port is up or one is due)."""
        if self._port is not None:
            return 0.0
        return max(0.0, self._next_attempt - self.clock())

    def service(self) -> bool:
        """Try to (re)open when down and an attempt is due; return whether the port is up."""
        if self._port is not None or self._closed:
            return self._port is not None
        now = self.clock()
        if now < self._next_attempt:
            return False
        self.open_attempts += 1
        try:
            self._port = self.opener(self.settings)
        except PortError as err:
            self.open_failures += 1
            reason = re.sub(r"\d+", "#", str(err))  # the kind of failure, not its numbers
            if self.open_attempts == 1 and self.losses == 0:
                self.log.warning("%s: %s; retrying with backoff up to %.1f s", self.name, err,
                                 self.backoff_max_s)
            elif self.open_attempts > 1 and reason != self._open_reason:
                # a new reason (the device is back but another process holds it): say so once
                self.log.warning("%s: still down: %s", self.name, err)
            else:
                self.log.debug("%s: still down: %s", self.name, err)
            self._open_reason = reason
            self._next_attempt = now + self._backoff
            self._backoff = min(2.0 * self._backoff, self.backoff_max_s)
            return False
        self._identity = self._open_identity()
        self._next_check = now + self.repoint_check_s
        if self._down_since is not None and (self.losses or self.open_failures):
            self.reopens += 1
            self.log.warning("%s: %s is back after %.1f s (%d attempts)", self.name,
                             self.settings.url, now - self._down_since, self.open_attempts)
        self._down_since = None
        self._backoff = self.backoff_min_s
        return True

    def _open_identity(self) -> tuple[int, int] | None:
        """(st_dev, st_ino) of the open descriptor, when the URL is a device path."""
        if self._path is None:
            return None
        try:
            st = os.fstat(int(self._port.fileno()))
        except (AttributeError, OSError, TypeError, ValueError):
            try:
                st = os.stat(self._path)
            except OSError:
                return None
        return (st.st_dev, st.st_ino)

    def _check_repoint(self) -> None:
        """Reopen when the path now names another device than the open one (see the module
        docstring); cheap: one ``stat`` every ``repoint_check_s``."""
        if self._identity is None or self._port is None:
            return
        now = self.clock()
        if now < self._next_check:
            return
        self._next_check = now + self.repoint_check_s
        try:
            st = os.stat(self._path)  # type: ignore[arg-type]
        except OSError:
            return  # gone: the reads will report it if the device went with it
        if not stat.S_ISCHR(st.st_mode) or (st.st_dev, st.st_ino) == self._identity:
            return
        self.repoints += 1
        self.log.warning("%s: %s now names another device; reopening it", self.name,
                         self.settings.url)
        port, self._port = self._port, None
        try:
            port.close()
        except Exception:
            self.log.debug("%s: close of the old device failed", self.name, exc_info=True)
        self._down_since = now
        self.open_attempts = 0
        self._next_attempt = now
        self._backoff = self.backoff_min_s
        self.service()

    def _lost(self, err: Exception) -> None:
        self.losses += 1
        self.log.warning("%s: %s lost: %s; reopening with backoff up to %.1f s", self.name,
                         self.settings.url, err, self.backoff_max_s)
        port, self._port = self._port, None
        try:
            port.close()
        except Exception:  # a vanished device may fail to close; it is gone either way
            self.log.debug("%s: close after loss failed", self.name, exc_info=True)
        now = self.clock()
        self._down_since = now
        self.open_attempts = 0
        self._backoff = self.backoff_min_s
        self._next_attempt = now + self.backoff_min_s

    # ------------------------------------------------------------------ the port interface

    @property
    def in_waiting(self) -> int:
        if self._port is None:
            return 0
        try:
            return int(getattr(self._port, "in_waiting", 0))
        except Exception as err:  # serial.SerialException, OSError: the device went away
            self._lost(err)
            return 0

    def read(self, size: int = 1) -> bytes:
        self._check_repoint()
        if self._port is None and not self.service():
            return b""
        try:
            data = bytes(self._port.read(size))
        except Exception as err:  # translated here, at the boundary: a read never raises
            self._lost(err)
            return b""
        if data:
            self.bytes_rx += len(data)
            if self.on_rx is not None:
                self.on_rx(data)
        return data

    def read_some(self, size: int = 65536) -> bytes:
        """What is waiting (see :func:`drivers.transport.read_some`); ``b""`` while down."""
        self._check_repoint()
        if self._port is None and not self.service():
            return b""
        return read_some(self, size)

    def write(self, data: bytes, /) -> int | None:
        """Bytes written: all of them, or what a non-blocking port took (``write_timeout=0``)."""
        self._check_repoint()
        if self._port is None and not self.service():
            self.tx_dropped += len(data)
            return 0
        try:
            n = self._port.write(data)
        except Exception as err:
            self._lost(err)
            self.tx_dropped += len(data)
            return 0
        n = len(data) if n is None else int(n)
        self.bytes_tx += n
        if self.on_tx is not None and n:
            self.on_tx(data[:n])
        return n

    def fileno(self) -> int:
        """The open port's descriptor (to wait on); OSError while the port is down."""
        if self._port is None:
            raise OSError("port is down")
        return int(self._port.fileno())

    def reset_input_buffer(self) -> None:
        if self._port is None:
            return
        reset = getattr(self._port, "reset_input_buffer", None)
        if reset is None:
            return
        try:
            reset()
        except Exception as err:
            self._lost(err)

    def close(self) -> None:
        self._closed = True
        if self._port is not None:
            port, self._port = self._port, None
            try:
                port.close()
            except Exception:
                self.log.debug("%s: close failed", self.name, exc_info=True)

    def counters(self) -> dict[str, int]:
        return {
            "bytes_rx": self.bytes_rx,
            "bytes_tx": self.bytes_tx,
            "tx_dropped": self.tx_dropped,
            "losses": self.losses,
            "reopens": self.reopens,
            "repoints": self.repoints,
            "open_failures": self.open_failures,
        }


def _device_path(url: str) -> str | None:
    """The filesystem path of a URL that names a device (``/dev/ttyUSB0``, a pty link), else
    None (``loop://``, ``socket://host:port``, ``rfc2217://`` ...)."""
    if "://" in url or not url:
        return None
    return url


def _is_port(p: ResilientPort) -> Port:  # mypy: a ResilientPort is a drivers.transport.Port
    return p
