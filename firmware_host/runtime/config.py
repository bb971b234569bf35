"""The bridge's configuration: typed objects loaded from TOML in ``config/`` (one place).

``load_config(path)`` validates the whole file (see :mod:`drivers.configload`): a bad file
fails at start naming the file, the key, what was expected and what was found, and the CLI exits
with status 2. ``BridgeConfig()`` with no file is the built-in default, which
``config/rover.toml`` states explicitly (a test keeps the two equal).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from drivers.configload import load_file
from drivers.mavlink.modes import alarm_mode
from drivers.transport import SerialSettings
from fdi.rover import RoverDetectorParams
from firmware_host.runtime.recorder import RecorderConfig

CONFIG_DIR = Path(__file__).resolve().parents[2] / "config"


@dataclass(frozen=True)
class ReferencePoint:
    """The local frame's origin; without it, the first valid fix."""

    lat_deg: float = field(default=0.0, metadata={"ge": -90.0, "le": 90.0})
    lon_deg: float = field(default=0.0, metadata={"ge": -180.0, "le": 180.0})
    alt_m: float = 0.0  # ellipsoidal height


@dataclass(frozen=True)
class RoverOutputs:
    """Where corrected data goes. URLs are pyserial URLs; ``pty:PATH`` makes a pty, linked."""

    nmea_url: str = ""
    nmea_baudrate: int = field(default=9600, metadata={"gt": 0})
    mavlink_url: str = ""  # e.g. "udpout:127.0.0.1:14550", or a serial device (reopened if lost)
    mavlink_baudrate: int = field(default=57600, metadata={"gt": 0})  # serial mavlink_url only
    mavlink_system: int = field(default=1, metadata={"ge": 1, "le": 255})
    mavlink_component: int = field(default=191, metadata={"ge": 1, "le": 255})
    target_system: int = field(default=1, metadata={"ge": 1, "le": 255})
    hold_on_alarm: bool = True
    vehicle: str = "rover"  # rover, boat, sub, copter, plane (ArduPilot's mode tables)
    # Mode requested on an alarm; "" = the vehicle's default (rover HOLD, sub ALT_HOLD; copter
    # and plane must name one). Checked at load (drivers.mavlink.modes.alarm_mode).
    alarm_mode: str = ""
    gps_id: int = field(default=0, metadata={"ge": 0, "le": 1, "doc": "GPS_INPUT gps_id: 1 = GPS2"})
    # Accuracy reported with a replaced fix is the prediction's, raised by this factor.
    replaced_accuracy_factor: float = field(default=3.0, metadata={"ge": 1.0})

    def __post_init__(self) -> None:
        if self.hold_on_alarm:
            alarm_mode(self.vehicle, self.alarm_mode)  # ValueError names what is allowed


@dataclass(frozen=True)
class RoverConfig:
    port: SerialSettings = field(
        default_factory=lambda: SerialSettings(url="/dev/ttyUSB0", baudrate=9600)
    )
    detector: RoverDetectorParams = field(default_factory=RoverDetectorParams)
    reference: ReferencePoint | None = None
    output: RoverOutputs = field(default_factory=RoverOutputs)
    max_line: int = field(default=120, metadata={"ge": 82, "le": 4096})
    silence_s: float = field(default=2.0, metadata={"gt": 0.0})
    reconnect_max_s: float = field(default=5.0, metadata={"ge": 0.1})  # reopen backoff cap


@dataclass(frozen=True)
class BridgeConfig:
    name: str = "rover-default"
    description: str = ""
    rover: RoverConfig = field(default_factory=RoverConfig)
    recorder: RecorderConfig = field(default_factory=RecorderConfig)


def load_config(path: str | Path | None) -> BridgeConfig:
    """Load a config file; ``None`` gives the built-in defaults. A bare preset name such as
    ``rover-paper`` is looked up as ``config/<name>.toml``."""
    if path is None:
        return BridgeConfig()
    p = Path(path)
    if not p.exists() and not p.suffix and (CONFIG_DIR / f"{p.name}.toml").exists():
        p = CONFIG_DIR / f"{p.name}.toml"
    return load_file(BridgeConfig, p)
