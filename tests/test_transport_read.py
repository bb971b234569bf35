"""drivers.transport.read_some reads what is there on every transport (issue G, first bullet).

pyserial's ``socket://`` handler reports ``in_waiting`` as 0 or 1, and ``read_some`` trusted
it: one byte a call, so a 50 Hz IMU link over ``socket://`` starved while the socket filled up.
The same tests run over a real TCP socket on 127.0.0.1, a real pty and ``loop://``.
"""

from __future__ import annotations

import socket
import threading
import time
from collections.abc import Callable, Iterator

import pytest

from drivers.ptypair import PtyPair
from drivers.resilient import ResilientPort
from drivers.transport import SerialSettings, open_port, read_some

FRAME = 40  # bytes: about a MAVLink 2 RAW_IMU packet
RATE_HZ = 50.0
DEADLINE_S = 5.0


def _frame(k: int) -> bytes:
    return bytes((k + i) % 256 for i in range(FRAME))


Writer = Callable[[bytes], None]


@pytest.fixture(params=["socket", "pty", "loop"])
def link(request: pytest.FixtureRequest) -> Iterator[tuple[Writer, ResilientPort]]:
    """(write to the far end, the project's port on this end) over one real transport."""
    kind = request.param
    if kind == "socket":
        with socket.create_server(("127.0.0.1", 0)) as server:
            url = f"socket://127.0.0.1:{server.getsockname()[1]}"
            port = ResilientPort(SerialSettings(url=url, timeout_s=0.05), name="imu")
            conn, _ = server.accept()
            with conn:
                yield conn.sendall, port
                port.close()
    elif kind == "pty":
        with PtyPair() as pty:
            port = ResilientPort(SerialSettings(url=pty.url, timeout_s=0.05), name="imu")
            yield pty.write, port
            port.close()
    else:
        port = ResilientPort(SerialSettings(url="loop://", timeout_s=0.05), name="imu")
        yield port.write, port
        port.close()


def test_one_read_per_tick_keeps_up_with_a_50hz_stream(link: tuple[Writer, ResilientPort]
                                                       ) -> None:
    """The vehicle's loop reads once per tick: one frame is written, one read_some follows.
    Every read returns the whole frame (before: 2 bytes over socket://, 38 left behind each
    tick: 9.5 kB piled up after 250 frames)."""
    write, port = link
    assert port.up
    got = bytearray()
    for k in range(250):  # 5 s of a 50 Hz stream
        write(_frame(k))
        got += port.read_some(4096)
        assert len(got) == FRAME * (k + 1), f"tick {k}: {FRAME * (k + 1) - len(got)} B behind"
    assert got == b"".join(_frame(k) for k in range(250))
    assert port.read_some(4096) == b""  # nothing left over


def test_a_burst_is_read_in_chunks(link: tuple[Writer, ResilientPort]) -> None:
    """12 kB at once (6 s of IMU frames after a stall) comes back in reads of up to 4096
    bytes, a handful in all (before: 6 000 reads over socket://)."""
    write, port = link
    data = b"".join(_frame(k) for k in range(300))
    writer = threading.Thread(target=write, args=(data,), daemon=True)  # a pty holds ~4 kB
    writer.start()
    got = bytearray()
    calls = 0
    deadline = time.monotonic() + DEADLINE_S
    while len(got) < len(data) and time.monotonic() < deadline:
        chunk = port.read_some(4096)
        assert len(chunk) <= 4096
        got += chunk
        calls += 1
    writer.join(DEADLINE_S)
    assert got == data
    # 3 full chunks; a pty passes its 4 kB buffer at a time while the writer refills it
    assert calls <= 6, calls


def test_a_paced_tcp_stream_arrives_in_about_one_read_per_frame() -> None:
    """A real TCP server on 127.0.0.1 streams 50 frames at 50 Hz to a ``socket://`` port read
    through drivers.transport: every byte arrives, in at most one read per frame plus the
    empty reads of the waits between frames (one per 50 ms timeout at most), and the reader
    is never more than one frame behind what was sent."""
    frames = 50
    sent = [0]
    with socket.create_server(("127.0.0.1", 0)) as server:
        url = f"socket://127.0.0.1:{server.getsockname()[1]}"
        port = open_port(SerialSettings(url=url, timeout_s=0.05))
        conn, _ = server.accept()

        def stream() -> None:
            t_next = time.monotonic()
            for k in range(frames):  # paced as the autopilot sends: the sender's own clock
                t_next += 1.0 / RATE_HZ
                time.sleep(max(0.0, t_next - time.monotonic()))
                conn.sendall(_frame(k))
                sent[0] += FRAME

        sender = threading.Thread(target=stream, daemon=True)
        sender.start()
        got = bytearray()
        calls = 0
        behind = 0
        deadline = time.monotonic() + DEADLINE_S
        while len(got) < frames * FRAME and time.monotonic() < deadline:
            before = sent[0]
            got += read_some(port, 4096)
            calls += 1
            behind = max(behind, before - len(got))
        sender.join(DEADLINE_S)
        conn.close()
        port.close()
    assert got == b"".join(_frame(k) for k in range(frames))
    # one read per frame, plus at most one empty 50 ms read per 20 ms gap (before: 1 000+)
    assert calls <= 2 * frames + 10, calls
    assert behind <= FRAME, behind
