"""The one door to pymavlink: dialect, encoding, decoding, connections and ``.tlog`` reading.

pymavlink keeps process-wide state: ``mavutil`` picks its dialect and wire protocol from the
environment variables ``MAVLINK_DIALECT`` and ``MAVLINK20`` when it is first imported, and
``mavutil.set_dialect`` swaps a module-global. This module is the only one in fdi-bridge that
imports pymavlink (STYLE.md rule 7). It fixes the dialect to **ardupilotmega** and the wire
protocol to **MAVLink 2** here, before ``mavutil`` is imported, and nowhere else. Everything the
rest of the project needs from pymavlink goes through the functions and classes below:

* :class:`GpsInputFix` and :class:`MavEndpoint` -- a mavutil connection (``udpout:``,
  ``udpin:``, ``tcp:``, a serial path) that sends typed messages and returns the bytes it sent;
* :class:`MavPacker` -- the same encoders without a connection: each call returns the packed
  packet (the router's own component writes those bytes where it wants);
* :func:`decode_packet` -- one framed packet (bytes) to a decoded message, or ``None``;
* :func:`crc_extra` / :func:`message_name` -- the dialect's per-message tables, for the framer;
* :func:`iter_tlog` -- a QGroundControl ``.tlog`` as ``(timestamp, raw bytes, message)`` records.

pymavlink's exceptions are translated into :class:`~fdi.errors.PortError` where a transport is
opened or written; bad packets are answered with ``None`` (a counted policy, never a guess).
"""

from __future__ import annotations

import binascii
import contextlib
import logging
import math
import os
import struct
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final, NamedTuple

from drivers.mavlink.modes import mode_number
from fdi.errors import PortError

DIALECT = "ardupilotmega"
_log = logging.getLogger("fdi_bridge.mavlink")

# pymavlink is imported on first use, not with this module: a rover replay or run without
# MAVLink never pays its ~0.13 s of start-up (issue 19). pymavlink reads these variables when
# mavutil is imported and whenever set_dialect() runs: they are fixed here, once, for the whole
# process (rule 7). MAVLINK20 selects the v20 dialect modules, which send MAVLink 2 and still
# decode MAVLink 1.
os.environ["MAVLINK20"] = "1"
os.environ["MAVLINK_DIALECT"] = DIALECT

_pymavlink: tuple[Any, Any] | None = None


def _load() -> tuple[Any, Any]:
    """``(mavutil, the ardupilotmega v20 dialect module)``, imported once (third-party only)."""
    global _pymavlink
    if _pymavlink is None:
        from pymavlink import mavutil
        from pymavlink.dialects.v20 import ardupilotmega

        if mavutil.current_dialect != DIALECT:  # imported before us with another dialect
            mavutil.set_dialect(DIALECT)
        _pymavlink = (mavutil, ardupilotmega)
    return _pymavlink


def _mavutil() -> Any:
    return _load()[0]


def _dialect() -> Any:
    return _load()[1]


def MAVLink(file: Any, srcSystem: int = 0, srcComponent: int = 0) -> Any:
    """A pymavlink ``MAVLink`` codec object of the dialect (pymavlink's own signature)."""
    return _dialect().MAVLink(file, srcSystem=srcSystem, srcComponent=srcComponent)


def mav_error() -> type[Exception]:
    """pymavlink's ``MAVError`` class (for ``except`` clauses)."""
    return _dialect().MAVError


# Enum values the rest of the project may use without importing pymavlink: the MAVLink
# standard's numbers (tests/test_mavlink_io.py keeps them equal to pymavlink's).
MAV_TYPE_GCS: Final = 6
MAV_TYPE_ONBOARD_CONTROLLER: Final = 18
MAV_AUTOPILOT_INVALID: Final = 8
MAV_STATE_ACTIVE: Final = 4
MAV_TYPE_SUBMARINE: Final = 12
MAV_AUTOPILOT_ARDUPILOTMEGA: Final = 3
MAV_MODE_FLAG_SAFETY_ARMED: Final = 128
MAV_CMD_DO_SET_MODE: Final = 176
MAV_MODE_FLAG_CUSTOM_MODE_ENABLED: Final = 1
MAV_PARAM_TYPE_REAL32: Final = 9
MAV_PARAM_TYPE_INT32: Final = 6
MAV_RESULT_IN_PROGRESS: Final = 5
MAV_RESULT_ACCEPTED: Final = 0
MAV_RESULT_DENIED: Final = 2
MAV_RESULT_UNSUPPORTED: Final = 3
MAV_SEVERITY_EMERGENCY: Final = 0
MAV_SEVERITY_ALERT: Final = 1
MAV_SEVERITY_CRITICAL: Final = 2
MAV_SEVERITY_ERROR: Final = 3
MAV_SEVERITY_WARNING: Final = 4
MAV_SEVERITY_NOTICE: Final = 5
MAV_SEVERITY_INFO: Final = 6
MAV_SEVERITY_DEBUG: Final = 7

GPS_INPUT_IGNORE_FLAG_ALT: Final = 1
GPS_INPUT_IGNORE_FLAG_VDOP: Final = 4
GPS_INPUT_IGNORE_FLAG_VEL_HORIZ: Final = 8
GPS_INPUT_IGNORE_FLAG_VEL_VERT: Final = 16

STATUSTEXT_LEN = 50
"""Bytes of text one STATUSTEXT carries; longer text is sent as chunks (MAVLink 2 ``id``)."""
NAMED_VALUE_NAME_LEN = 10
PARAM_ID_LEN = 16

def pymavlink_mode_tables() -> dict[str, dict[int, str]]:
    """Custom-mode tables per vehicle, from pymavlink (ArduPilot's mode numbers): number ->
    name. drivers.mavlink.modes holds the same tables without pymavlink (a test keeps them
    equal)."""
    mu = _mavutil()
    return {"rover": mu.mode_mapping_rover, "boat": mu.mode_mapping_rover,
            "sub": mu.mode_mapping_sub, "copter": mu.mode_mapping_acm,
            "plane": mu.mode_mapping_apm}


def crc_extra(msgid: int) -> int | None:
    """The CRC_EXTRA seed byte of message ``msgid`` in the dialect, or None when unknown."""
    cls = _dialect().mavlink_map.get(msgid)
    return None if cls is None else int(cls.crc_extra)


def crc_extra_table() -> dict[int, int]:
    """``{msgid: CRC_EXTRA}`` for every message of the dialect (a fresh dict)."""
    return {msgid: int(cls.crc_extra) for msgid, cls in _dialect().mavlink_map.items()}


def payload_length_table() -> dict[int, int]:
    """``{msgid: payload length with every extension field}`` for the dialect."""
    return {msgid: int(cls.unpacker.size) for msgid, cls in _dialect().mavlink_map.items()}


def target_offsets() -> dict[int, tuple[int | None, int | None]]:
    """``{msgid: (target_system offset, target_component offset)}`` in the wire payload.

    Only messages with a target field are listed. MANUAL_CONTROL's field ``target`` ("the
    system to be controlled") counts as its target system. Offsets are into the untruncated
    payload; a MAVLink 2 packet whose payload was cut before the offset has target 0 there.
    """
    out: dict[int, tuple[int | None, int | None]] = {}
    for msgid, cls in _dialect().mavlink_map.items():
        names = list(cls.ordered_fieldnames)
        offset = 0
        offsets: dict[str, int] = {}
        for i, name in enumerate(names):
            offsets[name] = offset
            code = chr(cls.native_format[i + 1])  # [0] is the "<" byte-order mark
            offset += struct.calcsize("<" + code) * max(1, int(cls.array_lengths[i]))
        sys_name = "target_system" if "target_system" in offsets else None
        if sys_name is None and "target" in offsets and cls.msgname == "MANUAL_CONTROL":
            sys_name = "target"
        if sys_name is None:
            continue
        out[msgid] = (offsets[sys_name], offsets.get("target_component"))
    return out


def message_name(msgid: int) -> str | None:
    """The dialect's name of message ``msgid`` (``"HEARTBEAT"``), or None when unknown."""
    cls = _dialect().mavlink_map.get(msgid)
    return None if cls is None else str(cls.msgname)


def message_id(name: str) -> int:
    """The id of the message called ``name`` (``"PARAM_SET"`` -> 23); KeyError if unknown."""
    return int(getattr(_dialect(), f"MAVLINK_MSG_ID_{name}"))


def custom_mode_number(mode: str, vehicle: str = "rover") -> int:
    """ArduPilot's custom-mode number of ``mode`` on ``vehicle`` (``"HOLD"``, rover -> 4)."""
    return mode_number(mode, vehicle)


@dataclass(frozen=True)
class GpsInputFix:
    """A fix for the autopilot's MAVLink GPS (GPS_INPUT; ArduPilot ``GPSn_TYPE = 14``).

    ``None`` velocity components, ``vdop`` or ``alt_m`` are sent as zero with the matching
    ignore flag (AP_GPS_MAV then leaves the altitude at 0 and the velocity at its *previous*
    value: the sink never sends an ignored velocity on a fix, see
    :class:`firmware_host.rover.outputs.MavlinkGpsSink`). ``yaw_deg`` (a dual-antenna heading)
    is sent in centidegrees, north as 36000 (0 means "no yaw" in GPS_INPUT).
    """

    time_usec: int  # bridge's own timestamp (µs)
    gps_week: int
    gps_week_ms: int
    fix_type: int  # 0/1 no fix, 2 2D, 3 3D, 4 DGPS, 5 RTK float, 6 RTK fixed (GPS_FIX_TYPE)
    lat_deg: float
    lon_deg: float
    alt_m: float | None  # AMSL; None: not known (GPS_INPUT_IGNORE_FLAG_ALT)
    hdop: float
    vdop: float | None
    vn_mps: float | None
    ve_mps: float | None
    vd_mps: float | None
    speed_accuracy_mps: float
    horiz_accuracy_m: float
    vert_accuracy_m: float
    satellites_visible: int
    gps_id: int = 0
    yaw_deg: float | None = None


def gps_input_ignore_flags(fix: GpsInputFix) -> int:
    """GPS_INPUT_IGNORE_FLAGS for the fields of ``fix`` that are not known."""
    flags = 0
    if fix.alt_m is None:
        flags |= GPS_INPUT_IGNORE_FLAG_ALT
    if fix.vdop is None:
        flags |= GPS_INPUT_IGNORE_FLAG_VDOP
    if fix.vn_mps is None or fix.ve_mps is None:
        flags |= GPS_INPUT_IGNORE_FLAG_VEL_HORIZ
    if fix.vd_mps is None:
        flags |= GPS_INPUT_IGNORE_FLAG_VEL_VERT
    return flags


def _or0(value: float | None) -> float:
    return 0.0 if value is None else float(value)


def gps_input_yaw(yaw_deg: float | None) -> int:
    """GPS_INPUT ``yaw`` (cdeg, 1..36000; 0 = not available) of a heading in degrees."""
    if yaw_deg is None or not math.isfinite(yaw_deg):
        return 0
    cdeg = round(yaw_deg % 360.0 * 100.0) % 36000
    return cdeg or 36000


def statustext_chunks(text: str) -> list[bytes]:
    """Split ``text`` (ASCII; other characters become ``?``) into 50-byte STATUSTEXT chunks.

    A text that fills its last chunk exactly is followed by an empty chunk, so the receiver sees
    the NUL that ends a chunked text (MAVLink STATUSTEXT ``chunk_seq`` rule).
    """
    data = text.encode("ascii", errors="replace")
    if len(data) <= STATUSTEXT_LEN:
        return [data]
    chunks = [data[i : i + STATUSTEXT_LEN] for i in range(0, len(data), STATUSTEXT_LEN)]
    if len(chunks[-1]) == STATUSTEXT_LEN:
        chunks.append(b"")
    return chunks


class ManualControlExt(NamedTuple):
    """MANUAL_CONTROL's MAVLink 2 extension fields, as a pilot's frame carries them.

    ``buttons2`` (buttons 16-31), ``enabled_extensions`` (bit 0: ``s`` valid, bit 1: ``t``,
    bits 2-7: ``aux1``-``aux6``), the ``s``/``t`` axes (pitch, roll; -1000..1000) and
    ``aux1``-``aux6``. All 0 is a frame without extensions. ArduSub takes every one of them
    (``Sub::transform_manual_control_to_rc_override``; buttons 16-31 act on their edges).
    """

    buttons2: int = 0
    enabled_extensions: int = 0
    s: int = 0
    t: int = 0
    aux: tuple[int, int, int, int, int, int] = (0, 0, 0, 0, 0, 0)

    @classmethod
    def of(cls, msg: Any) -> ManualControlExt:
        """The extension fields of a decoded MANUAL_CONTROL (0 where a MAVLink 1 frame or an
        older sender left them out)."""
        aux = tuple(int(getattr(msg, f"aux{i}", 0)) for i in range(1, 7))
        return cls(int(getattr(msg, "buttons2", 0)), int(getattr(msg, "enabled_extensions", 0)),
                   int(getattr(msg, "s", 0)), int(getattr(msg, "t", 0)),
                   (aux[0], aux[1], aux[2], aux[3], aux[4], aux[5]))

    def values(self) -> tuple[int, ...]:
        """The ten values in MANUAL_CONTROL's field order (after ``buttons``)."""
        return (self.buttons2, self.enabled_extensions, self.s, self.t, *self.aux)


class _Encoders:
    """Typed encoders shared by :class:`MavEndpoint` and :class:`MavPacker`.

    Subclasses provide ``_mav`` (a pymavlink ``MAVLink``) and ``_emit(msg) -> bytes``.
    """

    _mav: Any
    _statustext_id = 0

    def _emit(self, msg: Any) -> bytes:
        raise NotImplementedError

    def send_gps_input(self, fix: GpsInputFix) -> bytes:
        msg = self._mav.gps_input_encode(
            int(fix.time_usec),
            int(fix.gps_id),
            gps_input_ignore_flags(fix),
            int(fix.gps_week_ms),
            int(fix.gps_week),
            int(fix.fix_type),
            round(fix.lat_deg * 1e7),
            round(fix.lon_deg * 1e7),
            _or0(fix.alt_m),
            float(fix.hdop),
            _or0(fix.vdop),
            _or0(fix.vn_mps),
            _or0(fix.ve_mps),
            _or0(fix.vd_mps),
            float(fix.speed_accuracy_mps),
            float(fix.horiz_accuracy_m),
            float(fix.vert_accuracy_m),
            int(fix.satellites_visible),
            gps_input_yaw(fix.yaw_deg),
        )
        return self._emit(msg)

    def send_statustext(self, severity: int, text: str) -> bytes:
        """One STATUSTEXT, or several chunks sharing a nonzero ``id`` when text > 50 bytes."""
        chunks = statustext_chunks(text)
        if len(chunks) == 1:
            return self._emit(self._mav.statustext_encode(severity, chunks[0]))
        self._statustext_id = self._statustext_id % 0xFFFF + 1
        out = b""
        for seq, chunk in enumerate(chunks):
            msg = self._mav.statustext_encode(severity, chunk, self._statustext_id, seq)
            out += self._emit(msg)
        return out

    def send_heartbeat(self) -> bytes:
        """MAV_TYPE_ONBOARD_CONTROLLER / MAV_AUTOPILOT_INVALID: a companion, not a vehicle."""
        msg = self._mav.heartbeat_encode(
            MAV_TYPE_ONBOARD_CONTROLLER, MAV_AUTOPILOT_INVALID, 0, 0, MAV_STATE_ACTIVE
        )
        return self._emit(msg)

    def send_vehicle_heartbeat(self, mav_type: int, base_mode: int, custom_mode: int) -> bytes:
        """HEARTBEAT of a vehicle (a simulated autopilot: type, armed flag, flight mode)."""
        msg = self._mav.heartbeat_encode(
            mav_type, MAV_AUTOPILOT_ARDUPILOTMEGA, base_mode, custom_mode, MAV_STATE_ACTIVE
        )
        return self._emit(msg)

    def request_mode(self, target_system: int, mode: str, vehicle: str = "rover") -> bytes:
        """Ask the autopilot for a custom mode (``"HOLD"`` on a rover is custom mode 4).

        Sent as COMMAND_LONG MAV_CMD_DO_SET_MODE (param1 = MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
        param2 = custom mode) to component 1 (the autopilot), not the deprecated SET_MODE
        message: ArduPilot answers a COMMAND_LONG with COMMAND_ACK, so the bridge learns
        whether the mode change was accepted.
        """
        number = custom_mode_number(mode, vehicle)
        msg = self._mav.command_long_encode(
            target_system,
            1,
            MAV_CMD_DO_SET_MODE,
            0,
            float(MAV_MODE_FLAG_CUSTOM_MODE_ENABLED),
            float(number),
            0.0,
            0.0,
            0.0,
            0.0,
            0.0,
        )
        return self._emit(msg)

    def send_raw_imu(self, time_usec: int, acc: tuple[int, int, int],
                     gyro: tuple[int, int, int], imu_id: int = 0,
                     mag: tuple[int, int, int] = (0, 0, 0)) -> bytes:
        """RAW_IMU in ArduPilot's scaling (mG, mrad/s; see drivers/mavlink/imu.py), the compass
        in mGauss (all 0: none; drivers/mavlink/compass.py)."""
        msg = self._mav.raw_imu_encode(int(time_usec), *acc, *gyro, *mag, int(imu_id), 0)
        return self._emit(msg)

    def send_scaled_imu(self, instance: int, time_boot_ms: int, acc: tuple[int, int, int],
                        gyro: tuple[int, int, int], mag: tuple[int, int, int]) -> bytes:
        """SCALED_IMU (``instance`` 0), SCALED_IMU2 (1) or SCALED_IMU3 (2): mG, mrad/s, mGauss."""
        enc = (self._mav.scaled_imu_encode, self._mav.scaled_imu2_encode,
               self._mav.scaled_imu3_encode)[instance]
        msg = enc(int(time_boot_ms) & 0xFFFFFFFF, *acc, *gyro, *mag, 0)
        return self._emit(msg)

    def send_rc_channels_override(self, target_system: int, target_component: int,
                                  channels: tuple[int, ...]) -> bytes:
        """RC_CHANNELS_OVERRIDE with ``channels`` (18 values, µs; per the MAVLink spec
        UINT16_MAX ignores channels 1-8 and 0 releases them; 0 or UINT16_MAX ignores 9-18)."""
        if len(channels) != 18:
            raise ValueError("RC_CHANNELS_OVERRIDE takes 18 channel values")
        msg = self._mav.rc_channels_override_encode(target_system, target_component,
                                                    *(int(c) for c in channels))
        return self._emit(msg)

    def send_highres_imu(self, time_usec: int, acc: tuple[float, float, float],
                         gyro: tuple[float, float, float], imu_id: int = 0) -> bytes:
        """HIGHRES_IMU (m/s², rad/s); fields_updated says accel and gyro only (bits 0-5)."""
        msg = self._mav.highres_imu_encode(int(time_usec), *acc, *gyro, 0.0, 0.0, 0.0, 0.0, 0.0,
                                           0.0, 0.0, 0x3F, int(imu_id))
        return self._emit(msg)

    def send_system_time(self, time_unix_usec: int, time_boot_ms: int) -> bytes:
        msg = self._mav.system_time_encode(int(time_unix_usec), int(time_boot_ms) & 0xFFFFFFFF)
        return self._emit(msg)

    def send_named_value_float(self, name: str, value: float, time_boot_ms: int) -> bytes:
        """NAMED_VALUE_FLOAT; ``name`` is cut to 10 ASCII bytes."""
        raw = name.encode("ascii", errors="replace")[:NAMED_VALUE_NAME_LEN]
        msg = self._mav.named_value_float_encode(int(time_boot_ms) & 0xFFFFFFFF, raw, value)
        return self._emit(msg)

    def send_param_value(self, name: str, value: float, index: int, count: int,
                         param_type: int = MAV_PARAM_TYPE_REAL32) -> bytes:
        """PARAM_VALUE (``name`` up to 16 ASCII bytes) of a REAL32 or INT32 parameter.

        An INT32 value travels as a float holding the integer's value (what ArduPilot,
        MAVProxy and QGroundControl do for ``param_value``), rounded here.
        """
        raw = name.encode("ascii", errors="replace")[:PARAM_ID_LEN]
        if param_type != MAV_PARAM_TYPE_REAL32:
            value = float(round(value))
        msg = self._mav.param_value_encode(raw, value, param_type, count, index)
        return self._emit(msg)

    def send_command_ack(
        self, command: int, result: int, target_system: int = 0, target_component: int = 0
    ) -> bytes:
        msg = self._mav.command_ack_encode(command, result, 0, 0, target_system, target_component)
        return self._emit(msg)

    def send_manual_control(
        self, target_system: int, x: int, y: int, z: int, r: int, buttons: int = 0,
        ext: ManualControlExt | None = None,
    ) -> bytes:
        """MANUAL_CONTROL (x/y/r in -1000..1000, z in 0..1000 on ArduSub, 500 = neutral), with
        the extension fields of ``ext`` (none: all 0)."""
        more = () if ext is None else ext.values()
        msg = self._mav.manual_control_encode(target_system, x, y, z, r, buttons, *more)
        return self._emit(msg)

    def send_attitude(
        self, time_boot_ms: int, roll_rad: float, pitch_rad: float, yaw_rad: float,
        rates_rad_s: tuple[float, float, float] = (0.0, 0.0, 0.0),
    ) -> bytes:
        """ATTITUDE (angles in rad; body rates p, q, r in rad/s, zero unless given), as an
        autopilot reports its heading."""
        msg = self._mav.attitude_encode(
            int(time_boot_ms) & 0xFFFFFFFF, roll_rad, pitch_rad, yaw_rad, *rates_rad_s
        )
        return self._emit(msg)

    def send_ahrs2(self, roll_rad: float, pitch_rad: float, yaw_rad: float) -> bytes:
        """AHRS2 (ArduPilot's second attitude estimate; angles in rad, no position)."""
        msg = self._mav.ahrs2_encode(roll_rad, pitch_rad, yaw_rad, 0.0, 0, 0)
        return self._emit(msg)

    def send_gps_raw_int(self, time_usec: int, fix_type: int, lat_deg: float, lon_deg: float,
                         alt_m: float, satellites: int) -> bytes:
        """GPS_RAW_INT (an autopilot's report of its GPS: what it made of a GPS_INPUT; a
        simulated autopilot's echo); accuracies and velocity unknown (UINT16_MAX)."""
        msg = self._mav.gps_raw_int_encode(
            time_usec, fix_type, round(lat_deg * 1e7), round(lon_deg * 1e7), round(alt_m * 1e3),
            65535, 65535, 65535, 65535, satellites)
        return self._emit(msg)

    def send_param_set(
        self, target_system: int, target_component: int, name: str, value: float
    ) -> bytes:
        raw = name.encode("ascii", errors="replace")[:PARAM_ID_LEN]
        msg = self._mav.param_set_encode(
            target_system, target_component, raw, value, MAV_PARAM_TYPE_REAL32
        )
        return self._emit(msg)

    def send_file_transfer_protocol(self, target_system: int, target_component: int,
                                    payload: bytes, target_network: int = 0) -> bytes:
        """FILE_TRANSFER_PROTOCOL (MAVLink FTP) with ``payload`` (at most 251 bytes)."""
        data = list(payload[:251]) + [0] * (251 - min(len(payload), 251))
        msg = self._mav.file_transfer_protocol_encode(target_network, target_system,
                                                      target_component, data)
        return self._emit(msg)

    def send_param_request_list(self, target_system: int, target_component: int) -> bytes:
        return self._emit(self._mav.param_request_list_encode(target_system, target_component))

    def send_param_request_read(
        self, target_system: int, target_component: int, name: str, index: int = -1
    ) -> bytes:
        raw = name.encode("ascii", errors="replace")[:PARAM_ID_LEN]
        msg = self._mav.param_request_read_encode(target_system, target_component, raw, index)
        return self._emit(msg)

    def setup_signing(self, key: bytes, *, link_id: int = 0, timestamp: int | None = None) -> None:
        """Sign every packet sent from now on with the 32-byte ``key`` (MAVLink 2 signing).

        ``timestamp`` is in 10 µs units since 2015-01-01 (default: now).
        """
        if len(key) != 32:
            raise ValueError("a MAVLink signing key is 32 bytes")
        signing = self._mav.signing
        signing.secret_key = bytes(key)
        signing.sign_outgoing = True
        signing.link_id = link_id
        signing.timestamp = signing_timestamp_now() if timestamp is None else timestamp
        self._sign_clock = _signing_clock if timestamp is None else None

    _sign_clock: Any = None

    def _stamp(self) -> None:
        """Before each signed packet: timestamp = max(last + 1, now) (MAVLink 2 signing spec).

        pymavlink adds 1 per packet only, so a stream sent at 1 packet/s would lag the clock by
        almost a second per second, and a receiver that starts listening later (or reboots)
        refuses a new stream more than a minute old.
        """
        clock = self._sign_clock
        if clock is not None:
            signing = self._mav.signing
            now = clock()
            if now > signing.timestamp:
                signing.timestamp = now


_SIGNING_EPOCH_S = 1420070400  # 2015-01-01T00:00:00Z


def _signing_clock() -> int:
    return signing_timestamp_now()


def signing_timestamp_now(now_s: float | None = None) -> int:
    """A MAVLink signing timestamp (10 µs units since 2015-01-01) for ``now_s`` (Unix s)."""
    t = time.time() if now_s is None else now_s
    return int(max(0.0, t - _SIGNING_EPOCH_S) * 100_000)


class _Sink:
    """A file-like object pymavlink's ``MAVLink.send`` writes into; keeps the last packet."""

    def __init__(self) -> None:
        self.last = b""

    def write(self, buf: bytes) -> None:
        self.last = bytes(buf)


class MavPacker(_Encoders):
    """The encoders of :class:`MavEndpoint` with no connection: each call returns the packet.

    The sequence number advances per packet as on a real link; signing works the same way.
    """

    def __init__(self, source_system: int = 1, source_component: int = 191) -> None:
        self._sink = _Sink()
        self._mav = MAVLink(self._sink, srcSystem=source_system, srcComponent=source_component)

    @property
    def source_system(self) -> int:
        return int(self._mav.srcSystem)

    @property
    def source_component(self) -> int:
        return int(self._mav.srcComponent)

    def _emit(self, msg: Any) -> bytes:
        if self._sign_clock is not None:
            self._stamp()
        self._mav.send(msg)
        return self._sink.last


class PortEndpoint(MavPacker):
    """The encoders of :class:`MavEndpoint` writing to a byte port: a serial line to the autopilot.

    Give it a :class:`drivers.resilient.ResilientPort`: its writes never raise, a lost device
    (USB unplugged, the autopilot rebooting) is reported once and reopened with backoff, and
    what is sent while it is down is dropped and counted (``port.tx_dropped``).
    """

    def __init__(self, port: Any, source_system: int = 1, source_component: int = 191) -> None:
        super().__init__(source_system, source_component)
        self.port = port
        self.url = str(getattr(port, "port", "port"))
        self.partial_bytes = 0  # bytes a full line did not take (the packet is lost to the peer)

    def _emit(self, msg: Any) -> bytes:
        data = super()._emit(msg)
        self.send_raw(data)
        return data

    def send_raw(self, data: bytes) -> None:
        """Write without blocking: on a full line the rest is dropped and counted."""
        n = self.port.write(data)
        if n is not None and 0 < n < len(data):
            self.partial_bytes += len(data) - n

    def close(self) -> None:
        self.port.close()


class MavEndpoint(_Encoders):
    """A pymavlink connection by URL that sends typed messages and returns the bytes sent.

    ``url`` is what ``mavutil.mavlink_connection`` takes: ``udpout:HOST:PORT`` (send to),
    ``udpin:HOST:PORT`` (listen on; port 0 picks a free one, see :attr:`local_address`),
    ``tcp:HOST:PORT``, ``tcpin:HOST:PORT`` or a serial device path with ``baud``.
    """

    def __init__(
        self,
        url: str,
        *,
        source_system: int = 1,
        source_component: int = 191,
        baud: int = 57600,
    ) -> None:
        self.url = url
        self.bad_packets = 0
        try:
            self._conn = _mavutil().mavlink_connection(
                url,
                baud=baud,
                source_system=source_system,
                source_component=source_component,
                dialect=DIALECT,
                autoreconnect=False,
            )
        except (OSError, ValueError, mav_error()) as err:
            raise PortError(f"could not open MAVLink endpoint {url!r}: {err}") from err
        except Exception as err:  # serial.SerialException and other driver errors
            raise PortError(f"could not open MAVLink endpoint {url!r}: {err}") from err
        self._mav = self._conn.mav

    @property
    def local_address(self) -> tuple[str, int] | None:
        """``(host, port)`` the underlying socket is bound to, or None (serial, file)."""
        port = getattr(self._conn, "port", None)
        getsockname = getattr(port, "getsockname", None)
        if getsockname is None:
            return None
        host, portnum = getsockname()[:2]
        return str(host), int(portnum)

    def _emit(self, msg: Any) -> bytes:
        if self._sign_clock is not None:
            self._stamp()
        try:
            self._mav.send(msg)
        except OSError as err:
            raise PortError(f"could not write to {self.url!r}: {err}") from err
        if self._pending is not None:
            self._service_command()
        elif self.on_message is not None:  # someone watches what comes back: read it now
            self.drain(64)
        return bytes(msg.get_msgbuf())

    _pending: tuple[int, int, Any] | None = None  # (command, attempts, re-encode)
    _pending_due = 0.0
    command_retries = 5
    command_retry_s = 1.0

    @property
    def command_stats(self) -> dict[str, int]:
        """COMMAND_LONGs of :meth:`request_mode`: sent (with retries), accepted, refused,
        unacknowledged after :attr:`command_retries` attempts."""
        if "_cmd_stats" not in self.__dict__:
            self._cmd_stats = {"command_sent": 0, "command_accepted": 0,
                               "command_refused": 0, "command_unacked": 0}
        return self._cmd_stats

    def request_mode(self, target_system: int, mode: str, vehicle: str = "rover") -> bytes:
        """As :meth:`_Encoders.request_mode`, then wait (without blocking: at each later send)
        for the autopilot's COMMAND_ACK, resending every :attr:`command_retry_s` up to
        :attr:`command_retries` times; a refusal or no answer is counted and logged."""
        self._pending = None
        raw = super().request_mode(target_system, mode, vehicle)
        self.command_stats["command_sent"] += 1

        def again() -> bytes:
            return super(MavEndpoint, self).request_mode(target_system, mode, vehicle)

        self._pending = (MAV_CMD_DO_SET_MODE, 1, again)
        self._pending_due = time.monotonic() + self.command_retry_s
        self._pending_what = f"mode {mode}"
        return raw

    on_message: Callable[[Any], None] | None = None  # every message read (the status's echo)

    def drain(self, limit: int = 1024) -> int:
        """Read what has arrived, without blocking (at most ``limit`` messages): each goes to
        :attr:`on_message`, and a pending command's COMMAND_ACK settles it as at a send."""
        n = 0
        while n < limit and (msg := self._recv_nowait()) is not None:
            n += 1
            self._settles(msg)
        return n

    def _recv_nowait(self) -> Any | None:
        try:
            msg = self._conn.recv_msg()
        except OSError:
            return None
        if msg is not None and self.on_message is not None:
            self.on_message(msg)
        return msg

    def _settles(self, msg: Any) -> bool:
        """True when ``msg`` is the pending command's final COMMAND_ACK (counted, logged)."""
        pending = self._pending
        if pending is None or msg.get_type() != "COMMAND_ACK" or int(msg.command) != pending[0]:
            return False
        result = int(msg.result)
        if result == MAV_RESULT_IN_PROGRESS:
            self._pending_due = time.monotonic() + self.command_retry_s
            return False
        self._pending = None
        key = "command_accepted" if result == MAV_RESULT_ACCEPTED else "command_refused"
        self.command_stats[key] += 1
        if result != MAV_RESULT_ACCEPTED:
            _log.warning("autopilot refused %s (MAV_RESULT %d)", self._pending_what, result)
        return True

    def _service_command(self) -> None:
        pending = self._pending
        if pending is None:
            return
        command, attempts, again = pending
        for _ in range(64):  # what arrived since the last send (non-blocking)
            msg = self._recv_nowait()
            if msg is None:
                break
            if self._settles(msg):
                return
        if time.monotonic() < self._pending_due:
            return
        if attempts >= self.command_retries:
            self._pending = None
            self.command_stats["command_unacked"] += 1
            _log.warning("no COMMAND_ACK for %s after %d attempts", self._pending_what, attempts)
            return
        self._pending = (command, attempts + 1, again)
        self._pending_due = time.monotonic() + self.command_retry_s
        self.command_stats["command_sent"] += 1
        self._pending, keep = None, self._pending  # no recursion from the resend's own _emit
        try:
            again()
        finally:
            self._pending = keep

    def send_raw(self, data: bytes) -> None:
        """Write already-packed bytes (a replayed packet) unchanged."""
        try:
            self._conn.write(data)
        except OSError as err:
            raise PortError(f"could not write to {self.url!r}: {err}") from err

    def recv(self, timeout_s: float = 0.0) -> Any | None:
        """The next decoded message, or None when none came within ``timeout_s``.

        Packets pymavlink could not decode (``BAD_DATA``) are counted in :attr:`bad_packets`
        and skipped.
        """
        deadline = time.monotonic() + max(0.0, timeout_s)
        while True:
            try:
                if timeout_s > 0:
                    remaining = deadline - time.monotonic()
                    if remaining <= 0:
                        return None
                    msg = self._conn.recv_match(blocking=True, timeout=remaining)
                else:
                    msg = self._conn.recv_msg()
            except OSError as err:
                raise PortError(f"could not read from {self.url!r}: {err}") from err
            if msg is None:
                return None
            if msg.get_type() == "BAD_DATA":
                self.bad_packets += 1
                continue
            return msg

    def close(self) -> None:
        with contextlib.suppress(OSError):
            self._conn.close()

    def __enter__(self) -> MavEndpoint:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


# A parser used only by decode_packet: pymavlink's decode() keeps signing/sequence counters but
# no state that changes how the next packet decodes (no secret key is ever set on it).
_decoder: Any = None


def decode_packet(data: bytes) -> Any | None:
    """Decode one complete framed packet; None when its CRC or length is wrong.

    A message id the dialect does not know decodes to pymavlink's ``MAVLink_unknown``
    (``get_type()`` ``"UNKNOWN_<id>"``), not None. Signatures are not checked here.
    """
    global _decoder
    if _decoder is None:
        _decoder = MAVLink(None)
        _decoder.robust_parsing = True
    try:
        return _decoder.decode(bytearray(data))
    except (mav_error(), struct.error, IndexError, ValueError):
        return None


@dataclass(frozen=True)
class TlogRecord:
    """One record of a ``.tlog``: the timestamp and the packet as stored."""

    t_us: int  # the 8-byte big-endian microsecond timestamp
    raw: bytes  # the packet bytes exactly as in the file
    msg: Any | None  # decoded pymavlink message, or None for BAD_DATA / undecodable


_MAGIC_V1 = 0xFE
_MAGIC_V2 = 0xFD


def _packet_length(buf: bytes, pos: int) -> int | None:
    """Length of the packet starting at ``buf[pos]`` from its header, or None if not a start."""
    if pos >= len(buf):
        return None
    magic = buf[pos]
    if magic == _MAGIC_V1:
        if pos + 2 > len(buf):
            return None
        return 6 + buf[pos + 1] + 2
    if magic == _MAGIC_V2:
        if pos + 3 > len(buf):
            return None
        signed = buf[pos + 2] & 0x01
        return 10 + buf[pos + 1] + 2 + (13 if signed else 0)
    return None


# A tlog's timestamps are the recorder's clock at each packet: they only move forward, in steps
# of at most a link outage. A timestamp is "plausible" after another within these bounds. A
# record's own timestamp is judged against both neighbours (see _TlogChecker.time_ok): when the
# records before and after it agree with each other and not with it, it was damaged; a real
# outage or clock step moves every later stamp and is believed.
_TLOG_MAX_STEP_US = 60_000_000  # forward
_TLOG_MAX_BACK_US = 1_000_000  # backward (a clock slewed back by NTP)


def iter_tlog(path: str | os.PathLike[str]) -> Iterator[TlogRecord]:
    """Iterate over a QGroundControl ``.tlog``: 8-byte big-endian µs, then one packet, repeated.

    Each packet's length comes from its header and is trusted only when the packet's CRC (with
    the message's CRC_EXTRA) matches; the records yielded tile the file. Damage is handled as a
    MAVLink parser handles line noise, then the timestamps are resumed:

    * a record whose packet has no magic byte, a length past the file's end or a wrong CRC is
      damaged: it becomes one record with ``msg = None`` holding the bytes up to the next
      record that is valid (magic, length, CRC right, and a timestamp plausible after the last
      good one, or chained to the record after it). A truncated final record is one such too;
    * a record whose packet is valid but whose timestamp disagrees with both neighbours while
      they agree with each other (a flipped timestamp byte, beyond the 1 s back / gap + 1 s
      forward that an intact file may show) is yielded with ``msg = None``: its bytes are
      kept, its time is not believed;
    * a message id the dialect does not know has no CRC to check: in step with the file it is
      taken when the next record starts where its length says; after damage it is taken only
      when the next record is CRC-valid and chained to it.

    So one flipped byte anywhere loses at most the record it hit. A packet framed right whose
    CRC matches only over its zero-padded payload (a sender that cut trailing zeros after
    computing the CRC, as ArduSub's camera component does) keeps its place and is yielded with
    ``msg = None``, as pymavlink reports it (``BAD_DATA``).
    """
    data = Path(path).read_bytes()
    check = _TlogChecker(data)
    pos = 0
    end = len(data)
    last_t: int | None = None
    while pos + 8 < end:
        (t_us,) = struct.unpack_from(">Q", data, pos)
        start = pos + 8
        verdict = check.packet(start)
        if verdict is False or (verdict is None and not check.next_starts(start)):
            nxt = _resync_tlog(check, start + 1, last_t)
            yield TlogRecord(t_us, data[start:nxt], None)
            pos = nxt
            continue
        length = check.length(start)
        assert length is not None  # a packet that passed its check has one
        raw = data[start : start + length]
        pos = start + length
        if check.time_ok(start - 8, last_t):
            last_t = t_us
            yield TlogRecord(t_us, raw, decode_packet(raw))
        else:
            yield TlogRecord(t_us, raw, None)


def _plausible(t_us: int, last_us: int) -> bool:
    return last_us - _TLOG_MAX_BACK_US <= t_us <= last_us + _TLOG_MAX_STEP_US


def _resync_tlog(check: _TlogChecker, pos: int, last_t: int | None) -> int:
    """The first record start at or after ``pos`` (its packet one byte or more past the damaged
    record's start) whose packet is valid and whose timestamp is plausible after ``last_t`` or
    chained to the next record's; the file's end when there is none."""
    data = check.data
    end = len(data)
    i = pos + 8
    m1 = m2 = i - 1  # the next 0xFE and 0xFD at or after i (end: none), each found once
    while True:
        if m1 < i:
            m1 = data.find(_MAGIC_V1, i) % (end + 1)  # -1 -> end
        if m2 < i:
            m2 = data.find(_MAGIC_V2, i) % (end + 1)
        m = min(m1, m2)
        if m >= end:
            return end
        i = m + 1
        verdict = check.packet(m)
        if verdict is False:
            continue
        (t_us,) = struct.unpack_from(">Q", data, m - 8)
        if verdict is True and (last_t is None or _plausible(t_us, last_t)):
            return m - 8
        if check.chains(m - 8):
            return m - 8


# MAVLink's CRC-16/MCRF4XX, computed in C by binascii.crc_hqx (the bit-reflected CRC-16/XMODEM)
# on bit-reversed bytes. drivers.mavlink.framer.x25crc is the same function (a test keeps them
# equal); the framer imports this module, so this one cannot import the framer's.
_REV8 = bytes(int(f"{i:08b}"[::-1], 2) for i in range(256))


def _x25crc(data: bytes) -> int:
    c = binascii.crc_hqx(data.translate(_REV8), 0xFFFF)
    return (_REV8[c & 0xFF] << 8) | _REV8[c >> 8]


class _TlogChecker:
    """Packet checks over a tlog's bytes: CRC with the dialect's CRC_EXTRA (over the padded
    payload too), and whether two records chain."""

    def __init__(self, data: bytes) -> None:
        self.data = data
        self.crc = _x25crc
        self.extras = crc_extra_table()
        self.full = payload_length_table()
        self._verdicts: dict[int, bool | None] = {}  # each packet is checked once

    def packet(self, start: int) -> bool | None:
        """True: a whole packet whose CRC matches; False: none starts here, it is cut, or its
        CRC is wrong; None: framed, but its message id is not in the dialect (unchecked)."""
        if start in self._verdicts:
            return self._verdicts[start]
        verdict = self._verdicts[start] = self._check(start)
        if len(self._verdicts) > 64:
            self._verdicts.clear()  # only the records around the current one are asked again
        return verdict

    def length(self, start: int) -> int | None:
        """The packet's length from its header; None when no packet starts there or it runs
        past the file's end."""
        n = _packet_length(self.data, start)
        return None if n is None or start + n > len(self.data) else n

    def _check(self, start: int) -> bool | None:
        data = self.data
        n = self.length(start)
        if n is None:
            return False
        v2 = data[start] == _MAGIC_V2
        if v2 and data[start + 2] & ~0x01:
            return False  # an incompatibility flag other than "signed": not a packet we frame
        hlen = 10 if v2 else 6
        plen = data[start + 1]
        if v2:
            msgid = data[start + 7] | data[start + 8] << 8 | data[start + 9] << 16
        else:
            msgid = data[start + 5]
        extra = self.extras.get(msgid)
        if extra is None:
            return None
        crc_end = start + hlen + plen
        wire = data[crc_end] | data[crc_end + 1] << 8
        if self.crc(data[start + 1 : crc_end] + bytes((extra,))) == wire:
            return True
        body = data[start + 2 : crc_end]
        for k in range(plen + 1, (self.full.get(msgid, 0) if v2 else 0) + 1):
            if self.crc(bytes((k,)) + body + bytes(k - plen) + bytes((extra,))) == wire:
                return True  # the CRC of the untruncated payload (see the docstring)
        return False

    def next_starts(self, start: int) -> bool:
        """True when the record after the packet at ``start`` starts a packet (or the file
        ends there exactly)."""
        n = self.length(start)
        if n is None:
            return False
        nxt = start + n
        return nxt == len(self.data) or _packet_length(self.data, nxt + 8) is not None

    def _next_time(self, rec: int) -> int | None:
        """The timestamp of the record after the one at ``rec`` when its packet is framed and
        not known bad (CRC-valid or unchecked); None at the file's end or when it is bad."""
        n = self.length(rec + 8)
        if n is None:
            return None
        nxt = rec + 8 + n
        if nxt + 8 >= len(self.data) or self.packet(nxt + 8) is False:
            return None
        return int(struct.unpack_from(">Q", self.data, nxt)[0])

    def chains(self, rec: int) -> bool:
        """True when the record after the one at ``rec`` has a CRC-valid packet and a timestamp
        plausible after this one's."""
        n = self.length(rec + 8)
        if n is None:
            return False
        nxt = rec + 8 + n
        if nxt + 8 >= len(self.data) or self.packet(nxt + 8) is not True:
            return False
        (t_us,) = struct.unpack_from(">Q", self.data, rec)
        (t_next,) = struct.unpack_from(">Q", self.data, nxt)
        return _plausible(t_next, t_us)

    def time_ok(self, rec: int, last_t: int | None) -> bool:
        """Whether the timestamp of the (valid) record at ``rec`` is believed, after the last
        good one ``last_t``: plausible after it and followed plausibly by the next record's;
        else refused only when those two neighbours agree without it (it alone is off)."""
        (t_us,) = struct.unpack_from(">Q", self.data, rec)
        if last_t is None:
            return True
        after_last = _plausible(t_us, last_t)
        t_next = self._next_time(rec)
        if t_next is None:  # the file's end, or the next record is damaged: no second opinion
            return after_last
        if after_last and _plausible(t_next, t_us):
            return True
        return not _plausible(t_next, last_t)
