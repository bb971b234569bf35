"""A full disk under ``fdi-bridge run --out DIR --record DIR`` never stops detection (issue C.3).

The real command in a child process, its GPS on a real pty at 10 Hz, its GPS_INPUT to a UDP
socket on 127.0.0.1, ``--out`` and ``--record`` on a 256 KiB tmpfs (``tests/diskfull.py``;
skipped with the reason where mounting is not allowed). Once the bridge runs, the disk is
filled to the last byte and stays full; the receiver goes on for ``FDI_DISKFULL_SECONDS``
(default 10 s; the done-means asks for 60 s: ``FDI_DISKFULL_SECONDS=60``). The short run
proves the same thing: the outage starts after the first flush (0.25 s), both writers fail
on every flush from then on (40 tries of ``epochs.jsonl``, 20 of the recorder, whose buffer is
set to 16 KiB so that it also drops and counts within the run), then SIGTERM.

Before this change (issue C.3): exit 1 after a few seconds, GPS_INPUT stopped, ``summary.json``
left at 0 bytes, the last JSONL line cut.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

from drivers.mavlink.framer import MavFramer
from drivers.ptypair import PtyPair
from firmware_host.devtools.rover_sim import RoverScenario, generate
from tests.diskfull import fill, small_tmpfs

ROOT = Path(__file__).resolve().parents[1]
GPS_INPUT = 232
RATE_HZ = 10.0


def wait_for(cond: Callable[[], bool], timeout_s: float = 20.0, what: str = "") -> None:
    """Poll ``cond`` until true or the deadline."""
    deadline = time.monotonic() + timeout_s
    ev = threading.Event()
    while not cond():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        ev.wait(0.01)


class GpsInputCounter(threading.Thread):
    """The autopilot: a UDP socket on 127.0.0.1; the arrival time of every GPS_INPUT."""

    def __init__(self) -> None:
        super().__init__(name="autopilot", daemon=True)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.05)
        self.port = self.sock.getsockname()[1]
        self.times: list[float] = []
        self.stop = threading.Event()
        self.framer = MavFramer()

    def run(self) -> None:
        while not self.stop.is_set():
            try:
                data = self.sock.recv(65536)
            except TimeoutError:
                continue
            now = time.monotonic()
            self.times += [now for f in self.framer.feed(data) if f.msgid == GPS_INPUT]
        self.sock.close()


def test_full_disk_under_out_and_record_keeps_gps_input_and_exits_0(tmp_path: Path) -> None:
    seconds = float(os.environ.get("FDI_DISKFULL_SECONDS", "10"))
    with small_tmpfs(tmp_path / "disk", size_kb=256) as disk:
        out, rec, link = disk / "out", disk / "rec", tmp_path / "gps"
        cfg = tmp_path / "rover.toml"
        ap = GpsInputCounter()
        cfg.write_text(f'[rover.port]\nurl = "{link}"\ntimeout_s = 0.02\n'
                       f'[rover.output]\nmavlink_url = "udpout:127.0.0.1:{ap.port}"\n'
                       '[recorder]\nbuffer_max_kb = 16\n')
        sc = RoverScenario(rate_hz=RATE_HZ, duration_s=seconds + 60.0, seed=21)
        epochs = [data for _, data, _ in generate(sc)]
        stderr = tmp_path / "stderr.txt"
        sent: list[float] = []  # the time each epoch was written to the pty
        stop = threading.Event()
        with PtyPair(link=link) as pty, open(stderr, "wb") as err:
            ap.start()
            child = subprocess.Popen(
                [sys.executable, "-m", "firmware_host.cli", "run", "--config", str(cfg),
                 "--out", str(out), "--record", str(rec), "--json"],
                cwd=ROOT, stdout=subprocess.PIPE, stderr=err,
                env=dict(os.environ, PYTHONPATH=str(ROOT)))

            def receiver() -> None:  # the GPS: an epoch every 0.1 s on absolute deadlines
                due = time.monotonic()
                for data in epochs:
                    if stop.is_set():
                        return
                    pty.write(data)
                    sent.append(time.monotonic())
                    due += 1.0 / RATE_HZ
                    stop.wait(max(0.0, due - time.monotonic()))

            gps = threading.Thread(target=receiver, daemon=True)
            try:
                gps.start()
                wait_for(lambda: len(ap.times) >= 10, what="GPS_INPUT from the bridge")
                wait_for(lambda: (out / "epochs.jsonl").exists()
                         and (out / "epochs.jsonl").stat().st_size > 0,
                         what="the first lines of epochs.jsonl")
                fill(disk)  # full from here to the end
                t_full = time.monotonic()
                stop.wait(seconds)  # the receiver paces itself; this is the run's length
                stop.set()
                gps.join(5.0)
                t_end = sent[-1]
                n_sent = sum(1 for t in sent if t_full <= t <= t_end)
                # The last epoch's GPS_INPUT arrives within a second (or never does).
                deadline = time.monotonic() + 1.0
                while time.monotonic() < deadline and ap.times[-1] < t_end:
                    stop.wait(0.01)
                assert child.poll() is None, "the bridge stopped on the full disk"
                child.send_signal(signal.SIGTERM)
                stdout, _ = child.communicate(timeout=30)
            finally:
                stop.set()
                if child.poll() is None:
                    child.kill()
                    child.wait(10)
                ap.stop.set()
                ap.join(5.0)
        log = stderr.read_text(errors="replace")
        n_out = sum(1 for t in ap.times if t_full <= t <= t_end + 1.0)
        ratio = n_out / n_sent
        print(f"full disk {seconds:.0f} s at {RATE_HZ:.0f} Hz: {n_sent} epochs sent, "
              f"{n_out} GPS_INPUT ({100 * ratio:.1f} %), exit {child.returncode}")
        assert child.returncode == 0, log[-2000:]
        assert "internal error" not in log and "Traceback" not in log
        assert ratio >= 0.95, (n_sent, n_out)  # the rate held (1 GPS_INPUT per epoch)
        summary = json.loads((out / "summary.json").read_text())  # valid, complete
        assert summary == json.loads(stdout)  # the same summary printed and written
        assert summary["runtime"]["stopped_by"] == "SIGTERM"
        assert summary["epochs"] >= n_sent
        epochs_file = summary["epochs_file"]
        print(f"epochs_file {epochs_file}\nrecorder lost_records "
              f"{summary['recorder']['lost_records']} write_errors "
              f"{summary['recorder']['write_errors']}; summary.json "
              f"{(out / 'summary.json').stat().st_size} bytes")
        assert epochs_file["write_errors"] > 0 and epochs_file["lost_lines"] > 0
        assert epochs_file["outages"] == 1  # full from t_full to the end: one outage
        recorder = summary["recorder"]
        assert recorder["write_errors"] > 0 and recorder["lost_records"] > 0
        # No line of epochs.jsonl is cut: every line is whole JSON.
        lines = (out / "epochs.jsonl").read_bytes().splitlines(keepends=True)
        assert lines and all(line.endswith(b"\n") for line in lines)
        for line in lines:
            json.loads(line)
        assert epochs_file["lines_written"] == len(lines)
        assert epochs_file["lines_written"] + epochs_file["lost_lines"] == summary["epochs"]
        # Said once (not once an epoch): the outage of each writer.
        assert log.count("epochs.jsonl") <= 3, log[-2000:]
        assert not list(out.glob(".*tmp*"))  # no temporary file left
