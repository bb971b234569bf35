"""Outland driver over loop:// (hardware-free) and the sim server's byte protocol."""

from __future__ import annotations

import struct
from pathlib import Path

import pytest

from drivers.outland.framecodec import Framer, checksum, decode, load_protocol
from drivers.outland.link import OutlandLink, Telemetry, ThrusterCommand, encode_telemetry
from drivers.transport import SerialSettings, open_port
from firmware_host.devtools.rov_sim import RovPlant, RovSimServer, parse_fault
from firmware_host.rov.config import SimConfig
from firmware_host.runtime.loop import FakeClock

ROOT = Path(__file__).resolve().parent.parent
PROTO = load_protocol(ROOT / "config" / "protocols" / "outland1000.toml")


def test_rs232_streamed_telemetry_decoded_and_garbage_counted() -> None:
    port = open_port(SerialSettings(url="loop://", timeout_s=0.0))
    link = OutlandLink(port, PROTO, "rs232", node=1)
    tel = Telemetry(359.99, 12.5, 1.0, -2.0, 1)
    port.write(b"\x55\xaa" + encode_telemetry(PROTO, tel, 1) + encode_telemetry(PROTO, tel, 9))
    got = link.read_telemetry()
    assert len(got) == 1
    assert abs(got[0].heading_deg - 359.99) < 1e-9 and got[0].depth_m == 12.5
    assert link.rejects["garbage"] == 2 and link.rejects["wrong_node"] == 1
    port.close()


def test_rs485_poll_times_out_without_reply() -> None:
    # loop:// echoes our own command (a thrusters frame, not telemetry): no reply arrives.
    clock = FakeClock()
    port = open_port(SerialSettings(url="loop://", timeout_s=0.0))
    # every read advances the fake clock by 10 ms, like a port timeout would
    orig = port.read

    def read(size: int = 1) -> bytes:
        clock.advance(0.01)
        return bytes(orig(size))

    port.read = read  # type: ignore[method-assign]
    link = OutlandLink(port, PROTO, "rs485", node=1, reply_timeout_s=0.05, clock=clock)
    assert link.poll(ThrusterCommand(10, -10)) is None
    assert link.counts["timeouts"] == 1
    assert 0.05 <= clock() < 0.07
    port.close()


def test_sim_server_answers_polls_step_locked_and_ignores_other_nodes() -> None:
    plant = RovPlant(SimConfig(seed=3))
    srv = RovSimServer(plant, PROTO, "rs485", node=1)
    from drivers.outland.link import encode_command

    other = encode_command(PROTO, ThrusterCommand(50, -50), node=2, flags=0x80)
    assert srv.receive(other) == b""
    replies = [srv.receive(encode_command(PROTO, ThrusterCommand(50, -50), 1, 0x80))
               for _ in range(5)]
    frames = Framer(PROTO).feed(b"".join(replies))
    assert len(frames) == 5
    assert abs(plant.t - 4 * 0.2) < 1e-9  # first poll reads t = 0, then one period per poll
    assert plant.r > 0  # port > starboard turns to starboard (positive yaw rate)
    assert decode(PROTO, frames[0])[0] == "telemetry"


def test_sim_dropout_sends_nothing() -> None:
    plant = RovPlant(SimConfig(seed=3), [parse_fault("dropout@0-1")])
    srv = RovSimServer(plant, PROTO, "rs232")
    assert srv.tick() == b""  # t = 0.2
    plant.t = 1.0
    assert srv.tick() != b""


def _raw_telemetry(heading_raw: int) -> bytes:
    payload = struct.pack("<HHhhB", heading_raw, 1000, 0, 0, 0)
    head = bytes(PROTO.sync) + bytes((1, 0, 0x10, len(payload)))
    head += checksum(PROTO.header_checksum, head)
    return head + payload + checksum(PROTO.payload_checksum, payload)


def test_raw_heading_above_360_is_rejected_and_counted_not_wrapped() -> None:
    port = open_port(SerialSettings(url="loop://", timeout_s=0.0))
    link = OutlandLink(port, PROTO, "rs232", node=1)
    port.write(_raw_telemetry(36500) + _raw_telemetry(1234) + _raw_telemetry(65535))
    got = link.read_telemetry()
    assert [t.heading_deg for t in got] == [12.34]  # not 5.0 and 295.35 (the old % 360)
    assert link.rejects["out_of_range"] == 2
    port.close()


def test_encoder_sends_359_996_as_0_not_360() -> None:
    (frame,) = Framer(PROTO).feed(encode_telemetry(PROTO, Telemetry(359.996, 1.0), 1))
    assert decode(PROTO, frame)[1]["heading_deg"] == 0.0


def test_heading_jump_faster_than_the_vehicle_turns_is_flagged_not_hidden() -> None:
    """max_rate 120 deg/s at 5 Hz: 24 deg a sample. A 90 deg spike is passed on flagged and
    counted; the next sample is judged against the last plausible one; a real step is
    accepted once the vehicle could have turned that far (here after 0.4 s)."""
    clock = FakeClock()
    port = open_port(SerialSettings(url="loop://", timeout_s=0.0))
    link = OutlandLink(port, PROTO, "rs232", node=1, clock=clock)
    assert link.max_heading_rate == 120.0
    seq = [(0.0, 350.0), (0.2, 355.0), (0.4, 5.0),  # through north: 10 deg, plausible
           (0.6, 95.0),  # spike: 90 deg in 0.2 s
           (0.8, 8.0),  # back: 3 deg from the last plausible (5.0 at 0.4 s)
           (1.0, 60.0), (1.2, 60.0), (1.4, 60.0), (1.6, 60.0)]  # a 52 deg step that stays
    flags = []
    for t, h in seq:
        clock.now = t
        port.write(encode_telemetry(PROTO, Telemetry(h, 1.0), 1))
        (tel,) = link.read_telemetry()
        assert tel.heading_deg == pytest.approx(h)  # the value itself is passed on
        flags.append(tel.heading_suspect)
    assert flags == [False, False, False, True, False, True, True, False, False]
    assert link.counts["heading_suspect"] == 3
    port.close()
