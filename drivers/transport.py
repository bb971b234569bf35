"""Transports: a port is a URL.

Every driver opens its link with :func:`open_port`, a thin wrapper over
``serial.serial_for_url``: ``/dev/ttyUSB0``, a pty path from a replay, ``loop://``,
``socket://host:port``, ``spy://...`` and ``rfc2217://`` are all the same to a driver.
pyserial's exceptions are translated into :class:`~fdi.errors.PortError` here, at the boundary.

A device path (a serial device, a pty) is opened **exclusively**: pyserial's ``exclusive=True``
(``flock(LOCK_EX | LOCK_NB)``, which holds across processes, root or not), so a second bridge on
the same port is refused with the holder named (:mod:`drivers.devices`) instead of silently
taking half the bytes. A serial device that is not a pty also gets what gpsd gives it:
``TIOCEXCL`` (later non-root opens fail ``EBUSY``), and the open is refused when another process
already holds the device (gpsd's "already opened by another process"; gpsd holds devices without
``flock``). A pty is exempt from these two, as in gpsd: its creator (a replay, a test harness)
keeps its slave open. A FIFO, a regular file or a character device that is not a tty is
refused before it is opened (:func:`drivers.devices.refusal`).

:class:`SerialSettings` is the typed form of a port's configuration (it is also a config table).
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import struct
import termios
from dataclasses import dataclass, field
from typing import Literal, Protocol, cast

import serial
import serial.rs485
from serial.urlhandler import protocol_socket

from drivers import devices
from fdi.errors import PortClosedError, PortError

Parity = Literal["N", "E", "O", "M", "S"]


class Port(Protocol):
    """What the drivers use of a pyserial port (any ``serial_for_url`` backend has it)."""

    @property
    def port(self) -> str | None: ...

    def read(self, size: int = 1) -> bytes: ...

    def write(self, data: bytes, /) -> int | None: ...


@dataclass(frozen=True)
class RS485Config:
    """pyserial's RS-485 driver-enable settings, for adapters that need the kernel's help."""

    rts_level_for_tx: bool = field(default=True, metadata={
        "doc": "RTS level while sending (pyserial RS485Settings)"})
    rts_level_for_rx: bool = field(default=False, metadata={"doc": "RTS level while receiving"})
    loopback: bool = field(default=False, metadata={
        "doc": "the adapter's local echo of what it sends (pyserial RS485Settings.loopback)"})
    delay_before_tx: float | None = field(default=None, metadata={
        "ge": 0.0, "le": 1.0, "unit": "s", "doc": "wait after raising RTS before sending (not "
                                                  "set: none)"})
    delay_before_rx: float | None = field(default=None, metadata={
        "ge": 0.0, "le": 1.0, "unit": "s", "doc": "wait after sending before dropping RTS (not "
                                                  "set: none)"})


@dataclass(frozen=True)
class SerialSettings:
    """A port URL and its line settings (a ``[... .port]`` table in the config)."""

    url: str = field(default="loop://", metadata={
        "doc": "the port: a device path, a pty or a pyserial URL"})
    baudrate: int = field(default=9600, metadata={
        "gt": 0, "unit": "baud", "doc": "line speed of a serial device"})
    bytesize: int = field(default=8, metadata={
        "ge": 5, "le": 8, "unit": "bits", "doc": "data bits per character"})
    parity: Parity = field(default="N", metadata={"doc": "N none, E even, O odd, M mark, S space"})
    stopbits: float = field(default=1.0, metadata={
        "ge": 1.0, "le": 2.0, "unit": "bits", "doc": "stop bits: 1, 1.5 or 2"})
    timeout_s: float = field(default=0.05, metadata={
        "ge": 0.0, "unit": "s", "doc": "a read returns after at most this long without bytes"})
    rs485: RS485Config | None = field(default=None, metadata={
        "doc": "RS-485 driver-enable settings (not set: RS-232 behaviour)"})


def open_port(
    settings: SerialSettings, *, do_not_open: bool = False, write_timeout_s: float | None = None
) -> serial.Serial:
    """Open ``settings.url`` with ``serial.serial_for_url`` (a device path exclusively, see the
    module docstring); raise :class:`PortError` on failure."""
    url = settings.url
    device = "://" not in url and bool(url)
    if device:
        reason = devices.refusal(url)
        if reason is not None:
            raise PortError(f"{url!r} {reason}: refused (a port is a serial device, a pty or "
                            "a URL such as socket://host:port)")
    try:
        # socket:// gets its exact in_waiting (_SocketPort), a device path _DevicePort, else
        # what serial_for_url picks (it too returns the URL's handler class, typed as Serial)
        port: serial.Serial
        if device:
            port = _DevicePort(None, others_refused=not devices.is_pty(url))
        elif url.lower().startswith("socket://"):
            port = cast(serial.Serial, _SocketPort(None))
        else:
            port = serial.serial_for_url(url, do_not_open=True)
        port.baudrate = settings.baudrate
        port.bytesize = settings.bytesize
        port.parity = settings.parity
        port.stopbits = settings.stopbits
        port.timeout = settings.timeout_s
        port.write_timeout = write_timeout_s
        if isinstance(port, _SocketPort | _DevicePort):
            port.port = url  # as serial_for_url does
        if settings.rs485 is not None:
            r = settings.rs485
            port.rs485_mode = serial.rs485.RS485Settings(
                rts_level_for_tx=r.rts_level_for_tx,
                rts_level_for_rx=r.rts_level_for_rx,
                loopback=r.loopback,
                delay_before_tx=r.delay_before_tx,
                delay_before_rx=r.delay_before_rx,
            )
        if not do_not_open:
            port.open()
    except (serial.SerialException, OSError, ValueError) as err:
        if device and getattr(err, "errno", None) in (errno.EAGAIN, errno.EBUSY):
            held = devices.describe(devices.holders(url))
            raise PortError(f"{url!r} is in use by {held}: a port is read by one process only "
                            "(opened exclusively, as gpsd does); stop the other reader or "
                            "choose another port") from err
        if device and getattr(err, "errno", None) == errno.ENOTTY:
            raise PortError(f"{url!r} is not a serial port or tty: {err}") from err
        raise PortError(f"could not open {url!r}: {err}") from err
    return port


class _DevicePort(serial.Serial):
    """A serial device or pty opened with ``flock`` (pyserial's ``exclusive=True``); with
    ``others_refused`` (a device that is not a pty) also refused when another process holds
    it, and ``TIOCEXCL`` while it is ours (the module docstring)."""

    def __init__(self, port: str | None, *, others_refused: bool) -> None:
        super().__init__(port, exclusive=True)
        self.others_refused = others_refused
        self._tiocexcl = False

    def open(self) -> None:
        super().open()  # takes the flock, or raises (EAGAIN) when another opener has it
        if not self.others_refused:
            return
        assert self.fd is not None and self.port is not None
        if devices.other_openers(self.port):
            self.close()
            raise serial.SerialException(errno.EBUSY, f"{self.port} is open in another process")
        with contextlib.suppress(OSError):
            fcntl.ioctl(self.fd, termios.TIOCEXCL)
            self._tiocexcl = True

    def close(self) -> None:
        if self._tiocexcl and self.is_open and self.fd is not None:
            with contextlib.suppress(OSError):  # TIOCEXCL must not outlive this descriptor
                fcntl.ioctl(self.fd, termios.TIOCNXCL)
        self._tiocexcl = False
        super().close()


class _SocketPort(protocol_socket.Serial):
    """pyserial's ``socket://`` port whose ``in_waiting`` counts the bytes the kernel holds
    (``FIONREAD``), as a serial port's does (``TIOCINQ``): pyserial's own answers 0 or 1
    (readable or not), so a reader that trusts it takes one byte a call (issue G)."""

    @property
    def in_waiting(self) -> int:
        readable = int(super().in_waiting)  # raises PortNotOpenError when closed
        if not readable:
            return 0
        try:
            held = struct.unpack("i", fcntl.ioctl(self.fileno(), termios.FIONREAD,
                                                  b"\0\0\0\0"))[0]
        except OSError:
            return readable
        return max(1, int(held))  # readable with nothing held: the peer closed; read says so


def read_some(port: Port, size: int = 4096) -> bytes:
    """Read what is there, up to ``size`` bytes: at least one byte, or nothing after the
    port's timeout.

    ``in_waiting`` is taken as a lower bound, not a count: what arrives is read on while the
    port says more is waiting, so a URL handler that reports less than it holds is still
    drained (``socket://`` is given an exact count, above). On a serial device or a pty, whose
    count is exact, this is the one read of what is waiting it always was.

    Raises :class:`PortClosedError` when the far end went away (USB unplugged, pty master
    closed), :class:`PortError` for any other failure.
    """
    try:
        waiting = int(getattr(port, "in_waiting", 0))
        # blocks up to the port's timeout when nothing is waiting
        data = bytes(port.read(min(size, waiting) if waiting else 1))
        while data and len(data) < size:
            more = int(getattr(port, "in_waiting", 0))
            if not more:
                break
            chunk = bytes(port.read(min(size - len(data), more)))
            if not chunk:
                break
            data += chunk
        return data
    except serial.SerialException as err:
        if _looks_closed(err):
            raise PortClosedError(f"{port.port}: closed by the far end: {err}") from err
        raise PortError(f"could not read from {port.port}: {err}") from err
    except OSError as err:
        if err.errno in (errno.EIO, errno.ENXIO, errno.ENODEV, errno.EBADF):
            raise PortClosedError(f"{port.port}: {err.strerror}") from err
        raise PortError(f"could not read from {port.port}: {err}") from err


def open_port_nonblocking(settings: SerialSettings) -> serial.Serial:
    """:func:`open_port` with ``write_timeout = 0``: a write takes what fits now and returns
    how much (outputs that must never block the loop: what does not fit is dropped, counted)."""
    return open_port(settings, write_timeout_s=0.0)


def write_all(port: Port, data: bytes) -> None:
    """Write ``data``; translate failures into :class:`PortError`."""
    try:
        port.write(data)
    except serial.SerialTimeoutException as err:
        raise PortError(f"write to {port.port} timed out") from err
    except (serial.SerialException, OSError) as err:
        raise PortClosedError(f"could not write to {port.port}: {err}") from err


def _looks_closed(err: Exception) -> bool:
    text = str(err)
    return (
        "returned no data" in text
        or "Input/output error" in text
        or "[Errno 5]" in text
        or "disconnected" in text
        or "[Errno 6]" in text
        or "[Errno 19]" in text
    )
