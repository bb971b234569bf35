"""ArduPilot's flight modes per vehicle, and the mode the bridge asks for on a GPS alarm.

No pymavlink here, so a configuration can be validated at load time without importing it
(``tests/test_mavlink_modes.py`` checks these tables against pymavlink's ``mavutil`` ones,
which are ArduPilot's ``mode.h`` numbers).

The alarm mode (``[rover.output] alarm_mode``) must be a mode that does not need the position
the bridge has just declared untrustworthy, on the vehicle that is configured:

* Rover / boat: ``HOLD`` (default): stops and holds steering, no position needed;
* Sub (ArduSub has no ``HOLD``): ``ALT_HOLD`` (default, holds depth), or ``POSHOLD`` /
  ``SURFACE`` when configured;
* Copter and Plane: no default -- the operator names one (``LAND``, ``ALT_HOLD``, ``CIRCLE``
  ...), because the right answer depends on where the aircraft flies.
"""

from __future__ import annotations

MODES: dict[str, dict[str, int]] = {
    "rover": {"MANUAL": 0, "ACRO": 1, "LEARNING": 2, "STEERING": 3, "HOLD": 4, "LOITER": 5,
              "FOLLOW": 6, "SIMPLE": 7, "DOCK": 8, "CIRCLE": 9, "AUTO": 10, "RTL": 11,
              "SMART_RTL": 12, "GUIDED": 15, "INITIALISING": 16},
    "sub": {"STABILIZE": 0, "ACRO": 1, "ALT_HOLD": 2, "AUTO": 3, "GUIDED": 4, "CIRCLE": 7,
            "SURFACE": 9, "POSHOLD": 16, "MANUAL": 19},
    "copter": {"STABILIZE": 0, "ACRO": 1, "ALT_HOLD": 2, "AUTO": 3, "GUIDED": 4, "LOITER": 5,
               "RTL": 6, "CIRCLE": 7, "LAND": 9, "DRIFT": 11, "SPORT": 13, "FLIP": 14,
               "AUTOTUNE": 15, "POSHOLD": 16, "BRAKE": 17, "THROW": 18, "AVOID_ADSB": 19,
               "GUIDED_NOGPS": 20, "SMART_RTL": 21, "FLOWHOLD": 22, "FOLLOW": 23, "ZIGZAG": 24,
               "SYSTEMID": 25, "AUTOROTATE": 26, "AUTO_RTL": 27, "TURTLE": 28},
    "plane": {"MANUAL": 0, "CIRCLE": 1, "STABILIZE": 2, "TRAINING": 3, "ACRO": 4, "FBWA": 5,
              "FBWB": 6, "CRUISE": 7, "AUTOTUNE": 8, "AUTO": 10, "RTL": 11, "LOITER": 12,
              "TAKEOFF": 13, "AVOID_ADSB": 14, "GUIDED": 15, "QSTABILIZE": 17, "QHOVER": 18,
              "QLOITER": 19, "QLAND": 20, "QRTL": 21, "QAUTOTUNE": 22, "QACRO": 23,
              "THERMAL": 24},
}
MODES["boat"] = MODES["rover"]

DEFAULT_ALARM_MODE: dict[str, str] = {"rover": "HOLD", "boat": "HOLD", "sub": "ALT_HOLD"}

# Modes that need the position the alarm says is wrong: refused as an alarm mode.
_NEEDS_POSITION: dict[str, frozenset[str]] = {
    "rover": frozenset({"AUTO", "GUIDED", "LOITER", "RTL", "SMART_RTL", "CIRCLE", "FOLLOW",
                        "DOCK"}),
    "copter": frozenset({"AUTO", "GUIDED", "LOITER", "RTL", "SMART_RTL", "CIRCLE", "FOLLOW",
                         "ZIGZAG", "AUTO_RTL", "POSHOLD", "BRAKE"}),
    "plane": frozenset({"AUTO", "GUIDED", "RTL", "LOITER", "TAKEOFF", "QLOITER", "QRTL"}),
}
_NEEDS_POSITION["boat"] = _NEEDS_POSITION["rover"]
_SUB_ALARM_MODES = frozenset({"ALT_HOLD", "POSHOLD", "SURFACE", "STABILIZE", "MANUAL"})


def mode_number(mode: str, vehicle: str) -> int:
    """ArduPilot's custom-mode number of ``mode`` on ``vehicle``; ValueError names the options."""
    table = MODES.get(vehicle.lower())
    if table is None:
        raise ValueError(f"unknown vehicle {vehicle!r}; known: {', '.join(sorted(MODES))}")
    number = table.get(mode.upper())
    if number is None:
        raise ValueError(f"{vehicle} has no mode {mode!r}; known: {', '.join(table)}")
    return number


def alarm_mode(vehicle: str, configured: str = "") -> str:
    """The mode to request on an alarm: ``configured`` checked, or the vehicle's default.

    ValueError (with what is allowed) for an unknown vehicle or mode, a mode that needs a
    position (Sub: anything but ALT_HOLD/POSHOLD/SURFACE/STABILIZE/MANUAL), or a Copter/Plane
    with none configured. Called when the configuration is loaded.
    """
    v = vehicle.lower()
    if v not in MODES:
        raise ValueError(f"unknown vehicle {vehicle!r}; known: {', '.join(sorted(MODES))}")
    mode = configured.upper() or DEFAULT_ALARM_MODE.get(v, "")
    if not mode:
        raise ValueError(f"vehicle {vehicle!r} has no default alarm mode: set alarm_mode "
                         f"(for example LAND or ALT_HOLD on a copter, CIRCLE on a plane)")
    mode_number(mode, v)
    if v == "sub" and mode not in _SUB_ALARM_MODES:
        allowed = ", ".join(sorted(_SUB_ALARM_MODES))
        raise ValueError(f"alarm_mode {mode!r} on a sub: one of {allowed}")
    if mode in _NEEDS_POSITION.get(v, frozenset()):
        raise ValueError(f"alarm_mode {mode!r} needs the GPS position the alarm distrusts")
    return mode
