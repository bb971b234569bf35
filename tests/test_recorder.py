"""The flight recorder: format, bounded buffer, flush schedule, rotation, directory cap,
SIGKILL at any moment, and replay of a recorded session giving the same epochs.jsonl."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from drivers.capture import CaptureReader, Channel
from drivers.ptypair import PtyPair
from drivers.transport import SerialSettings
from firmware_host.commands.replay import load_input, run_replay
from firmware_host.commands.run import RoverBridge
from firmware_host.devtools.rover_sim import RoverScenario, generate
from firmware_host.runtime.config import BridgeConfig, RoverConfig
from firmware_host.runtime.loop import FakeClock
from firmware_host.runtime.recorder import FlightRecorder, RecorderConfig, read_session

ROOT = Path(__file__).resolve().parents[1]


def wait_for(cond, timeout_s: float = 15.0, what: str = "") -> None:  # type: ignore[no-untyped-def]
    deadline = time.monotonic() + timeout_s
    ev = threading.Event()
    while not cond():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        ev.wait(0.005)


def _recorder(tmp_path: Path, clock: FakeClock, **kw: float) -> FlightRecorder:
    cfg = RecorderConfig(dir=str(tmp_path), **kw)  # type: ignore[arg-type]
    rec = FlightRecorder(tmp_path, cfg, clock=clock,
                         wall_us=lambda: 1_700_000_000_000_000 + round(clock() * 1e6))
    rec.add_channel(Channel("gps rx", "/dev/ttyUSB0", direction="rx"))
    rec.add_channel(Channel("nmea tx", "/dev/ttyUSB1", direction="tx"))
    return rec


def test_records_read_back_in_the_capture_format(tmp_path: Path) -> None:
    clock = FakeClock()
    rng = np.random.default_rng(1)
    rec = _recorder(tmp_path, clock)
    sent = []
    for k in range(200):
        clock.now = k * 0.01
        data = rng.integers(0, 256, int(rng.integers(1, 300)), dtype=np.uint8).tobytes()
        rec.write(k % 2, data)
        sent.append((k % 2, data))
    rec.write(0, b"x" * 70000)  # longer than one record: split, same time
    sent.append((0, b"x" * 70000))
    rec.close()
    files = rec.recordings()
    assert len(files) == 1
    reader = CaptureReader(files[0])
    assert [c.name for c in reader.channels] == ["gps rx", "nmea tx"]
    got = [(r.channel, r.data) for r in reader]
    joined = {0: b"", 1: b""}
    for ch, d in got:
        joined[ch] += d
    assert joined[0] == b"".join(d for ch, d in sent if ch == 0)
    assert joined[1] == b"".join(d for ch, d in sent if ch == 1)
    assert rec.bytes_by_channel == [len(joined[0]), len(joined[1])]


def test_flush_schedule_and_bounded_buffer(tmp_path: Path) -> None:
    clock = FakeClock()
    rec = _recorder(tmp_path, clock, flush_interval_s=0.5, buffer_max_kb=4)
    for k in range(1000):  # 100 B every 10 ms of the fake clock for 10 s
        clock.now = k * 0.01
        rec.write(0, bytes(100))
        assert len(rec._buf) < 4096 + 200  # never more than the bound (plus one record)
        # What is on disk is never older than the flush interval.
        on_disk = rec.recordings()[0].stat().st_size if rec.recordings() else 0
        in_memory = len(rec._buf)
        assert in_memory <= 4096 + 200
        if k * 0.01 >= 0.5:
            assert on_disk > 0
    assert 19 <= rec.syncs <= 21  # every 0.5 s of the clock
    rec.poll()
    rec.close()


def test_rotation_and_directory_cap(tmp_path: Path) -> None:
    clock = FakeClock()
    rec = _recorder(tmp_path, clock, file_max_mb=0.05, dir_max_mb=0.2)
    (tmp_path / "unrelated.txt").write_text("kept")
    for k in range(2000):  # 2000 x 500 B = 1 MB
        clock.now = k * 0.05
        rec.write(0, bytes(500))
    rec.close()
    files = rec.recordings()
    sizes = [p.stat().st_size for p in files]
    assert rec.files_opened >= 18
    assert rec.files_deleted == rec.files_opened - len(files)
    assert sum(sizes) <= 0.2e6 + 0.05e6 + 0.5 * 20 * 500  # the cap, plus the open file
    assert (tmp_path / "unrelated.txt").exists()
    assert files == sorted(files) and files[-1] == rec.path  # the newest survive
    # The surviving session reads back continuously (each file carries the header).
    data = b"".join(r.data for _, r in read_session(files))
    assert len(data) > 0 and set(data) == {0}


def test_background_sync_rotates_and_closes_cleanly(tmp_path: Path) -> None:
    clock = FakeClock()
    cfg = RecorderConfig(file_max_mb=0.02, dir_max_mb=10.0, flush_interval_s=0.1)
    rec = FlightRecorder(tmp_path, cfg, clock=clock, background_sync=True)
    ch = rec.add_channel(Channel("gps rx", direction="rx"))
    for k in range(500):
        clock.now = k * 0.05
        rec.write(ch, bytes([k % 256]) * 300)
    rec.close()
    assert rec._syncer is not None and not rec._syncer.is_alive()
    files = rec.recordings()
    assert len(files) == rec.files_opened >= 5 and rec.syncs >= len(files)
    data = b"".join(r.data for _, r in read_session(files))
    assert data == b"".join(bytes([k % 256]) * 300 for k in range(500))


def test_truncated_last_record_is_skipped(tmp_path: Path) -> None:
    clock = FakeClock()
    rec = _recorder(tmp_path, clock)
    for k in range(10):
        rec.write(0, b"$GPGGA,%d\r\n" % k)
    rec.close()
    path = rec.recordings()[0]
    raw = path.read_bytes()
    path.write_bytes(raw[:-7])  # killed in the middle of the last record
    reader = CaptureReader(path)
    records = list(reader)
    assert len(records) == 9 and reader.truncated and not reader.corrupt
    inp = load_input(path)
    assert inp.total_bytes == sum(len(r.data) for r in records)  # streamed to the end
    assert inp.truncated and "truncated" in inp.notes[0]


# --------------------------------------------------------------------------- replay = live


def test_replaying_a_recorded_session_reproduces_epochs_jsonl(tmp_path: Path) -> None:
    link = tmp_path / "gps"
    sc = RoverScenario(rate_hz=10.0, duration_s=40.0, seed=11, fault_every_s=8.0)
    chunks = [data for _, data, _ in generate(sc)]
    cfg = BridgeConfig(rover=RoverConfig(port=SerialSettings(url=str(link), timeout_s=0.02)))
    rec = FlightRecorder(tmp_path / "rec", RecorderConfig(file_max_mb=1.0))
    live = tmp_path / "live.jsonl"
    with PtyPair(link=link) as pty, open(live, "w", encoding="utf-8") as jsonl:
        bridge = RoverBridge(cfg, jsonl=jsonl, recorder=rec)
        stop = threading.Event()
        th = threading.Thread(target=bridge.run, args=(stop.is_set,), daemon=True)
        th.start()
        rng = np.random.default_rng(2)
        blob = b"".join(chunks)
        i = 0
        while i < len(blob):  # arbitrary chunking: the pipeline does not depend on it
            n = int(rng.integers(1, 700))
            pty.write(blob[i : i + n])
            i += n
        wait_for(lambda: bridge.port.bytes_rx == len(blob), what="all bytes read")
        stop.set()
        th.join(5.0)
        bridge.close()
    files = rec.recordings()
    assert len(files) == 1
    summary = run_replay(BridgeConfig(), files[0], tmp_path / "replay")
    replayed = (tmp_path / "replay" / "epochs.jsonl").read_bytes()
    assert summary["epochs"] == 400 and summary["faults"] > 0
    assert replayed == live.read_bytes()


# --------------------------------------------------------------------------- SIGKILL


def _kill_trial(tmp_path: Path, kill_after_s: float, seed: int) -> dict[str, float]:
    """A child `fdi-bridge run` records a pty stream; kill -9 it; measure what was lost."""
    link = tmp_path / f"gps{seed}"
    recdir = tmp_path / f"rec{seed}"
    cfg = tmp_path / f"rover{seed}.toml"
    cfg.write_text(f'[rover.port]\nurl = "{link}"\ntimeout_s = 0.02\n'
                   f'[recorder]\ndir = "{recdir}"\nflush_interval_s = 0.5\n')
    sc = RoverScenario(rate_hz=50.0, duration_s=60.0, seed=seed)
    epochs = [data for _, data, _ in generate(sc)]
    sent: list[tuple[float, int]] = []  # (wall time after the write, total bytes sent)
    stop = threading.Event()
    with PtyPair(link=link) as pty:
        child = subprocess.Popen(
            [sys.executable, "-m", "firmware_host.cli", "run", "--config", str(cfg)],
            cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)

        def writer() -> None:  # the receiver: an epoch every 20 ms
            total = 0
            for data in epochs:
                if stop.is_set():
                    return
                pty.write(data)
                total += len(data)
                sent.append((time.time(), total))
                stop.wait(0.02)

        th = threading.Thread(target=writer, daemon=True)
        try:
            th.start()

            def recording() -> bool:
                return any(p.stat().st_size > 400 for p in recdir.glob("*.cap"))

            wait_for(recording, 20.0, "the child to record")
            deadline = time.time() + kill_after_s
            stop.wait(max(0.0, deadline - time.time()))  # the moment of the kill (chosen)
            t_kill = time.time()
            os.kill(child.pid, signal.SIGKILL)
            stop.set()
            child.wait(10.0)
        finally:
            stop.set()
            if child.poll() is None:
                child.kill()
                child.wait(10.0)
            th.join(5.0)
    files = sorted(recdir.glob("*.cap"))
    records = [r for _, r in read_session(files)]
    recorded = sum(len(r.data) for r in records)
    blob = b"".join(epochs)
    got = b"".join(r.data for r in records)
    # pyserial flushes the input on open, so the recording starts where the child opened the
    # port; from there it is exactly what was sent, with no gap.
    start = blob.find(got[:300])
    assert start >= 0 and got == blob[start : start + len(got)]
    end = start + recorded
    sent_before = [(t, n) for t, n in sent if t <= t_kill]
    first_lost = next((t for t, n in sent_before if n > end), None)
    loss_s = 0.0 if first_lost is None else t_kill - first_lost
    last_record_s = t_kill - records[-1].t_us / 1e6
    return {"loss_s": loss_s, "last_record_age_s": last_record_s,
            "bytes_sent": sent_before[-1][1], "bytes_recorded": recorded}


def test_sigkill_loses_at_most_one_second(tmp_path: Path) -> None:
    trials = int(os.environ.get("FDI_KILL_TRIALS", "3"))
    rng = np.random.default_rng(7)
    results = [_kill_trial(tmp_path, float(rng.uniform(0.2, 1.8)), seed) for seed in
               range(trials)]
    worst = max(r["loss_s"] for r in results)
    if os.environ.get("FDI_KILL_TRIALS"):
        print("sigkill trials:", results, "worst loss", worst)
    assert worst <= 1.0, results
    assert all(r["last_record_age_s"] <= 1.0 for r in results), results


@pytest.mark.parametrize("interval", [0.5, 1.0])
def test_flush_interval_is_at_most_one_second(interval: float) -> None:
    assert RecorderConfig(flush_interval_s=interval).flush_interval_s <= 1.0
