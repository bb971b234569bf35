"""``fdi-bridge run`` says what it is doing, as a user sees it (issue 17).

Real parts: the program as a subprocess, the GPS receiver on a real pty fed at 10 Hz, and the
program's own stderr on a real terminal (a pty from :func:`pty.openpty`) or on a pipe (as
systemd's journal or ``2>file`` has it). On a terminal: the banner, then one status line
refreshed in place (``\\r``) with the epochs counting up, then the summary on its own line. On
a pipe: the banner and the summary, no ``\\r``.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import threading
from pathlib import Path

from drivers.ptypair import PtyPair
from firmware_host.devtools.rover_sim import RoverScenario, generate
from tests.ptyrun import cli_under_pty

ROOT = Path(__file__).resolve().parents[1]

CONFIG = """name = "status-test"
[rover]
silence_s = 1.0
reconnect_max_s = 0.5
[rover.port]
url = "{gps}"
baudrate = 38400
timeout_s = 0.05
[rover.output]
mavlink_url = "udpout:127.0.0.1:{port}"
"""


def _config(tmp_path: Path) -> Path:
    cfg = tmp_path / "bridge.toml"
    cfg.write_text(CONFIG.format(gps=tmp_path / "gps", port=9))  # port 9: discard, loopback
    return cfg


class Feeder(threading.Thread):
    """The receiver: a simulated drive's NMEA on the pty at 10 Hz until stopped (about 2 kB/s:
    the link is set to 38400 baud, which carries it; at 9600 the bridge warns)."""

    def __init__(self, pty_pair: PtyPair) -> None:
        super().__init__(daemon=True)
        sc = RoverScenario(rate_hz=10.0, duration_s=60.0, seed=11, fault_every_s=1e9)
        self.chunks = [data for _, data, _ in generate(sc)]
        self.pty = pty_pair
        self.halt = threading.Event()

    def stop(self) -> None:
        """Stop, and wait for the thread, before the pty is closed under it (a read on the
        closed descriptor raised EBADF in the thread: a fresh-clone CI run's warning)."""
        self.halt.set()
        self.join(timeout=5.0)

    def run(self) -> None:
        for chunk in self.chunks:
            if self.halt.is_set():
                return
            self.pty.write(chunk)
            self.pty.read(0.0)
            self.halt.wait(0.1)


def _cmd(cfg: Path, *extra: str) -> list[str]:
    return [sys.executable, "-m", "firmware_host.cli", "run", "--config", str(cfg),
            "--duration", "4", *extra]


def _env() -> dict[str, str]:
    return dict(os.environ, PYTHONPATH=str(ROOT), COLUMNS="200")


def test_on_a_terminal_banner_then_a_refreshing_status_line(tmp_path: Path) -> None:
    cfg = _config(tmp_path)
    with PtyPair(link=tmp_path / "gps", baudrate=38400) as gps:
        feeder = Feeder(gps)
        feeder.start()
        try:
            rc, text = cli_under_pty(_cmd(cfg)[3:], tmp_path, timeout=30.0, env=_env())
        finally:
            feeder.stop()
    assert rc == 0, text
    assert "Traceback" not in text
    banner, rest = text.split("\r\n\r", 1)  # the terminal turns \n into \r\n
    assert banner.startswith("fdi-bridge 0.1.0: running")
    for label in ("config", "vehicle", "port gps", "outputs", "recorder", "records"):
        assert re.search(rf"^  {label} +\S", banner, re.M), (label, banner)
    assert str(tmp_path / "gps") in banner and "MAVLink udpout:127.0.0.1:9" in banner
    live, summary = rest.split("\r\n", 1)
    lines = [x.removesuffix("\x1b[K") for x in live.split("\r")]
    assert len(lines) >= 3, live  # one a second for 4 s
    epochs = [int(re.search(r"epochs (\d+)", x).group(1)) for x in lines]  # type: ignore[union-attr]
    assert epochs == sorted(epochs) and epochs[-1] > epochs[0] > 0
    assert all(re.search(r"\| gps up [\d.]+ k?B/s \| last epoch [\d.]+ s ago( \| .+)?$", x)
               for x in lines), lines
    assert "WARNING" not in text  # the link carries the rate: nothing to warn about
    assert summary.split()[:2] == ["vehicle", "rover"]
    assert re.search(r"^stopped by +duration", summary, re.M)


def test_on_a_pipe_banner_and_summary_without_the_live_line(tmp_path: Path) -> None:
    cfg = _config(tmp_path)
    with PtyPair(link=tmp_path / "gps", baudrate=38400) as gps:
        feeder = Feeder(gps)
        feeder.start()
        try:
            proc = subprocess.run(_cmd(cfg), capture_output=True, env=_env(), cwd=tmp_path,
                                  timeout=30.0)
        finally:
            feeder.stop()
    err, out = proc.stderr.decode(), proc.stdout.decode()
    assert proc.returncode == 0, err
    assert "\r" not in err and "\r" not in out and "Traceback" not in err
    assert "fdi-bridge 0.1.0: running" in err and "  vehicle   rover" in err
    assert "epochs |" not in err and "last epoch" not in err  # no status line within a minute
    rows = dict(line.split(None, 1) for line in out.splitlines()
                if line and not line.startswith(("port", "gps")))
    assert rows["vehicle"] == "rover" and int(rows["epochs"]) >= 20
    port = next(line for line in out.splitlines() if line.startswith("gps"))
    assert int(port.split()[1]) > 1000  # bytes read from the receiver


def test_json_summary_on_stdout(tmp_path: Path) -> None:
    cfg = _config(tmp_path)
    with PtyPair(link=tmp_path / "gps", baudrate=38400) as gps:
        feeder = Feeder(gps)
        feeder.start()
        try:
            proc = subprocess.run(_cmd(cfg, "--json"), capture_output=True, env=_env(),
                                  cwd=tmp_path, timeout=30.0)
        finally:
            feeder.stop()
    summary = json.loads(proc.stdout)
    assert summary["vehicle"] == "rover" and summary["runtime"]["stopped_by"] == "duration"
