"""Port checks that open something (the spelling checks are in
:mod:`firmware_host.commands.checks`, which stays free of pyserial for a light ``--help``).

:func:`check_port_opens` opens a port once and closes it: a command that must not start
without its port (``record`` without ``--wait``, ``replay --nmea-out``) fails at start with one
line (:class:`~fdi.errors.PortError`, exit 1) instead of writing an empty capture or dropping
every byte and exiting 0.
"""

from __future__ import annotations

from drivers.transport import SerialSettings, open_port
from fdi.errors import PortError
from firmware_host.commands.checks import check_mavlink_url, check_serial_url
from firmware_host.runtime.config import BridgeConfig


def check_port_opens(url: str, option: str, baudrate: int = 9600, *, bytesize: int = 8,
                     parity: str = "N", stopbits: float = 1.0) -> None:
    """Open ``url`` with its line settings and close it; :class:`PortError` naming ``option``
    when it cannot be opened (missing device, permission denied, busy, bad URL)."""
    settings = SerialSettings(url=url, baudrate=baudrate, bytesize=bytesize,
                              parity=parity,  # type: ignore[arg-type]
                              stopbits=stopbits, timeout_s=0.0)
    try:
        port = open_port(settings)
    except PortError as err:
        raise PortError(f"{option} {url}: cannot open the port: {err}") from err
    port.close()


def output_urls(cfg: BridgeConfig, nmea_url: str | None,
                mavlink_url: str | None) -> tuple[str, str]:
    """The NMEA and MAVLink output URLs a rover command will use (the option, else the
    config's), their spelling checked (:class:`~fdi.errors.UsageError`); ``""`` for none."""
    out = cfg.rover.output
    nmea = nmea_url if nmea_url is not None else out.nmea_url
    mav = mavlink_url if mavlink_url is not None else out.mavlink_url
    if nmea:
        check_serial_url(nmea, "--nmea-out" if nmea_url is not None else "rover.output.nmea_url")
    if mav:
        check_mavlink_url(mav, "--mavlink" if mavlink_url is not None
                          else "rover.output.mavlink_url")
    return nmea or "", mav or ""
