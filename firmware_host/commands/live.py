"""How ``fdi-bridge run`` (and ``mavlink`` with a vehicle) shows itself: the start banner, the
live status and the end summary.

* :class:`ConsoleStatus` is the :class:`~firmware_host.runtime.status.StatusSink` the commands
  give the :class:`~firmware_host.runtime.runner.Runner`: the banner on stderr; on a terminal
  one refreshing status line (``\\r``, as ``gpsmon`` and MAVProxy keep theirs), elsewhere (the
  systemd journal, a pipe) the same line as an INFO log record once a minute;
* :func:`run_summary_text` is the human end summary (an aligned table,
  :mod:`firmware_host.commands.tables`); ``--json`` prints the summary instead.
"""

from __future__ import annotations

import logging
import shutil
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, TextIO

import firmware_host
from firmware_host.commands.tables import fields, fmt, table
from firmware_host.runtime.config import BridgeFile, presets_dir
from firmware_host.runtime.config_rov import COMPASS_ONLY, rov_gyro
from firmware_host.runtime.status import AutopilotView, Banner, Snapshot

log = logging.getLogger("fdi_bridge.status")

LOG_EVERY_S = 60.0
HEARTBEAT_LOST_S = 3.0  # three 1 Hz heartbeats missed: the autopilot is not there
# GPS_RAW_INT's fix_type (MAVLink GPS_FIX_TYPE), as short as cgps shows it
GPS_FIX_NAMES = {0: "no GPS", 1: "no fix", 2: "2D", 3: "3D", 4: "DGPS", 5: "RTK float",
                 6: "RTK fixed", 7: "static", 8: "PPP"}

def _rate(bps: float) -> str:
    """Fixed decimals, so that the refreshing line does not jitter."""
    if bps >= 1000.0:
        return f"{bps / 1000.0:.2f} kB/s"
    return f"{bps:.0f} B/s"


def _age(s: float | None) -> str:
    if s is None:
        return "none yet"
    return f"{s:.1f} s ago"


def _clock(s: float) -> str:
    s = max(0, int(s))
    return f"{s // 3600:d}:{s // 60 % 60:02d}:{s % 60:02d}"


def status_line(s: Snapshot) -> str:
    """``0:01:05 epochs 650 faults 3 alarms 1 | gps up 812 B/s | last epoch 0.1 s ago`` (the
    last epoch is the rover's last fix, the ROV's last control step), then the vehicle's
    ``detail`` (the rover: ``| DGPS 9sv HDOP 0.8 +0.3E +13.3N m 2.0 m/s | out accept DGPS
    0.49 m | GGA+RMC+VTG``, its fix as cgps shows one)."""
    head = [_clock(s.elapsed_s), f"epochs {s.epochs}"]
    if s.faults is not None:
        head.append(f"faults {s.faults}")
    if s.alarms is not None:
        head.append(f"alarms {s.alarms}")
    head += [f"{k} {fmt(v)}" for k, v in s.extra.items()]
    parts = [" ".join(head)]
    for p in s.ports:
        if p.up:
            rate = _rate(p.rx_bps) + (f" tx {_rate(p.tx_bps)}" if p.tx_bps > 0 else "")
            parts.append(f"{p.name} up {rate}")
        else:
            since = "" if p.down_s is None else f" {p.down_s:.1f} s"
            parts.append(f"{p.name} WAITING{since}")
    parts.append(f"last epoch {_age(s.last_record_age_s)}")
    parts += s.detail
    if s.autopilot is not None:
        parts.append(autopilot_text(s.autopilot))
    return " | ".join(parts)


def autopilot_text(a: AutopilotView) -> str:
    """``autopilot hb 0.4 s echo 3D 10sv``: the autopilot's last heartbeat and its GPS_RAW_INT
    (its own view of the fix we sent), ``autopilot SILENT 12 s`` past :data:`HEARTBEAT_LOST_S`,
    ``autopilot no heartbeat`` before the first; the echo's age when it is older than that."""
    age = a.heartbeat_age_s
    if age is None:
        text = "autopilot no heartbeat"
    elif age > HEARTBEAT_LOST_S:
        text = f"autopilot SILENT {age:.0f} s"
    else:
        text = f"autopilot hb {age:.1f} s"
    if a.gps_fix_type is not None:
        kind = GPS_FIX_NAMES.get(a.gps_fix_type, str(a.gps_fix_type))
        text += f" echo {kind} {a.gps_sats}sv"
        if a.gps_age_s is not None and a.gps_age_s > HEARTBEAT_LOST_S:
            text += f" {a.gps_age_s:.0f} s ago"
    elif age is not None:
        text += " no GPS_RAW_INT"
    return text


def banner_lines(b: Banner) -> list[tuple[str, str]]:
    """The banner as (label, text) rows: vehicle, each port, outputs, recorder, router links,
    the run's files."""
    rows: list[tuple[str, str]] = [("vehicle", b.vehicle)]
    for p in b.ports:
        rows.append((f"port {p.name}", f"{p.url} at {p.baudrate} baud"))
    rows.append(("outputs", ", ".join(b.outputs) if b.outputs else "none"))
    rows.append(("recorder", b.recorder or "off"))
    for link in b.router:
        rows.append(("router", link))
    rows.append(("records", f"{b.out_dir}/epochs.jsonl, summary.json" if b.out_dir
                 else "none (--out DIR to keep them)"))
    rows.append(("stop", f"after {fmt(b.duration_s)} s or ^C" if b.duration_s
                 else "^C or SIGTERM"))
    return rows


def _is_tty(stream: TextIO) -> bool:
    isatty = getattr(stream, "isatty", None)
    return bool(isatty and isatty())


class ConsoleStatus:
    """The banner and the live status on ``stream`` (stderr). ``header`` rows come first in
    the banner (the command's: version, config file and preset). ``tty`` defaults to whether
    ``stream`` is a terminal; ``quiet`` (``-q``) shows neither banner nor status."""

    def __init__(self, header: list[tuple[str, str]] | None = None, *,
                 stream: TextIO | None = None, tty: bool | None = None, quiet: bool = False,
                 log_every_s: float = LOG_EVERY_S,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.stream = stream if stream is not None else sys.stderr
        self.tty = _is_tty(self.stream) if tty is None else tty
        self.header = header or []
        self.quiet = quiet
        self.log_every_s = log_every_s
        self.clock = clock
        self._next_log: float | None = None
        self._shown = False
        self.last_line = ""
        self._handlers: list[logging.Handler] = []

    def banner(self, banner: Banner) -> None:
        if self.quiet:
            return
        rows = [*self.header, *banner_lines(banner)]
        width = max(len(k) for k, _ in rows)
        text = "\n".join(f"  {k.ljust(width)}  {v}" for k, v in rows)
        self.stream.write(f"fdi-bridge {firmware_host.__version__}: running\n{text}\n")
        self.stream.flush()

    def update(self, snapshot: Snapshot) -> None:
        line = self.last_line = status_line(snapshot)
        if self.quiet:
            return
        if self.tty:
            if not self._handlers:
                self._hook_logging()
            cols = shutil.get_terminal_size((120, 24)).columns
            self.stream.write("\r" + line[: max(20, cols - 1)] + "\x1b[K")
            self.stream.flush()
            self._shown = True
            return
        now = self.clock()
        if self._next_log is None:
            self._next_log = now + self.log_every_s  # the first a minute after the start
        elif now >= self._next_log:
            self._next_log = now + self.log_every_s
            log.info("status %s", line)

    def filter(self, record: logging.LogRecord) -> bool:
        """A log record on the terminal: clear the status line first (the next update
        draws it again), so that the two never share a line."""
        if self._shown:
            self.stream.write("\r\x1b[K")
            self._shown = False
        return True

    def _hook_logging(self) -> None:
        for h in logging.getLogger().handlers:
            if getattr(h, "stream", None) is self.stream:
                h.addFilter(self)
                self._handlers.append(h)

    def close(self) -> None:
        """End the refreshing line (the summary starts on its own line)."""
        for h in self._handlers:
            h.removeFilter(self)
        self._handlers = []
        if self._shown:
            self.stream.write("\n")
            self.stream.flush()
            self._shown = False


def console_status(config: str | Path | None, bf: BridgeFile) -> ConsoleStatus:
    """The banner and live status of a run on stderr (nothing with ``-q``)."""
    header: list[tuple[str, str]] = []
    if bf.path is not None:
        preset = bf.path.parent.resolve() == presets_dir().resolve()
        header.append(("config", f"{bf.path}" + (f" (preset {bf.path.stem})" if preset else "")))
    elif config:
        header.append(("config", str(config)))
    if bf.name:
        header.append(("name", bf.name))
    if bf.rov is not None and bf.rover is None:  # the ROV runs: what its FDI can see
        gyro = rov_gyro(bf.rov)
        header.append(("heading FDI", COMPASS_ONLY if gyro is None
                       else f"compass FIR + gyro witness ({gyro})"))
    quiet = logging.getLogger().getEffectiveLevel() > logging.WARNING
    return ConsoleStatus(header, quiet=quiet)


def _counts(d: Any) -> str:
    if not isinstance(d, dict) or not d:
        return "-"
    return ", ".join(f"{k} {fmt(v)}" for k, v in d.items())


def run_summary_text(s: dict[str, Any]) -> str:
    """The end summary of a run for a human: what stopped it, the counters, one row a port."""
    rt = s.get("runtime", {})
    rows: list[tuple[str, Any, str]] = [
        ("vehicle", s.get("vehicle"), ""),
        ("stopped by", rt.get("stopped_by"), f"after {fmt(rt.get('elapsed_s'))} s"),
    ]
    if "epochs" in s:
        rows.append(("epochs", s.get("epochs"), ""))
    for key, unit in (("faults", "epochs flagged"), ("alarms", "")):
        if key in s:
            rows.append((key, s[key], unit))
    if "actions" in s:
        rows.append(("actions", _counts(s.get("actions")), ""))
    fs = s.get("failsafe")
    if isinstance(fs, dict):
        rows.append(("failsafe", _counts(fs), ""))
    if "steps" in s:
        rows.append(("steps", s.get("steps"), f"({fmt(s.get('overruns', 0))} overruns)"))
    if "output_errors" in s:
        rows.append(("output errors", s.get("output_errors"), ""))
    rec = s.get("recorder")
    if isinstance(rec, dict):
        rows.append(("recorder", rec.get("records"), "records, " + _counts(
            {k: rec[k] for k in ("files_opened", "write_errors", "lost_bytes") if k in rec})))
    if s.get("partial"):
        rows.append(("partial", True, "interrupted"))
    out = [fields(rows)]
    ports = s.get("ports") or {}
    if ports:
        out.append("")
        out.append(table(
            ["port", "bytes rx", "bytes tx", "losses", "reopens", "open failures"],
            [[name, c.get("bytes_rx"), c.get("bytes_tx"), c.get("losses"), c.get("reopens"),
              c.get("open_failures")] for name, c in ports.items()]))
    router = s.get("router")
    if isinstance(router, dict):
        out.append("")
        out.append(router_table(router))
    return "\n".join(out)


def router_table(router: dict[str, Any]) -> str:
    """One row a router link: packets and bytes each way, drops."""
    rows = []
    for name, c in router.items():
        if isinstance(c, dict) and ("rx_packets" in c or "tx_packets" in c):
            rows.append([name, c.get("rx_packets"), c.get("tx_packets"),
                         c.get("dropped_queue_full"), c.get("rx_kernel_drops", "-"),
                         c.get("no_peer"), c.get("link_errors")])
    if not rows:
        return fields([("router", _counts(router), "")])
    return table(["link", "rx packets", "tx packets", "queue full", "rx lost (kernel)",
                  "no peer", "link errors"], rows)
