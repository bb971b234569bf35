"""The autopilot's raw compass and body rates from MAVLink, and a tilt-compensated heading.

Takes decoded message objects duck-typed (``msg.get_type()`` and attributes), as
:mod:`drivers.mavlink.imu` does, so this module never imports pymavlink.

Fields (MAVLink common dialect; ArduPilot's ``GCS_MAVLINK::send_raw_imu`` /
``send_scaled_imu``):

- ``RAW_IMU`` / ``SCALED_IMU`` / ``SCALED_IMU2`` / ``SCALED_IMU3``: ``xmag, ymag, zmag`` in
  milligauss (int16), body frame forward-right-down. ArduPilot fills them from
  ``Compass::get_field(i)``: the field after the offsets, scale and orientation of the
  calibration, so it is the field the autopilot's own compass heading is computed from. A
  message whose three fields are all exactly 0 carries no compass (no such instance) and
  yields ``None``.
- ``ATTITUDE``: ``roll, pitch, yaw`` (rad) and ``rollspeed, pitchspeed, yawspeed`` (rad/s,
  body rates p, q, r).

:func:`tilt_compensated_heading_deg` is ArduPilot's ``Compass::calculate_heading`` (the
heading convention of AP_Compass / AP_AHRS: clockwise from north looking down, the field
de-rotated by roll and pitch, declination added):
``headY = my cos(roll) cos(pitch) - mz sin(roll) cos(pitch)``,
``headX = mx cos²(pitch) + sin(pitch) (my sin(roll) cos(pitch) + mz cos(roll) cos(pitch))``,
``heading = atan2(-headY, headX) + declination``. (ArduPilot writes it with the DCM's third
row ``c = (-sin pitch, sin roll cos pitch, cos roll cos pitch)``; the common factor
``cos(pitch) > 0`` does not change the angle.)

:func:`heading_rate_dps` turns body rates into the rate of the heading (the Euler-angle
kinematics, ``psi' = (q sin(roll) + r cos(roll)) / cos(pitch)``), the input of the
gyro witness.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from fdi.errors import DecodeError

COMPASS_MESSAGES = ("RAW_IMU", "SCALED_IMU", "SCALED_IMU2", "SCALED_IMU3")
MIN_HORIZONTAL_MGAUSS = 20.0
"""Below this horizontal field (mG; the Earth's is 50-400 mG) the heading is not defined."""


@dataclass(frozen=True)
class MagSample:
    """One compass reading, body FRD, milligauss (as calibrated by the autopilot)."""

    field_mgauss: tuple[float, float, float]
    source: str  # the MAVLink message name
    gyro_rad_s: tuple[float, float, float] | None  # the same message's body rates, if any


def _floats(msg: Any, names: tuple[str, ...], kind: str) -> tuple[float, ...]:
    try:
        return tuple(float(getattr(msg, n)) for n in names)
    except (AttributeError, TypeError, ValueError) as err:
        raise DecodeError("compass-field", f"{kind}: {err}") from err


def mag_from_message(msg: Any) -> MagSample | None:
    """The compass of one IMU message; ``None`` for other messages or no compass in it.

    Raises :class:`~fdi.errors.DecodeError` when a compass message lacks a field."""
    kind = msg.get_type()
    if kind not in COMPASS_MESSAGES:
        return None
    mag = _floats(msg, ("xmag", "ymag", "zmag"), kind)
    if not any(mag):
        return None
    gyr = _floats(msg, ("xgyro", "ygyro", "zgyro"), kind)
    gyro = None if not any(gyr) else (gyr[0] * 1e-3, gyr[1] * 1e-3, gyr[2] * 1e-3)  # mrad/s
    return MagSample((mag[0], mag[1], mag[2]), kind, gyro)


def tilt_compensated_heading_deg(
    field: tuple[float, float, float], roll_rad: float, pitch_rad: float,
    declination_deg: float = 0.0,
) -> float | None:
    """Heading (deg, 0..360, clockwise from true north with the declination added) from the
    body field and the attitude (module docstring); ``None`` when the horizontal field is
    below :data:`MIN_HORIZONTAL_MGAUSS` or a value is not finite."""
    mx, my, mz = field
    sr, cr = math.sin(roll_rad), math.cos(roll_rad)
    sp, cp = math.sin(pitch_rad), math.cos(pitch_rad)
    head_y = my * cr - mz * sr  # headY / cos(pitch)
    head_x = mx * cp + sp * (my * sr + mz * cr)  # headX / cos(pitch)
    if not (math.isfinite(head_x) and math.isfinite(head_y)):
        return None
    if math.hypot(head_x, head_y) < MIN_HORIZONTAL_MGAUSS:
        return None
    return (math.degrees(math.atan2(-head_y, head_x)) + declination_deg) % 360.0


def heading_rate_dps(gyro_rad_s: tuple[float, float, float], roll_rad: float,
                     pitch_rad: float) -> float | None:
    """The rate of the heading (deg/s) from body rates ``(p, q, r)`` (rad/s); ``None`` near
    pitch ±90° or for a value that is not finite."""
    _, q, r = gyro_rad_s
    cp = math.cos(pitch_rad)
    if abs(cp) < 1e-3:
        return None
    rate = (q * math.sin(roll_rad) + r * math.cos(roll_rad)) / cp
    return math.degrees(rate) if math.isfinite(rate) else None


def body_field_mgauss(heading_deg: float, roll_rad: float, pitch_rad: float,
                      horizontal_mgauss: float, down_mgauss: float,
                      declination_deg: float = 0.0) -> tuple[float, float, float]:
    """The inverse of :func:`tilt_compensated_heading_deg` (a simulated magnetometer): the
    body-frame field of a vehicle at this attitude in a field of the given horizontal and
    downward strength whose north is ``declination_deg`` east of true north."""
    psi = math.radians(heading_deg - declination_deg)  # the magnetic heading
    # NED field in the magnetic frame, rotated into the body: C = Rx(roll)^T Ry(pitch)^T Rz^T.
    n = horizontal_mgauss * math.cos(psi)
    e = -horizontal_mgauss * math.sin(psi)
    d = down_mgauss
    sp, cp = math.sin(pitch_rad), math.cos(pitch_rad)
    x1, z1 = cp * n - sp * d, sp * n + cp * d  # pitch
    sr, cr = math.sin(roll_rad), math.cos(roll_rad)
    y2, z2 = cr * e + sr * z1, -sr * e + cr * z1  # roll
    return (x1, y2, z2)
