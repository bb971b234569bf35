"""``epochs.jsonl`` is kill-safe to a quarter of a second (issue C item 9).

It lost up to 1.26 s at 10 Hz on ``SIGKILL`` (an 8 KiB buffer flushed when full); now the
runner hands the records to the kernel every 0.25 s of its clock (the monotonic clock in a run;
wall time, not the epochs' times, so a receiver that stops sending does not hold records back),
checked on every iteration. A fake-clock runner shows the bound on every iteration; a real
``fdi-bridge run --out`` killed with ``kill -9`` at seeded moments shows it end to end.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any, Literal

import numpy as np

from drivers.ptypair import PtyPair
from firmware_host.devtools.rover_sim import RoverScenario, generate
from firmware_host.runtime.loop import FakeClock
from firmware_host.runtime.runner import Runner
from firmware_host.runtime.vehicle import Context, MavlinkSpec, PortSpec

ROOT = Path(__file__).resolve().parents[1]
PAD = "x" * 400  # a rover record is 400-700 bytes


class Writer:
    """A period-paced vehicle writing one rover-sized record per step (10 Hz)."""

    name = "writer"
    pacing: Literal["period"] = "period"
    period_s = 0.1

    def __init__(self) -> None:
        self.ctx: Context | None = None
        self.n = 0

    def ports(self) -> list[PortSpec]:
        return []

    def mavlink(self) -> MavlinkSpec | None:
        return None

    def outputs(self) -> tuple[str, ...]:
        return ()

    def status_fields(self) -> dict[str, Any]:
        return {}

    def status_detail(self) -> tuple[str, ...]:
        return ()

    def start(self, ctx: Context) -> None:
        self.ctx = ctx

    def step(self, t: float) -> int:
        assert self.ctx is not None
        self.n += 1
        self.ctx.epochs.write({"k": self.n, "t": round(t, 3), "pad": PAD})
        return 1

    def check(self, now: float) -> None:
        pass

    def idle_s(self) -> float:
        return 0.0

    def finish(self) -> None:
        pass

    def summary(self) -> dict[str, Any]:
        return {"epochs": self.n}


def test_records_reach_the_kernel_within_a_quarter_second(tmp_path: Path) -> None:
    """After every iteration the file, read by another reader (what a SIGKILL leaves), holds
    every record older than the flush interval 0.25 s plus one period: at most 3 records at
    10 Hz wait in memory (an 8 KiB buffer held 19 of these, 1.9 s)."""
    clock = FakeClock(50.0)
    v = Writer()
    path = tmp_path / "epochs.jsonl"
    worst = {"waiting": 0}

    def on_disk() -> None:
        lines = path.read_bytes().count(b"\n") if path.exists() else 0
        worst["waiting"] = max(worst["waiting"], v.n - lines)

    runner = Runner(v, out_dir=tmp_path, duration_s=20.0, clock=clock, sleep=clock.sleep)
    runner.run(until=lambda: on_disk() is not None)
    assert v.n >= 200  # 20 s at 10 Hz
    assert worst["waiting"] <= 3, worst  # 0.25 s + one period at 10 Hz
    assert len(path.read_text().splitlines()) == v.n


def _utc_of(data: bytes) -> float:
    """The UTC seconds of day of a generated epoch (its GGA's time)."""
    for sentence in data.split(b"\r\n"):
        if sentence[3:6] == b"GGA":
            s = sentence.split(b",")[1].decode()
            return int(s[0:2]) * 3600 + int(s[2:4]) * 60 + float(s[4:])
    raise AssertionError(f"no GGA in {data!r}")


def _kill_trial(tmp_path: Path, seed: int, kill_after_s: float) -> tuple[float, int]:
    """``fdi-bridge run --out`` fed at 10 Hz through a pty, killed -9 ``kill_after_s`` after
    its first line reached the file; (seconds of epochs processed but not in the file,
    lines in the file)."""
    link, out = tmp_path / f"gps{seed}", tmp_path / f"out{seed}"
    cfg = tmp_path / f"rover{seed}.toml"
    cfg.write_text(f'[rover.port]\nurl = "{link}"\ntimeout_s = 0.02\n')
    epochs = [data for _, data, _ in generate(RoverScenario(rate_hz=10.0, duration_s=60.0,
                                                            seed=seed))]
    sent: list[float] = []
    stop = threading.Event()
    path = out / "epochs.jsonl"
    with PtyPair(link=link) as pty:
        child = subprocess.Popen(
            [sys.executable, "-m", "firmware_host.cli", "run", "--config", str(cfg),
             "--out", str(out)], cwd=ROOT, stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL, env=dict(os.environ, PYTHONPATH=str(ROOT)))

        def receiver() -> None:  # an epoch every 0.1 s on absolute deadlines
            due = time.monotonic()
            for data in epochs:
                if stop.is_set():
                    return
                pty.write(data)
                sent.append(time.monotonic())
                due += 0.1
                stop.wait(max(0.0, due - time.monotonic()))

        th = threading.Thread(target=receiver, daemon=True)
        try:
            th.start()
            deadline = time.monotonic() + 20.0
            while not (path.exists() and path.stat().st_size > 0):
                assert time.monotonic() < deadline, "the bridge wrote no epoch"
                stop.wait(0.01)
            stop.wait(kill_after_s)  # the moment of the kill (chosen)
            t_kill = time.monotonic()
            os.kill(child.pid, signal.SIGKILL)
            child.wait(10)
        finally:
            stop.set()
            if child.poll() is None:
                child.kill()
                child.wait(10)
            th.join(5)
    lines = path.read_bytes().splitlines(keepends=True)
    assert lines and all(x.endswith(b"\n") for x in lines)  # no cut line
    # An epoch is complete when the next one starts (NMEA has no end-of-cycle mark) and is
    # processed within a few ms: every epoch written 0.2 s before the kill was processed.
    processed = max(i for i, t in enumerate(sent) if t <= t_kill - 0.2)
    lost_s = _utc_of(epochs[processed]) - json.loads(lines[-1])["utc"]
    return round(max(0.0, lost_s), 3), len(lines)


def test_sigkill_loses_at_most_half_a_second_of_epochs(tmp_path: Path) -> None:
    """A real ``kill -9`` at four seeded moments: the file lacks at most 0.25 s + one
    iteration of what the bridge processed (before: up to 1.26 s at 10 Hz)."""
    rng = np.random.default_rng(93)
    for seed in (1, 2, 3, 4):
        lost_s, in_file = _kill_trial(tmp_path, seed, float(rng.uniform(1.5, 2.5)))
        print(f"SIGKILL trial {seed}: {in_file} lines in the file, {lost_s:.2f} s lost")
        assert in_file >= 10
        assert lost_s <= 0.5, (seed, lost_s)
