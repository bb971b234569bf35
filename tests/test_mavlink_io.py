"""drivers.mavlink.io: typed MAVLink messages over real loopback UDP, decoding and .tlog reading."""

from __future__ import annotations

import struct
import subprocess
import sys
from collections import Counter
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from drivers.mavlink import io as mio
from fdi.errors import PortError
from firmware_host.runtime.config_mavlink import DEFAULT_ALLOW_UNSIGNED

ROOT = Path(__file__).resolve().parents[1]
SMALL_TLOG = ROOT.parent / "shared" / "corpus" / "ardusub" / "small.tlog"
DEADLINE_S = 5.0


@pytest.fixture()
def link() -> Iterator[tuple[mio.MavEndpoint, mio.MavEndpoint]]:
    """A pymavlink receiver on an ephemeral 127.0.0.1 port and a sender pointed at it."""
    rx = mio.MavEndpoint("udpin:127.0.0.1:0", source_system=255, source_component=190)
    addr = rx.local_address
    assert addr is not None
    tx = mio.MavEndpoint(f"udpout:127.0.0.1:{addr[1]}", source_system=7, source_component=191)
    yield tx, rx
    tx.close()
    rx.close()


def _recv_type(rx: mio.MavEndpoint, mtype: str) -> Any:
    msg = rx.recv(timeout_s=DEADLINE_S)
    assert msg is not None, f"no {mtype} within {DEADLINE_S} s"
    assert msg.get_type() == mtype
    return msg


FIX = mio.GpsInputFix(
    time_usec=1_234_567_890,
    gps_week=2300,
    gps_week_ms=345_678_900,
    fix_type=3,
    lat_deg=47.3977419,
    lon_deg=-122.1234567,
    alt_m=12.5,
    hdop=0.9,
    vdop=1.4,
    vn_mps=1.25,
    ve_mps=-0.5,
    vd_mps=0.125,
    speed_accuracy_mps=0.3,
    horiz_accuracy_m=2.5,
    vert_accuracy_m=4.0,
    satellites_visible=11,
    gps_id=0,
)


def test_gps_input_fields_and_units_over_udp(
    link: tuple[mio.MavEndpoint, mio.MavEndpoint],
) -> None:
    tx, rx = link
    sent = tx.send_gps_input(FIX)
    msg = _recv_type(rx, "GPS_INPUT")
    assert bytes(msg.get_msgbuf()) == sent
    assert sent[0] == 0xFD  # MAVLink 2
    assert msg.get_srcSystem() == 7 and msg.get_srcComponent() == 191
    assert msg.time_usec == 1_234_567_890
    assert msg.time_week == 2300 and msg.time_week_ms == 345_678_900
    assert msg.fix_type == 3 and msg.satellites_visible == 11 and msg.gps_id == 0
    assert msg.lat == 473977419  # degE7
    assert msg.lon == -1221234567
    assert msg.alt == pytest.approx(12.5)
    assert msg.hdop == pytest.approx(0.9, abs=1e-6)
    assert msg.vdop == pytest.approx(1.4, abs=1e-6)
    assert (msg.vn, msg.ve, msg.vd) == pytest.approx((1.25, -0.5, 0.125))
    assert msg.speed_accuracy == pytest.approx(0.3, abs=1e-6)
    assert msg.horiz_accuracy == pytest.approx(2.5)
    assert msg.vert_accuracy == pytest.approx(4.0)
    assert msg.ignore_flags == 0


def test_gps_input_ignore_flags_for_unknown_fields(
    link: tuple[mio.MavEndpoint, mio.MavEndpoint],
) -> None:
    tx, rx = link
    from dataclasses import replace

    tx.send_gps_input(replace(FIX, vdop=None, vn_mps=None, ve_mps=None, vd_mps=None))
    msg = _recv_type(rx, "GPS_INPUT")
    assert msg.ignore_flags == (
        mio.GPS_INPUT_IGNORE_FLAG_VDOP
        | mio.GPS_INPUT_IGNORE_FLAG_VEL_HORIZ
        | mio.GPS_INPUT_IGNORE_FLAG_VEL_VERT
    )
    assert msg.ignore_flags == 4 | 8 | 16
    assert (msg.vdop, msg.vn, msg.ve, msg.vd) == (0.0, 0.0, 0.0, 0.0)
    tx.send_gps_input(replace(FIX, vd_mps=None))
    assert _recv_type(rx, "GPS_INPUT").ignore_flags == 16


def test_statustext_short_and_chunked(link: tuple[mio.MavEndpoint, mio.MavEndpoint]) -> None:
    tx, rx = link
    tx.send_statustext(mio.MAV_SEVERITY_WARNING, "GPS fault isolated")
    msg = _recv_type(rx, "STATUSTEXT")
    assert msg.severity == 4 and msg.text == "GPS fault isolated" and msg.id == 0
    text = "".join(chr(ord("a") + i % 26) for i in range(120))
    sent = tx.send_statustext(mio.MAV_SEVERITY_CRITICAL, text)
    parts = [_recv_type(rx, "STATUSTEXT") for _ in range(3)]
    assert [p.chunk_seq for p in parts] == [0, 1, 2]
    assert len({p.id for p in parts}) == 1 and parts[0].id != 0
    assert "".join(p.text for p in parts) == text
    assert sent == b"".join(bytes(p.get_msgbuf()) for p in parts)


def test_statustext_chunks_exact_multiple_ends_with_empty_chunk() -> None:
    assert mio.statustext_chunks("x" * 50) == [b"x" * 50]
    assert mio.statustext_chunks("x" * 100) == [b"x" * 50, b"x" * 50, b""]
    assert mio.statustext_chunks("é") == [b"?"]


def test_heartbeat_is_an_onboard_controller(
    link: tuple[mio.MavEndpoint, mio.MavEndpoint],
) -> None:
    tx, rx = link
    tx.send_heartbeat()
    msg = _recv_type(rx, "HEARTBEAT")
    assert msg.type == 18 == mio.MAV_TYPE_ONBOARD_CONTROLLER
    assert msg.autopilot == 8 == mio.MAV_AUTOPILOT_INVALID
    assert msg.get_srcComponent() == 191


def test_request_mode_hold_is_do_set_mode_custom_4(
    link: tuple[mio.MavEndpoint, mio.MavEndpoint],
) -> None:
    tx, rx = link
    tx.request_mode(1, "HOLD")
    msg = _recv_type(rx, "COMMAND_LONG")
    assert msg.command == 176  # MAV_CMD_DO_SET_MODE
    assert msg.target_system == 1 and msg.target_component == 1
    assert msg.param1 == 1.0  # MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    assert msg.param2 == 4.0  # Rover HOLD
    assert mio.custom_mode_number("surface", "sub") == 9
    with pytest.raises(ValueError):
        mio.custom_mode_number("HOLD", "sub")


def test_named_value_float(link: tuple[mio.MavEndpoint, mio.MavEndpoint]) -> None:
    tx, rx = link
    tx.send_named_value_float("gps_ratio_long", 3.5, 1234)
    msg = _recv_type(rx, "NAMED_VALUE_FLOAT")
    assert msg.name == "gps_ratio_"  # cut at 10 characters
    assert msg.value == 3.5 and msg.time_boot_ms == 1234


def test_signed_packets_decode_and_carry_signature(
    link: tuple[mio.MavEndpoint, mio.MavEndpoint],
) -> None:
    tx, rx = link
    tx.setup_signing(bytes(range(32)), link_id=3)
    sent = tx.send_heartbeat()
    assert sent[2] & 0x01 and len(sent) == 10 + sent[1] + 2 + 13
    assert sent[-13] == 3  # link id
    assert _recv_type(rx, "HEARTBEAT").get_srcSystem() == 7


def test_packer_sequence_and_decode_packet() -> None:
    packer = mio.MavPacker(source_system=3, source_component=191)
    first = packer.send_heartbeat()
    second = packer.send_heartbeat()
    assert (first[4], second[4]) == (0, 1)  # sequence numbers
    msg = mio.decode_packet(first)
    assert msg is not None and msg.get_type() == "HEARTBEAT"
    corrupt = bytearray(first)
    corrupt[-1] ^= 0xFF
    assert mio.decode_packet(bytes(corrupt)) is None
    assert mio.decode_packet(first[:-3]) is None
    assert mio.crc_extra(0) == 50 and mio.crc_extra(2_000_000) is None
    assert mio.message_name(232) == "GPS_INPUT"
    assert mio.message_id("PARAM_SET") == 23


def test_open_failure_is_a_port_error() -> None:
    with pytest.raises(PortError):
        mio.MavEndpoint("/dev/fdi-bridge-no-such-serial-port", baud=115200)


@pytest.mark.skipif(not SMALL_TLOG.exists(), reason=f"corpus capture {SMALL_TLOG} is absent")
def test_iter_tlog_counts_on_the_ardusub_dive() -> None:
    records = list(mio.iter_tlog(SMALL_TLOG))
    # The issue states 35,916 messages, four of them BAD_DATA; pymavlink's own mavlogfile
    # reader agrees. Every record is one whole MAVLink 2 packet: the records tile the file.
    assert len(records) == 35_916
    assert sum(8 + len(r.raw) for r in records) == SMALL_TLOG.stat().st_size == 1_510_263
    bad = [r for r in records if r.msg is None]
    assert len(bad) == 4
    # The four are whole, well-framed packets from component 100 (a camera manager) whose CRC
    # matches the dialect's CRC_EXTRA only over a longer payload than was sent: a sender bug
    # (CRC computed before trailing zeros were cut), not line noise.
    assert [(r.raw[5], r.raw[6], r.raw[7] | r.raw[8] << 8) for r in bad] == [
        (1, 100, 259),  # CAMERA_INFORMATION
        (1, 100, 269),  # VIDEO_STREAM_INFORMATION
        (1, 100, 260),  # CAMERA_SETTINGS
        (1, 100, 262),  # CAMERA_CAPTURE_STATUS
    ]
    assert all(r.raw[0] == 0xFD for r in records)
    good = [r for r in records if r.msg is not None]
    assert all(bytes(r.msg.get_msgbuf()) == r.raw for r in good)
    types = Counter(r.msg.get_type() for r in good)
    assert types["ATTITUDE"] == 5245 and types["GPS_INPUT"] == 1011
    assert types["HEARTBEAT"] == 1056
    ts = [r.t_us for r in records]
    assert ts == sorted(ts)
    assert (ts[-1] - ts[0]) / 1e6 == pytest.approx(263, abs=2)


def test_iter_tlog_resyncs_after_garbage(tmp_path: Path) -> None:
    packer = mio.MavPacker()
    a, b = packer.send_heartbeat(), packer.send_statustext(6, "hello")
    path = tmp_path / "x.tlog"
    t0 = 1_700_000_000_000_000
    path.write_bytes(
        struct.pack(">Q", t0) + a
        + struct.pack(">Q", t0 + 1) + b"\x00\x01garbage"
        + struct.pack(">Q", t0 + 2) + b
        + struct.pack(">Q", t0 + 3) + b[:5]
    )  # fmt: skip
    records = list(mio.iter_tlog(path))
    assert [r.raw for r in records] == [a, b"\x00\x01garbage", b, b[:5]]
    assert [r.msg is None for r in records] == [False, True, False, True]
    assert [r.t_us - t0 for r in records] == [0, 1, 2, 3]


def test_enum_constants_are_pymavlinks() -> None:
    """drivers.mavlink.io spells the standard's numbers so that importing it does not import
    pymavlink; each must be the dialect's own value."""
    from pymavlink.dialects.v20 import ardupilotmega as dialect

    names = [n for n in dir(mio) if n.startswith(("MAV_", "GPS_INPUT_IGNORE_FLAG_"))]
    assert len(names) >= 27
    for name in names:
        assert getattr(mio, name) == getattr(dialect, name), name


def test_importing_the_io_module_does_not_import_pymavlink() -> None:
    code = ("import sys, drivers.mavlink.io as m; assert 'pymavlink' not in sys.modules; "
            "m.message_id('HEARTBEAT'); assert 'pymavlink.mavutil' in sys.modules")
    subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT)


def test_default_unsigned_pass_list_names_dialect_messages() -> None:
    ids = [mio.message_id(name) for name in DEFAULT_ALLOW_UNSIGNED]  # KeyError if not
    assert ids == [109, 166]  # RADIO_STATUS, RADIO: ArduPilot's unsigned accept list
