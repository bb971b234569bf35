"""Outland driver over loop:// (hardware-free) and the sim server's byte protocol."""

from __future__ import annotations

from pathlib import Path

from drivers.outland.framecodec import Framer, decode, load_protocol
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
