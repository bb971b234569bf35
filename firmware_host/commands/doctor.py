"""``fdi-bridge doctor [--config FILE]``: start-up checks, a clear list of what is wrong.

Without ``--config`` it lists the system's serial ports (check 2) and stops there: what a field
engineer wants first, before any file names the receiver's port.

Checks, in order:

1. the configuration file loads and validates exactly as ``fdi-bridge run --config`` loads it
   (:func:`~firmware_host.runtime.config.load_bridge_file`, then ``run_mode``):
   which vehicle it is (``[rover]`` or ``[rov]``) or whether it runs the router (``[mavlink]``);
2. the serial ports the system has (``serial.tools.list_ports``);
3. every configured port: a device path exists, is a character device, and this user can read
   and write it; if not, which group owns it (``dialout`` on Debian/Ubuntu, ``uucp`` on Arch)
   and the command to join it. URLs with a scheme (``socket://``, ``rfc2217://``, ``loop://``)
   are parsed, not opened; ``pty:PATH`` outputs need a writable directory;
4. the MAVLink endpoints: the URL parses (``udpout:HOST:PORT``, ``udpin:[HOST:]PORT``,
   ``tcp:HOST:PORT``, ``tcpin:[HOST:]PORT``, or a device); a listening UDP port is test-bound on
   127.0.0.1 only (never on a public interface) to find a port already in use;
5. the flight recorder's directory: it exists or can be created, is writable, and its disk has
   room for the configured cap;
6. the GPS receiver, read for ``--gps-probe-s`` seconds: whether its sentences at its rate fit
   the port's baud rate (a warning naming the largest rate that fits, :mod:`drivers.gps.link`);
   with a MAVLink output, its rate (a warning below 5 Hz: ArduPilot's ``AP_GPS::is_healthy``
   wants a fix at least every ~215 ms); with a
   ``[mavlink]`` table, the tlog directory and the parameter file's directory are writable and
   have room (a full disk stops them, not forwarding);
7. an ROV: whether its heading FDI has a gyro witness; without one (the Outland link, or
   ``[rov.ardusub] gyro = "none"``) a warning "compass only: slow drifts are not detectable".

:func:`diagnose` returns a :class:`Report`; only :func:`run` prints. Exit status 1 when
anything is wrong, 0 otherwise (warnings do not fail).
"""

from __future__ import annotations

import argparse
import grp
import itertools
import json
import os
import shutil
import socket
import stat
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from serial.tools import list_ports

from drivers.gps.link import LinkFit, bits_per_byte
from drivers.gps.stream import NmeaStream
from drivers.mavlink.links import is_network_url
from drivers.transport import SerialSettings, open_port
from fdi.errors import ConfigError, FdiBridgeError
from firmware_host.commands.tables import table
from firmware_host.runtime.config import load_bridge_file, run_mode
from firmware_host.runtime.config_mavlink import MavlinkConfig
from firmware_host.runtime.config_rov import COMPASS_ONLY, RovConfig, rov_gyro

_SCHEMES = ("socket://", "rfc2217://", "loop://", "spy://", "alt://", "hwgrep://", "cp2110://")


@dataclass
class Report:
    ok: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)
    ports: list[str | dict[str, str]] = field(default_factory=list)

    def port_rows(self) -> list[dict[str, str]]:
        """Each system port as device / description / hwid (``-`` where pyserial has n/a)."""
        rows = []
        for p in self.ports:
            d = p if isinstance(p, dict) else {"device": p}
            rows.append({k: (d.get(k) or "-").replace("n/a", "-")
                         for k in ("device", "description", "hwid")})
        return rows

    def as_dict(self) -> dict[str, Any]:
        return {"ports": self.port_rows(), "ok": self.ok, "warnings": self.warnings,
                "problems": self.problems}

    def lines(self) -> list[str]:
        out = ["serial ports on this system:"]
        rows = self.port_rows()
        if rows:
            out.append(table(["DEVICE", "DESCRIPTION", "HWID"],
                             [[r["device"], r["description"], r["hwid"]] for r in rows],
                             indent="  "))
        else:
            out.append("  (none found)")
        out.append("")
        if not (self.ok or self.warnings or self.problems):
            out.append("no configuration checked (--config FILE checks one)")
            return out
        out += [f"ok       {m}" for m in self.ok]
        out += [f"warning  {m}" for m in self.warnings]
        out += [f"PROBLEM  {m}" for m in self.problems]
        if self.problems:
            out.append(f"{len(self.problems)} problem(s): the bridge will not run as configured")
        else:
            out.append("no problems found")
        return out


def _system_ports() -> list[str | dict[str, str]]:
    """The system's serial ports as ``python -m serial.tools.list_ports -v`` lists them."""
    return [{"device": p.device, "description": p.description or "", "hwid": p.hwid or ""}
            for p in sorted(list_ports.comports(), key=lambda p: p.device)]


def check_device(
    rep: Report,
    role: str,
    url: str,
    *,
    access: Callable[[str, int], bool] = os.access,
    groups: Callable[[], list[int]] = os.getgroups,
) -> None:
    """A configured port: exists, character device, readable and writable (see module doc)."""
    if not url:
        return
    if url.startswith(_SCHEMES):
        rep.ok.append(f"{role}: {url} is a URL (not a device; opened at run time)")
        return
    if url.startswith("pty:"):
        parent = Path(url[4:]).parent if url[4:] else Path("/tmp")
        if parent.is_dir() and access(str(parent), os.W_OK | os.X_OK):
            rep.ok.append(f"{role}: {url}: a pty will be linked in {parent}")
        else:
            rep.problems.append(f"{role}: {url}: cannot create the link in {parent}")
        return
    path = Path(url)
    if not path.exists():
        dangling = " (a symlink to a missing device)" if path.is_symlink() else ""
        rep.problems.append(f"{role}: {url} does not exist{dangling}: is the adapter plugged "
                            "in? (the bridge waits and reopens it, but check the name)")
        return
    st = path.stat()
    if not stat.S_ISCHR(st.st_mode):
        rep.warnings.append(f"{role}: {url} is not a character device (a serial port is)")
    if access(url, os.R_OK | os.W_OK):
        rep.ok.append(f"{role}: {url} exists, readable and writable")
        return
    try:
        group = grp.getgrgid(st.st_gid).gr_name
    except KeyError:
        group = str(st.st_gid)
    if st.st_gid in groups():
        rep.problems.append(f"{role}: {url}: not readable and writable although you are in "
                            f"group {group} (mode {stat.filemode(st.st_mode)}): check its "
                            "permissions (udev rule)")
    else:
        rep.problems.append(f"{role}: {url}: not readable and writable by this user: join group "
                            f"{group!r} (sudo usermod -aG {group} $USER, then log in again)")


def check_mavlink_url(rep: Report, role: str, url: str) -> None:
    """Parse a MAVLink URL; test-bind a listening UDP port on 127.0.0.1 only."""
    if not url:
        return
    if not is_network_url(url):
        check_device(rep, role, url)  # a serial device for the autopilot
        return
    scheme, _sep, rest = url.partition(":")
    host, _, port_text = rest.rpartition(":")
    listening = scheme in ("udpin", "udp", "tcpin")
    if not host and not listening:
        rep.problems.append(f"{role}: {url}: expected {scheme}:HOST:PORT")
        return
    try:
        port = int(port_text)
    except ValueError:
        rep.problems.append(f"{role}: {url}: port {port_text!r} is not a number")
        return
    if not 0 <= port <= 65535 or (port == 0 and not listening):
        rep.problems.append(f"{role}: {url}: port {port} out of range")
        return
    if scheme in ("udpin", "udp") and port:
        # Only ever on 127.0.0.1: a socket already bound to the port (on any address, without
        # SO_REUSEADDR) makes this fail, which is what we want to know.
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            try:
                s.bind(("127.0.0.1", port))
            except OSError as err:
                rep.problems.append(f"{role}: {url}: UDP port {port} is already in use "
                                    f"({err.strerror}): another MAVLink program?")
                return
    rep.ok.append(f"{role}: {url} parses" + (" (UDP port free on 127.0.0.1)"
                                             if scheme in ("udpin", "udp") and port else ""))


def check_recorder(rep: Report, directory: str, dir_max_mb: float, file_max_mb: float,
                   access: Callable[[str, int], bool] = os.access) -> None:
    if not directory:
        rep.warnings.append("recorder: off (no [recorder] dir, no --record): nothing will be "
                            "kept for a replay after an incident")
        return
    d = Path(directory)
    probe = d
    while not probe.exists():
        if probe.parent == probe:
            break
        probe = probe.parent
    if probe.exists() and not probe.is_dir():
        rep.problems.append(f"recorder: {directory}: {probe} is not a directory")
        return
    if not access(str(probe), os.W_OK | os.X_OK):
        what = "is not writable" if probe == d else f"cannot be created ({probe} not writable)"
        rep.problems.append(f"recorder: {directory} {what} by this user")
        return
    free_mb = shutil.disk_usage(probe).free / 1e6
    if free_mb < dir_max_mb:
        rep.warnings.append(f"recorder: {directory}: {free_mb:.0f} MB free, less than the cap "
                            f"dir_max_mb = {dir_max_mb:g}: the disk fills first")
    if file_max_mb > dir_max_mb:
        rep.warnings.append("recorder: file_max_mb > dir_max_mb: only one file will be kept")
    rep.ok.append(f"recorder: {directory} writable ({free_mb:.0f} MB free, cap "
                  f"{dir_max_mb:g} MB)")


GPS_HEALTHY_PERIOD_S = 0.215  # ArduPilot AP_GPS::is_healthy: updates faster than this


def check_gps_rate(rep: Report, url: str, baudrate: int, seconds: float,
                   opener: Callable[..., Any] | None = None, *, bits: float = 10.0,
                   autopilot: bool = True) -> None:
    """Read the receiver for ``seconds``; warn when its sentences at its rate do not fit
    ``baudrate`` (:mod:`drivers.gps.link`: the largest rate that fits, the fixes), and, with
    an ``autopilot`` (a MAVLink output), when its epochs are slower than ArduPilot's GPS health
    check accepts (a 1 Hz receiver feeding GPS_INPUT). A port that cannot be opened (in use by
    the running bridge, absent) is skipped: the device check reports it."""
    try:
        port = (opener or open_port)(SerialSettings(url=url, baudrate=baudrate, timeout_s=0.1))
    except (FdiBridgeError, OSError, ValueError):
        return
    stream = NmeaStream()
    times: list[float] = []
    kinds: tuple[str, ...] = ()
    first_bytes: int | None = None  # bytes_in when the first epoch closed
    last_bytes = 0
    try:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            data = port.read(4096)
            for e in stream.feed(data or b""):
                if e.utc_s is not None:
                    times.append(e.utc_s)
                    kinds = e.sentences
                    if first_bytes is None:
                        first_bytes = stream.bytes_in
                    last_bytes = stream.bytes_in
    except (OSError, ValueError) as err:
        rep.warnings.append(f"GPS rate: could not read {url}: {err}")
        return
    finally:
        port.close()
    gaps = sorted(b - a for a, b in itertools.pairwise(times) if b > a)
    if not gaps:
        if autopilot:
            rep.warnings.append(f"GPS rate: fewer than two epochs from {url} in {seconds:g} s")
        return
    period = gaps[len(gaps) // 2]
    if len(times) >= 3 and first_bytes is not None and last_bytes > first_bytes:
        fit = LinkFit(baudrate, (last_bytes - first_bytes) / (len(times) - 1), 1.0 / period,
                      kinds, bits)
        if not fit.fits:
            rep.warnings.append(fit.message())
        else:
            rep.ok.append(f"GPS link: {fit.need_bytes_s:.0f} B/s of {fit.capacity_bytes_s:.0f} "
                          f"at {baudrate} baud ({fit.load:.0%})")
    if not autopilot:
        return
    if period > GPS_HEALTHY_PERIOD_S:
        rep.warnings.append(
            f"GPS rate: the receiver sends a fix every {period:.2f} s ({1 / period:.1f} Hz); "
            f"ArduPilot's GPS health check wants one every {GPS_HEALTHY_PERIOD_S * 1000:.0f} ms "
            "or faster (5 Hz or more): set the receiver to 5-10 Hz or GPS_INPUT is unhealthy")
    else:
        rep.ok.append(f"GPS rate: {1 / period:.1f} Hz")


def check_mavlink_disk(rep: Report, mc: MavlinkConfig) -> None:
    """The ``[mavlink]`` tlog directory and parameter file: writable, with room."""
    places = [("tlog", Path(mc.tlog_dir), mc.tlog_min_free_bytes + mc.tlog_max_bytes)
              if mc.tlog_dir else None,
              ("parameter file", Path(mc.param_file).parent, 4096) if mc.param_file else None]
    for place in places:
        if place is None:
            continue
        what, d, need = place
        probe = d
        while not probe.exists() and probe != probe.parent:
            probe = probe.parent
        if not os.access(probe, os.W_OK):
            rep.warnings.append(f"mavlink {what}: {d} is not writable: it will not be written "
                                "(forwarding goes on)")
            continue
        free = shutil.disk_usage(probe).free
        if free < need:
            rep.warnings.append(f"mavlink {what}: {free / 1e6:.1f} MB free at {d}, less than "
                                f"{need / 1e6:.1f} MB: it pauses until space returns")
        else:
            rep.ok.append(f"mavlink {what}: {d} writable ({free / 1e6:.0f} MB free)")


def check_rov_gyro(rep: Report, rov: RovConfig) -> None:
    """What the ROV's heading FDI can detect: with a gyro witness, or the compass alone."""
    gyro = rov_gyro(rov)
    if gyro is not None:
        rep.ok.append(f"rov: heading FDI with a gyro witness ({gyro})")
        return
    if not rov.ft.gyro_enabled:
        why = "[rov.ft] gyro_enabled = false"
    elif rov.heading_source == "outland":
        why = "the Outland link carries no gyro"
    else:
        why = '[rov.ardusub] gyro = "none"; the link carries one: "attitude" or "imu"'
    rep.warnings.append(f"rov: {COMPASS_ONLY} ({why}; docs/rov.md)")


def diagnose(
    config: str | Path | None,
    *,
    mavlink_url: str | None = None,
    record_dir: str | None = None,
    list_ports: Callable[[], Sequence[str | dict[str, str]]] = _system_ports,
    access: Callable[[str, int], bool] = os.access,
    gps_probe_s: float = 0.0,
) -> Report:
    rep = Report()
    try:
        rep.ports = list(list_ports())
    except Exception as err:  # a broken sysfs must not hide the other checks
        rep.warnings.append(f"could not list serial ports: {err}")
    if config is None:  # the ports only
        return rep
    try:
        bf = load_bridge_file(config)  # what `run --config` reads, with the same checks
        mode = run_mode(bf)
    except (ConfigError, FdiBridgeError, ValueError) as err:
        rep.problems.append(f"config: {err}")
        return rep
    tables = "" if bf.sections == (mode,) else f"; tables {', '.join(bf.sections)}"
    rep.ok.append(f"config: {bf.path} loads ({mode}{tables})")
    if bf.rover is not None and mode != "rov":
        rc = bf.rover
        check_device(rep, "GPS input", rc.port.url, access=access)
        check_device(rep, "NMEA output", rc.output.nmea_url, access=access)
        check_mavlink_url(rep, "MAVLink output", mavlink_url or rc.output.mavlink_url)
        if mode == "rover" and not (mavlink_url or rc.output.mavlink_url or rc.output.nmea_url):
            rep.warnings.append("no output configured (rover.output nmea_url / mavlink_url): "
                                "corrected data goes nowhere")
    if bf.rov is not None:
        if bf.rov.heading_source == "mavlink":
            rep.ok.append("rov: heading from the autopilot (ATTITUDE through [mavlink])")
            check_rov_gyro(rep, bf.rov)
        elif mode == "mavlink":
            rep.warnings.append("rov: `run` on a file with [mavlink] runs the router and the "
                                "rover only; the [rov] table is not used")
        else:
            check_device(rep, "ROV link", bf.rov.link.port.url, access=access)
            check_rov_gyro(rep, bf.rov)
    if bf.mavlink is not None:
        mc = bf.mavlink
        check_mavlink_url(rep, "MAVLink autopilot", mc.autopilot.url)
        for i, gcs in enumerate(mc.gcs):
            check_mavlink_url(rep, f"MAVLink gcs {gcs.name or i}", gcs.url)
        check_mavlink_disk(rep, mc)
    if gps_probe_s > 0 and bf.rover is not None and mode != "rov":
        gp = bf.rover.port
        check_gps_rate(rep, gp.url, gp.baudrate, gps_probe_s,
                       bits=bits_per_byte(gp.bytesize, gp.parity, gp.stopbits),
                       autopilot=bool(bf.mavlink is not None or mavlink_url
                                      or bf.rover.output.mavlink_url))
    rc_rec = bf.recorder
    check_recorder(rep, record_dir if record_dir is not None else rc_rec.dir,
                   rc_rec.dir_max_mb, rc_rec.file_max_mb, access=access)
    return rep


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--config", default=None,
                        help="config file or preset name (without: list the serial ports only)")
    parser.add_argument("--gps-probe-s", type=float, default=3.0,
                        help="read the GPS this long to check that its rate fits the baud rate "
                             "(and, with a MAVLink output, ArduPilot's health check) "
                             "(0: do not)")
    parser.add_argument("--mavlink", default=None,
                        help="the MAVLink URL `run` will be given (default: the config's)")
    parser.add_argument("--record", default=None,
                        help="the recorder directory `run` will use (default: the config's)")
    parser.add_argument("--json", action="store_true",
                        help="print the ports and the checks as one JSON object")


def run(args: argparse.Namespace) -> int:
    rep = diagnose(args.config, mavlink_url=args.mavlink, record_dir=args.record,
                   gps_probe_s=args.gps_probe_s)
    if args.json:
        print(json.dumps(rep.as_dict()))
    else:
        for line in rep.lines():
            print(line)
    return 1 if rep.problems else 0
