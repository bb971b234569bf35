"""gpsd reads the corrected NMEA stream from a pty and reports the same positions.

The bridge's NMEA output goes to a pty it creates (``pty:LINK``); gpsd (Debian package
``gpsd``, started here, read-only ``-b``) opens the linked slave like any receiver. A watcher
on gpsd's JSON socket collects TPV reports; every position gpsd reports must be one the bridge
put out for that fix time, and gpsd must report nearly every output fix.
"""

from __future__ import annotations

import json
import shutil
import socket
import subprocess
import time
from pathlib import Path
from typing import Any

import pytest

from firmware_host.commands.replay import run_replay
from firmware_host.devtools.rover_sim import RoverScenario, write_run
from firmware_host.rover.outputs import NmeaSink
from firmware_host.runtime.config import BridgeConfig

GPSD = shutil.which("gpsd") or ("/usr/sbin/gpsd" if Path("/usr/sbin/gpsd").exists() else None)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class GpsdWatch:
    def __init__(self, port: int, deadline_s: float = 10.0) -> None:
        end = time.monotonic() + deadline_s
        while True:
            try:
                self.sock = socket.create_connection(("127.0.0.1", port), timeout=0.5)
                break
            except OSError:
                if time.monotonic() > end:
                    raise
                time.sleep(0.05)  # polling gpsd's start-up, with a deadline
        self.sock.sendall(b'?WATCH={"enable":true,"json":true};\n')
        self.buf = b""
        self.reports: list[dict[str, Any]] = []

    def poll(self, timeout_s: float) -> None:
        self.sock.settimeout(timeout_s)
        try:
            chunk = self.sock.recv(65536)
        except TimeoutError:
            return
        self.buf += chunk
        *lines, self.buf = self.buf.split(b"\n")
        for line in lines:
            if line.strip():
                self.reports.append(json.loads(line))

    def wait_for(self, pred: Any, deadline_s: float) -> bool:
        end = time.monotonic() + deadline_s
        while time.monotonic() < end:
            if any(pred(r) for r in self.reports):
                return True
            self.poll(0.2)
        return False


@pytest.mark.skipif(GPSD is None, reason="gpsd is not installed (Debian package gpsd)")
def test_gpsd_reports_the_corrected_positions(tmp_path: Path) -> None:
    run_dir = tmp_path / "run"
    write_run(RoverScenario(rate_hz=1.0, duration_s=120.0, seed=11), run_dir)
    link = tmp_path / "gps0"
    sink = NmeaSink(f"pty:{link}")
    port = _free_port()
    assert GPSD is not None
    proc = subprocess.Popen(
        [GPSD, "-N", "-n", "-b", "-S", str(port),
         "-F", str(tmp_path / "gpsd.sock"), str(link)],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
    )
    try:
        watch = GpsdWatch(port)
        assert watch.wait_for(lambda r: r.get("class") == "DEVICES", 10.0), "gpsd never answered"
        summary = run_replay(BridgeConfig(), run_dir / "rover.nmea", tmp_path / "out",
                             speed=40.0, sinks=[sink])
        text = (tmp_path / "out" / "epochs.jsonl").read_text()
        epochs = [json.loads(x) for x in text.splitlines() if x]
        last_t = max(e["utc"] for e in epochs if e["lat"] is not None)

        def done(r: dict[str, Any]) -> bool:
            return r.get("class") == "TPV" and _sod(r.get("time", "")) == last_t

        watch.wait_for(done, 10.0)
    finally:
        proc.terminate()
        proc.wait(timeout=5)
        sink.close()
    out = {e["utc"]: e for e in epochs if e["lat"] is not None}
    tpv = [r for r in watch.reports if r.get("class") == "TPV" and "lat" in r and "time" in r]
    assert summary["faults"] > 0, "the run should contain replaced fixes"
    matched = 0
    for r in tpv:
        e = out.get(_sod(r["time"]))
        assert e is not None, f"gpsd reported a fix the bridge did not put out: {r}"
        assert abs(r["lat"] - e["lat"]) < 1e-8 and abs(r["lon"] - e["lon"]) < 1e-8
        matched += 1
    assert matched >= 0.95 * len(out), f"gpsd reported {matched} of {len(out)} output fixes"
    replaced = [e["utc"] for e in out.values() if e["action"] == "replace"]
    assert set(replaced) <= {_sod(r["time"]) for r in tpv}


def _sod(iso: str) -> float | None:
    """'2025-05-12T10:00:01.000Z' -> seconds of day."""
    if "T" not in iso:
        return None
    hms = iso.split("T", 1)[1].rstrip("Z")
    h, m, s = hms.split(":")
    return round(int(h) * 3600 + int(m) * 60 + float(s), 2)
