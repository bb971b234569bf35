"""The spelling of a port's URL, checked before anything is opened: a MAVLink URL
(:func:`check_mavlink_url`) and a serial device or pyserial URL (:func:`check_serial_url`).

Each returns the URL or raises :class:`~fdi.errors.UsageError` with one line naming the option
(or config key), what was expected and what was found. The command line's checks
(:mod:`firmware_host.commands.checks`) and the configuration loader
(:mod:`firmware_host.runtime.config`) use the same functions. Only the standard library and
:mod:`fdi.errors`: ``--help`` stays light.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

from fdi.errors import UsageError

# The mavutil / MAVProxy network spellings (drivers.mavlink.links.NETWORK_SCHEMES; repeated here
# so that this module stays free of pymavlink for a light --help).
MAVLINK_SCHEMES = ("udpin", "udpout", "udp", "udpbcast", "tcp", "tcpin")
_LISTENING = ("udpin", "udp", "tcpin")
# pyserial's URL handlers (serial.urlhandler.protocol_*).
SERIAL_SCHEMES = ("loop", "socket", "rfc2217", "spy", "alt", "hwgrep", "cp2110")
_URL_SCHEME = re.compile(r"^([A-Za-z][A-Za-z0-9+.-]*)://(.*)$")


def _port_number(text: str, url: str, option: str, *, allow_zero: bool) -> int:
    try:
        port = int(text)
    except ValueError:
        raise UsageError(f"{option} {url}: port {text!r} is not a number") from None
    low = 0 if allow_zero else 1
    if not low <= port <= 65535:
        raise UsageError(f"{option} {url}: port {port} out of range {low}-65535")
    return port


def check_mavlink_url(url: str, option: str = "--mavlink") -> str:
    """A MAVLink URL as mavutil and MAVProxy spell it: ``udpout:HOST:PORT``, ``udpin:[HOST:]PORT``,
    ``tcp:HOST:PORT``, ``tcpin:[HOST:]PORT`` (port 1-65535; 0 = any free port for a server), or
    a serial device / pyserial URL (:func:`check_serial_url`) for an autopilot on a wire."""
    scheme, sep, rest = url.partition(":")
    if sep and scheme in MAVLINK_SCHEMES and not rest.startswith("//"):
        host, hsep, port_text = rest.rpartition(":")
        listening = scheme in _LISTENING
        if not hsep:
            host, port_text = "", rest
        if not host and not listening:
            raise UsageError(f"{option} {url}: expected {scheme}:HOST:PORT")
        _port_number(port_text, url, option, allow_zero=listening)
        return url
    if sep and scheme in MAVLINK_SCHEMES:
        raise UsageError(f"{option} {url}: expected {scheme}:HOST:PORT (no //)")
    try:
        return check_serial_url(url, option, pty=False)
    except UsageError as err:
        known = ", ".join(f"{s}:" for s in MAVLINK_SCHEMES)
        raise UsageError(f"{err} (a MAVLink URL is one of {known} HOST:PORT, or a serial "
                         "device)") from None


def check_serial_url(url: str, option: str = "port", *, pty: bool = True) -> str:
    """A pyserial URL (``socket://HOST:PORT``, ``loop://``, ``rfc2217://`` ...), a device path,
    or (``pty=True``, outputs) ``pty:PATH`` whose directory exists and is writable."""
    if not url:
        raise UsageError(f"{option}: empty URL")
    if url.startswith("pty:"):
        if not pty:
            raise UsageError(f"{option} {url}: pty: is for NMEA outputs only")
        link = url[4:]
        if link:
            parent = Path(link).absolute().parent
            if not parent.is_dir():
                raise UsageError(f"{option} {url}: directory {parent} does not exist")
            if not os.access(parent, os.W_OK | os.X_OK):
                raise UsageError(f"{option} {url}: directory {parent} not writable")
            if Path(link).is_dir():
                raise UsageError(f"{option} {url}: {link} is a directory")
        return url
    m = _URL_SCHEME.match(url)
    if m:
        scheme, rest = m.group(1).lower(), m.group(2)
        if scheme not in SERIAL_SCHEMES:
            known = ", ".join(f"{s}://" for s in SERIAL_SCHEMES)
            raise UsageError(f"{option} {url}: unknown URL scheme {scheme!r} (known: {known}, "
                             "a device path" + (", pty:PATH" if pty else "") + ")")
        if scheme in ("socket", "rfc2217"):
            hostport = rest.split("?", 1)[0].rstrip("/")
            host, hsep, port_text = hostport.rpartition(":")
            if not hsep or not host:
                raise UsageError(f"{option} {url}: expected {scheme}://HOST:PORT")
            _port_number(port_text, url, option, allow_zero=False)
        return url
    # A device path (/dev/ttyUSB0, /dev/serial/by-path/...:1.0-port0, COM3): not opened here.
    return url
