"""``replay --speed 1`` onto a pty honours the capture's baud rate (issue 45): a pty carries any
rate, the recorded line did not. drivers/gps/link.py's WirePacer; the replay's pty feeder."""

from __future__ import annotations

import json
import time
from pathlib import Path

import pytest

from drivers.capture import CaptureWriter, Channel
from drivers.gps.link import WirePacer
from firmware_host.cli import main
from firmware_host.devtools.rover_sim import RoverScenario, generate

SC = RoverScenario(rate_hz=10.0, duration_s=3.0, seed=2, kinds=())
EPOCHS = [data for _t, data, _truth in generate(SC)]


def test_a_line_that_carries_the_rate_leaves_the_times_alone() -> None:
    chunks = [(k * 0.1, data) for k, data in enumerate(EPOCHS)]
    assert list(WirePacer(chunks, 38400)) == chunks
    assert WirePacer(chunks, 38400).lag_s == 0.0


def test_a_line_too_slow_falls_behind_by_the_excess() -> None:
    """About 206-byte epochs at 10 Hz on 9600 baud (960 B/s): after the first (complete when
    recorded), each epoch is done once its bytes have crossed the line, so the line is never
    idle and the k-th epoch is done at the bytes since the first over 960 B/s."""
    chunks = [(k * 0.1, data) for k, data in enumerate(EPOCHS)]
    paced = WirePacer(chunks, 9600)
    out = list(paced)
    after_first = 0
    for k, ((t, data), (t_wire, same)) in enumerate(zip(chunks, out, strict=True)):
        assert same is data and t_wire >= t
        if k:
            after_first += len(data)
            assert t_wire == pytest.approx(after_first / 960.0, rel=1e-9), k
    late = out[-1][0] - chunks[-1][0]
    assert late > 3.0 and paced.lag_s == pytest.approx(late, rel=1e-9)


def test_8_data_bits_with_parity_and_2_stop_bits_are_12_bits_a_byte() -> None:
    chunks = [(0.0, b"x"), (0.0, b"x" * 960)]
    assert list(WirePacer(chunks, 9600, bits=12.0))[1][0] == pytest.approx(1.2)


def _capture(path: Path, baud: int) -> Path:
    with CaptureWriter(path, [Channel("gps", url="/dev/ttyUSB0", baudrate=baud)]) as cap:
        for k, data in enumerate(EPOCHS):
            cap.write(0, data, t_us=1_750_000_000_000_000 + k * 100_000)
    return path


def test_replay_at_speed_1_takes_the_wire_s_time(tmp_path: Path) -> None:
    """30 epochs (3 s recorded, about 6.2 kB) with a 9600-baud header: the line needs about
    6.4 s, so the replay takes at least that (a lower bound: a busy machine is only slower);
    the epochs are all there, in order."""
    total = sum(len(d) for d in EPOCHS)
    wire_s = total / 960.0
    assert wire_s > 2.0 * 3.0  # the line is the limit, not the recording's 3 s
    cap = _capture(tmp_path / "slow.cap", 9600)
    t0 = time.monotonic()
    assert main(["replay", str(cap), "--speed", "1", "--out", str(tmp_path / "o")]) == 0
    took = time.monotonic() - t0
    assert took >= wire_s - 0.3, (took, wire_s)
    lines = (tmp_path / "o" / "epochs.jsonl").read_text().splitlines()
    utcs = [json.loads(x)["utc"] for x in lines]
    assert len(utcs) == len(EPOCHS) and utcs == sorted(utcs)
