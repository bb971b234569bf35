"""``fdi-bridge record`` captures a port's bytes; replaying the capture gives the same epochs.

A generated rover stream is written into a real pty; the recorder reads the slave side by its
path (as it would read /dev/ttyUSB0). Replaying the capture through a pty must reproduce,
record for record, the epochs.jsonl of replaying the original NMEA log: the pipeline is
deterministic given its input bytes.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path

from drivers.capture import CaptureReader
from drivers.ptypair import PtyPair
from drivers.transport import SerialSettings
from firmware_host.commands.record import record
from firmware_host.commands.replay import run_replay
from firmware_host.devtools.rover_sim import RoverScenario, write_run
from firmware_host.runtime.config import BridgeConfig


def test_record_then_replay_reproduces_epochs(tmp_path: Path) -> None:
    write_run(RoverScenario(rate_hz=5.0, duration_s=60.0, seed=8), tmp_path / "run")
    lines = [
        line
        for line in (tmp_path / "run" / "rover.nmea").read_bytes().splitlines(keepends=True)
        if not line.startswith(b"#")
    ]
    stop = threading.Event()
    opened = threading.Event()
    counts: dict[str, int] = {}
    cap = tmp_path / "field.cap"
    with PtyPair(baudrate=9600) as pty:
        settings = SerialSettings(url=pty.url, baudrate=9600, timeout_s=0.02)

        def recorder() -> None:
            counts.update(record(settings, cap, stop=stop.is_set, on_open=opened.set))

        th = threading.Thread(target=recorder, daemon=True)
        th.start()
        assert opened.wait(5.0), "the recorder never opened the port"
        total = 0
        for i in range(0, len(lines), 10):
            total += pty.write(b"".join(lines[i : i + 10]))
        deadline = time.monotonic() + 10.0
        while time.monotonic() < deadline:  # poll the capture file's growth, with a deadline
            if cap.exists() and sum(len(r.data) for r in CaptureReader(cap)) >= total:
                break
            time.sleep(0.02)
        stop.set()
        th.join(timeout=5.0)
    assert counts["bytes"] == total
    reader = CaptureReader(cap)
    assert reader.channels[0].baudrate == 9600
    assert not reader.truncated and not reader.corrupt
    cfg = BridgeConfig()
    a = run_replay(cfg, tmp_path / "run" / "rover.nmea", tmp_path / "a")
    b = run_replay(cfg, cap, tmp_path / "b")
    assert a["epochs"] == b["epochs"] == 300
    ja = (tmp_path / "a" / "epochs.jsonl").read_bytes()
    assert ja == (tmp_path / "b" / "epochs.jsonl").read_bytes()
