"""A plain log's blocks (``ReplayInput.blocks``, issue 46: the replay reads its input without
a Python step a line) are the line-by-line chunks joined, byte for byte and time for time:
on generated logs, on logs with every kind of line end, comments, blank lines, lines longer
than the read size and than ``readline``'s limit, and no line end at the end."""

from __future__ import annotations

import random
from pathlib import Path

import pytest

from firmware_host.commands import replay
from firmware_host.commands.replay import _join, _nmea_blocks, _nmea_chunks, load_input
from firmware_host.devtools.rover_sim import RoverScenario, write_run

SIZES = (1, 7, 100, 4096, 65536)


def _same(path: Path, sizes: tuple[int, ...] = SIZES) -> None:
    for size in sizes:
        want = list(_join(_nmea_chunks(path), size))
        got = list(_nmea_blocks(path, size))
        assert got == want, size
        inp = load_input(path)
        assert list(inp.blocks(size)) == want
        assert inp.total_bytes == sum(len(d) for _, d in want)
    assert load_input(path).data() == b"".join(d for _, d in _nmea_chunks(path))


def test_generated_logs(tmp_path: Path) -> None:
    for seed, rate in ((3, 10.0), (4, 1.0)):
        write_run(RoverScenario(rate_hz=rate, duration_s=120.0, seed=seed), tmp_path / str(seed))
        _same(tmp_path / str(seed) / "rover.nmea")


_PIECES = [b"$GPGGA,120000.00,4807.038,N,01131.000,E,1,08,0.9,545.4,M,47.0,M,,*47",
           b"$GNRMC,235959.5,A,4807.038,N,01131.000,E,022.4,084.4,230394,003.1,W*6A",
           b"$GPZDA,000001,01,01,2020,,", b"$GPGST,12000", b"$G\rGGA,120001.00,",
           b"$GPVTG,,T,,M,0.0,N,0.0,K", b"# a comment", b"  # indented comment", b"#",
           b"", b" ", b"$", b"\x00\xff", b"garbage", b"$GPGGA,1200xx"]
_ENDS = [b"\r\n", b"\n", b"\r", b"\n\r", b"\r\r\n", b""]


@pytest.mark.parametrize("seed", range(40))
def test_every_kind_of_line(tmp_path: Path, seed: int, monkeypatch: pytest.MonkeyPatch) -> None:
    rng = random.Random(seed)
    if seed % 2:  # small reads and a small readline limit: long lines on both paths
        monkeypatch.setattr(replay, "_READ", rng.choice((5, 16, 64)))
        monkeypatch.setattr(replay, "_LINE_MAX", rng.choice((8, 40, 200)))
    parts = []
    t = 43190.0
    for _ in range(rng.randrange(0, 300)):
        if rng.random() < 0.5:
            t += rng.choice((0.1, 0.0, -1.0, 61.0, 0.5))
            hh, rest = divmod(t % 86400.0, 3600.0)
            mm, ss = divmod(rest, 60.0)
            parts.append(b"$GP%s,%02d%02d%05.2f,x" % (
                rng.choice((b"GGA", b"RMC", b"GST", b"VTG")), hh, mm, ss))
        else:
            parts.append(rng.choice(_PIECES) * rng.choice((1, 1, 1, 3)))
        parts.append(rng.choice(_ENDS))
    path = tmp_path / "log.nmea"
    path.write_bytes(b"".join(parts))
    _same(path)


def test_empty_log(tmp_path: Path) -> None:
    path = tmp_path / "empty.nmea"
    path.write_bytes(b"")
    assert list(_nmea_blocks(path, 10)) == [(0.0, b"")]
    _same(path)
