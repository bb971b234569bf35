"""IMU samples from MAVLink messages, in SI units, for the INS/GNSS filter.

Takes decoded message objects duck-typed (``msg.get_type()`` and attributes), as yielded by
:func:`drivers.mavlink.io.iter_tlog` or a live link, so this module never imports pymavlink.

Units, from the MAVLink common dialect (``message_definitions/v1.0/common.xml``):

- ``HIGHRES_IMU``: ``xacc..zacc`` m/s², ``xgyro..zgyro`` rad/s (float), ``time_usec`` µs.
- ``SCALED_IMU`` / ``SCALED_IMU2`` / ``SCALED_IMU3``: accelerations in mG (int16), rates in
  mrad/s, ``time_boot_ms`` ms.
- ``RAW_IMU``: the dialect calls the fields "raw" but gives them the units mG and mrad/s and
  says "on ArduPilot platforms, this message is identical to SCALED_IMU"; ArduPilot fills it
  with acceleration · 1000 / 9.80665 and rate · 1000. We assume that scaling (checked on the
  ArduSub corpus: a vehicle at rest reads ``zacc ≈ −1000``, i.e. −1 g of specific force on the
  down axis). For an autopilot that sends true sensor counts, pass the scale factors.
  ``time_usec`` µs.

All are in the body frame forward-right-down (FRD) and give the specific force (at rest the
accelerometer reads −g on z), the convention of :mod:`fdi.insgnss`. A message whose six
inertial fields are all exactly 0 (ArduSub sends ``SCALED_IMU2`` with only the magnetometer
when there is no second IMU) carries no inertial data and yields ``None``.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from typing import Any

from fdi.errors import DecodeError

STANDARD_G = 9.80665  # m/s² per g, the value ArduPilot and MAVLink use
MG_TO_M_S2 = STANDARD_G / 1000.0
MRAD_TO_RAD = 1e-3

IMU_MESSAGES = ("HIGHRES_IMU", "RAW_IMU", "SCALED_IMU", "SCALED_IMU2", "SCALED_IMU3")
_SCALED = {"SCALED_IMU": 0, "SCALED_IMU2": 1, "SCALED_IMU3": 2}


@dataclass(frozen=True)
class ImuSample:
    """One IMU reading in SI units, body FRD."""

    t_s: float  # autopilot time (since boot, or UNIX epoch for some time_usec), s
    gyro_rad_s: tuple[float, float, float]
    accel_m_s2: tuple[float, float, float]  # specific force
    source: str  # MAVLink message name
    imu_id: int  # 0 for IMU1, 1 for IMU2, ...


@dataclass(frozen=True)
class RawImuScale:
    """Scale of RAW_IMU fields: ArduPilot's mG and mrad/s by default."""

    accel_m_s2_per_lsb: float = MG_TO_M_S2
    gyro_rad_s_per_lsb: float = MRAD_TO_RAD


def _fields(msg: Any, names: tuple[str, ...], kind: str) -> tuple[float, ...]:
    try:
        return tuple(float(getattr(msg, n)) for n in names)
    except (AttributeError, TypeError, ValueError) as err:
        raise DecodeError("imu-field", f"{kind}: {err}") from err


_ACC = ("xacc", "yacc", "zacc")
_GYR = ("xgyro", "ygyro", "zgyro")


def imu_from_message(msg: Any, raw_scale: RawImuScale | None = None) -> ImuSample | None:
    """Convert one IMU message to :class:`ImuSample`; ``None`` for other messages or no data.

    Raises :class:`~fdi.errors.DecodeError` when an IMU message lacks a field.
    """
    kind = msg.get_type()
    if kind not in IMU_MESSAGES:
        return None
    acc = _fields(msg, _ACC, kind)
    gyr = _fields(msg, _GYR, kind)
    if not any(acc) and not any(gyr):
        return None
    if kind == "HIGHRES_IMU":
        t_s = _fields(msg, ("time_usec",), kind)[0] * 1e-6
        ka, kg = 1.0, 1.0
        imu_id = int(getattr(msg, "id", 0) or 0)
    elif kind == "RAW_IMU":
        scale = raw_scale or RawImuScale()
        t_s = _fields(msg, ("time_usec",), kind)[0] * 1e-6
        ka, kg = scale.accel_m_s2_per_lsb, scale.gyro_rad_s_per_lsb
        imu_id = int(getattr(msg, "id", 0) or 0)
    else:
        t_s = _fields(msg, ("time_boot_ms",), kind)[0] * 1e-3
        ka, kg = MG_TO_M_S2, MRAD_TO_RAD
        imu_id = _SCALED[kind]
    return ImuSample(
        t_s=t_s,
        gyro_rad_s=(gyr[0] * kg, gyr[1] * kg, gyr[2] * kg),
        accel_m_s2=(acc[0] * ka, acc[1] * ka, acc[2] * ka),
        source=kind,
        imu_id=imu_id,
    )


def iter_imu(
    messages: Iterable[Any | None],
    source: str | None = None,
    raw_scale: RawImuScale | None = None,
) -> Iterator[ImuSample]:
    """IMU samples from a stream of decoded messages (``None`` entries are skipped).

    ``source`` keeps one message type (e.g. ``"RAW_IMU"``); without it every IMU message is
    yielded, which mixes sensors: choose one before feeding a filter.
    """
    for msg in messages:
        if msg is None:
            continue
        if source is not None and msg.get_type() != source:
            continue
        sample = imu_from_message(msg, raw_scale)
        if sample is not None:
            yield sample
