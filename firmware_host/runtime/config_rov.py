"""Schema of the ROV heading hold: the ``[rov]`` table (``config/rov.toml``, ``rov-paper.toml``).

Built-in defaults are the dataclass defaults (= ``config/rov.toml``); a preset states only what it
changes. Loading and validation: :func:`firmware_host.runtime.config.load_bridge_file`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal, cast

from drivers.transport import SerialSettings
from fdi.errors import ConfigError
from fdi.heading_ft import FtConfig
from fdi.lms_fir import DetectorConfig
from fdi.pid import PidConfig
from firmware_host.runtime.recorder import RecorderConfig

Wiring = Literal["rs232", "rs485"]


@dataclass(frozen=True)
class LinkConfig:
    """The vehicle link: port, wiring, protocol description (a path relative to the config file,
    else one of the packaged ``protocols/``; the loader makes it absolute)."""

    port: SerialSettings = field(default_factory=lambda: SerialSettings(baudrate=115200), metadata={
        "doc": "the link's port"})
    wiring: Wiring = field(default="rs232", metadata={
        "doc": "rs232: full duplex; rs485: half duplex (the link waits for each reply)"})
    protocol: str = field(default="protocols/outland1000.toml", metadata={
        "range": "a protocol TOML file",
        "doc": "the Outland frame layout: a path relative to the config file, else one of the "
               "packaged protocols/"})
    address: int = field(default=1, metadata={
        "ge": 0, "le": 255, "unit": "-", "doc": "the vehicle's address on the link"})
    reply_timeout_s: float = field(default=0.05, metadata={
        "ge": 0.001, "lt": 1.0, "unit": "s",
        "doc": "wait this long for the vehicle's telemetry reply to a poll"})
    reconnect_max_s: float = field(default=5.0, metadata={
        "ge": 0.1, "le": 3600.0, "unit": "s", "doc": "longest wait between reopens of a lost port"})


Plant = Literal["nomoto", "nonlinear"]
HeadingSource = Literal["outland", "mavlink"]

# ArduSub's flight modes whose pilot yaw comes from MANUAL_CONTROL ``r`` (ArduSub's mode
# handlers read ``channel_yaw``): the bridge may steer in these; in AUTO, GUIDED, CIRCLE and
# SURFACE the autopilot owns the heading, and the bridge refuses to command.
ARDUSUB_YAW_MODES = ("MANUAL", "STABILIZE", "ACRO", "ALT_HOLD", "POSHOLD")
ArduSubHeading = Literal["attitude", "raw_compass"]
CompassMessage = Literal["RAW_IMU", "SCALED_IMU", "SCALED_IMU2", "SCALED_IMU3"]
ArduSubGyro = Literal["none", "imu", "attitude"]
ArduSubOutput = Literal["manual_control", "rc_override"]

GYRO_FOR_HEADING: dict[str, ArduSubGyro] = {"attitude": "attitude", "raw_compass": "imu"}
"""``[rov.ardusub] gyro`` when not given: the link always carries a gyro (ATTITUDE's rates; the
compass message's own gyro beside the raw compass)."""
_GYRO_NOT_GIVEN = cast(ArduSubGyro, "")  # replaced in __post_init__, never seen outside


@dataclass(frozen=True)
class ArduSubConfig:
    """The ROV through an ArduSub autopilot (``[rov.ardusub]``, used when
    ``heading_source = "mavlink"``; docs/rov-ardusub.md). The GCS system id the commands carry
    is ``[mavlink] pilot_system_id`` (ArduSub's ``MAV_GCS_SYSID``, ``SYSID_MYGCS`` before 4.7),
    their component id the bridge's ``[mavlink] component_id``. ``gyro`` not given:
    :data:`GYRO_FOR_HEADING` of ``heading`` (resolved here, so the object always holds one)."""

    vehicle_system_id: int = field(default=1, metadata={
        "ge": 1, "le": 255, "unit": "-", "doc": "the ArduSub autopilot's MAVLink system id"})
    steer: bool = field(
        default=True, metadata={"doc": "false: detect only, never send MANUAL_CONTROL"})
    modes: tuple[str, ...] = field(default=ARDUSUB_YAW_MODES, metadata={
        "doc": "modes the bridge may steer in",
        "choices": ["MANUAL", "STABILIZE", "ACRO", "ALT_HOLD", "POSHOLD"]})
    yaw_dead_band: int = field(default=100, metadata={
        "ge": 0, "le": 1000, "doc": "pilot |r| above: the pilot steers", "unit": "-"})
    pilot_release_s: float = field(default=2.0, metadata={
        "ge": 0.0, "le": 3600.0, "doc": "pilot yaw centred this long: hand back", "unit": "s"})
    pilot_timeout_s: float = field(default=1.0, metadata={
        "ge": 0.05, "lt": 3.0, "doc": "pilot MANUAL_CONTROL silent this long: stop sending",
        "unit": "s"})
    send_without_pilot: bool = field(
        default=False, metadata={"doc": "true: steer with no pilot or ground station present "
                                        "(neither the pilot's MANUAL_CONTROL nor the GCS's "
                                        "HEARTBEAT within pilot_timeout_s); the bridge's frames "
                                        "then hide ArduSub's GCS failsafe (FS_GCS_ENABLE)"})
    heartbeat_timeout_s: float = field(default=3.0, metadata={
        "ge": 0.1, "le": 3600.0, "doc": "autopilot HEARTBEAT older: not commanding", "unit": "s"})
    heading: ArduSubHeading = field(
        default="attitude", metadata={"doc": "attitude: ATTITUDE.yaw (the EKF's); raw_compass: "
                                             "xmag/ymag of compass_message, tilt-compensated"})
    compass_message: CompassMessage = field(
        default="RAW_IMU", metadata={"doc": "the message whose xmag/ymag/zmag is the compass"})
    declination_deg: float = field(default=0.0, metadata={
        "ge": -180.0, "le": 180.0, "doc": "raw_compass: added (east positive; ArduPilot's "
                                          "COMPASS_DEC in degrees)", "unit": "deg"})
    compass_offset_deg: float = field(default=0.0, metadata={
        "ge": -180.0, "le": 180.0, "doc": "raw_compass: added after the declination (mounting)",
        "unit": "deg"})
    gyro: ArduSubGyro = field(
        default=_GYRO_NOT_GIVEN,
        metadata={"doc": "the gyro witness's yaw rate: none (the FIR alone: slow drifts are not "
                         "detectable), imu (the compass_message's gyro), attitude (ATTITUDE's "
                         "rates); default attitude with heading = attitude, imu with "
                         "raw_compass"})
    output: ArduSubOutput = field(
        default="manual_control", metadata={"doc": "manual_control or rc_override"})
    rc_yaw_channel: int = field(default=4, metadata={
        "ge": 1, "le": 8, "doc": "rc_override: RCMAP_YAW", "unit": "-"})
    rc_throttle_channel: int = field(default=3, metadata={
        "ge": 1, "le": 8, "doc": "rc_override: RCMAP_THROTTLE", "unit": "-"})
    rc_forward_channel: int = field(default=5, metadata={
        "ge": 1, "le": 8, "doc": "rc_override: RCMAP_FORWARD", "unit": "-"})
    rc_lateral_channel: int = field(default=6, metadata={
        "ge": 1, "le": 8, "doc": "rc_override: RCMAP_LATERAL", "unit": "-"})
    handback_deg: float = field(default=8.0, metadata={
        "ge": 0.0, "le": 90.0, "doc": "deg: while the heading is substituted, every other "
                                      "heading the link carries (EKF yaw, AHRS2, the raw "
                                      "compass) this far from the substitute: yaw handed back to "
                                      "the pilot (0: off)", "unit": "deg"})
    substitute_max_s: float = field(default=120.0, metadata={
        "ge": 0.0, "le": 3600.0, "doc": "s: a substitute that is gyro dead reckoning (no "
                                        "compensated compass) is trusted this long, then yaw is "
                                        "handed back to the pilot (0: no limit)", "unit": "s"})

    def __post_init__(self) -> None:
        if self.gyro == _GYRO_NOT_GIVEN:
            object.__setattr__(self, "gyro", GYRO_FOR_HEADING[self.heading])
        bad = [m for m in self.modes if m not in ARDUSUB_YAW_MODES]
        if bad:
            raise ValueError(f"modes: {', '.join(bad)} do not take MANUAL_CONTROL yaw "
                             f"(one of {', '.join(ARDUSUB_YAW_MODES)})")
        chans = (self.rc_yaw_channel, self.rc_throttle_channel, self.rc_forward_channel,
                 self.rc_lateral_channel)
        if len(set(chans)) != len(chans):
            raise ValueError("rc_yaw_channel, rc_throttle_channel, rc_forward_channel and "
                             f"rc_lateral_channel must differ, found {chans}")


@dataclass(frozen=True)
class SimConfig:
    """The simulated vehicle: yaw model, current, compass noise, yaw-rate gyro.

    ``plant = "nomoto"``: first-order linear Nomoto (the paper's textbook case). ``"nonlinear"``
    adds quadratic yaw damping, thrust ~ c|c| with a dead band and a weaker reverse, one period
    of actuator latency, compass outliers, a magnetic deviation that grows with thrust and waves
    (the keys marked "nonlinear" apply to that plant only). Turns and the gyro apply to both.
    """

    seed: int = field(default=1, metadata={
        "ge": 0, "unit": "-", "doc": "seed of the simulation's random generators (current, "
                                     "noise, gyro bias, outliers)"})
    plant: Plant = field(default="nomoto", metadata={
        "doc": "nomoto: first-order linear yaw model; nonlinear: adds damping, a thrust dead "
               "band, latency, outliers, deviation, waves"})
    nomoto_T_s: float = field(default=1.5, metadata={
        "gt": 0.0, "unit": "s", "doc": "Nomoto time constant T"})
    nomoto_K: float = field(default=0.2, metadata={
        "gt": 0.0, "doc": "deg/s per % thrust", "unit": "(deg/s)/%"})
    current_max_pct: float = field(default=4.0, metadata={
        "ge": 0.0, "unit": "%", "doc": "the current's constant part, drawn uniformly within ± "
                                       "this (as thrust)"})
    current_amp_pct: float = field(default=1.0, metadata={
        "ge": 0.0, "unit": "%", "doc": "amplitude of the current's slow sinusoidal variation"})
    current_period_s: float = field(default=900.0, metadata={
        "gt": 0.0, "unit": "s", "doc": "period of the current's variation"})
    compass_noise_deg: float = field(default=0.5, metadata={
        "ge": 0.0, "unit": "deg", "doc": "σ of the compass's white noise"})
    initial_heading_deg: float = field(default=110.0, metadata={
        "ge": -360.0, "le": 360.0, "unit": "deg", "doc": "the vehicle's true heading at start"})
    depth_m: float = field(default=10.0, metadata={
        "ge": 0.0, "le": 11000.0, "unit": "m", "doc": "the depth the telemetry reports (constant)"})
    thrust_K: float = field(default=1.0, metadata={
        "gt": 0.0, "doc": "nonlinear: deg/s per %", "unit": "(deg/s)/%"})
    quad_damping: float = field(default=0.05, metadata={
        "ge": 0.0, "doc": "nonlinear: 1/(deg/s)", "unit": "1/(deg/s)"})
    dead_band_pct: float = field(default=3.0, metadata={
        "ge": 0.0, "lt": 100.0, "unit": "%",
        "doc": "nonlinear: commands within this give no thrust"})
    reverse_efficiency: float = field(default=0.7, metadata={
        "gt": 0.0, "le": 1.0, "unit": "-",
        "doc": "nonlinear: reverse thrust as a fraction of forward"})
    latency_periods: int = field(default=1, metadata={
        "ge": 0, "le": 10, "unit": "periods", "doc": "nonlinear: actuator latency"})
    outlier_prob: float = field(default=0.002, metadata={
        "ge": 0.0, "lt": 1.0, "unit": "-",
        "doc": "nonlinear: chance of a compass outlier each sample"})
    outlier_deg: float = field(default=20.0, metadata={
        "ge": 0.0, "unit": "deg", "doc": "nonlinear: an outlier is uniform within ± this"})
    deviation_deg: float = field(default=1.0, metadata={
        "doc": "nonlinear: at full thrust", "ge": -180.0, "le": 180.0, "unit": "deg"})
    wave_amp_dps: float = field(default=0.4, metadata={
        "ge": 0.0, "unit": "deg/s", "doc": "nonlinear: amplitude of the waves' yaw rate"})
    wave_period_s: float = field(default=7.0, metadata={
        "gt": 0.0, "unit": "s", "doc": "nonlinear: the waves' period"})
    turn_every_s: float = field(default=0.0, metadata={
        "ge": 0.0, "doc": "the setpoint turns every this long (0: no turns)", "unit": "s"})
    turn_deg: float = field(default=30.0, metadata={
        "ge": -180.0, "le": 180.0, "unit": "deg",
        "doc": "with turn_every_s: the setpoint alternates by this"})
    gyro_noise_dps: float = field(default=0.05, metadata={
        "ge": 0.0, "unit": "deg/s", "doc": "σ of the yaw-rate gyro's white noise"})
    gyro_bias_max_dps: float = field(default=0.2, metadata={
        "ge": 0.0, "unit": "deg/s", "doc": "the gyro's bias, drawn uniformly within ± this"})


@dataclass(frozen=True)
class RovConfig:
    """Everything the ROV loop needs (the ``[rov]`` table of ``config/rov.toml``).

    ``recorder`` is the file's top-level ``[recorder]`` (one per file), filled in by the loader.
    """

    period_s: float = field(default=0.2, metadata={
        "ge": 0.005, "le": 60.0, "unit": "s",
        "doc": "the control loop's period (one poll of the vehicle, one FDI step, one command)"})
    heading_source: HeadingSource = field(
        default="outland",
        metadata={"doc": "outland: the Outland link; mavlink: an ArduSub autopilot ([mavlink])"})
    setpoint_deg: float = field(default=150.0, metadata={
        "ge": 0.0, "lt": 360.0, "unit": "deg", "doc": "heading to hold"})
    surge_pct: float = field(default=0.0, metadata={
        "ge": -100.0, "le": 100.0, "unit": "%",
        "doc": "forward thrust added to both thrusters (common mode)"})
    dropout_hold_s: float = field(default=1.0, metadata={
        "ge": 0.0, "le": 3600.0, "unit": "s",
        "doc": "without telemetry, the last command is held this long, then the thrusters go "
               "neutral"})
    detector: DetectorConfig = field(default_factory=DetectorConfig)
    ft: FtConfig = field(default_factory=FtConfig)
    pid: PidConfig = field(default_factory=PidConfig)
    link: LinkConfig = field(default_factory=LinkConfig)
    sim: SimConfig = field(default_factory=SimConfig)
    ardusub: ArduSubConfig = field(default_factory=ArduSubConfig)
    recorder: RecorderConfig = field(default_factory=RecorderConfig, metadata={"toml": False})


COMPASS_ONLY = "compass only: slow drifts are not detectable"
"""What the banner and ``doctor`` say of an ROV without a gyro witness (docs/rov.md)."""


def rov_gyro(rov: RovConfig) -> str | None:
    """The yaw-rate gyro the ROV's fault detection gets, as the banner names it, or None when it
    runs on the compass alone: the Outland link carries no gyro; ArduSub with
    ``gyro = "none"``; or ``[rov.ft] gyro_enabled = false``."""
    if not rov.ft.gyro_enabled or rov.heading_source == "outland":
        return None
    a = rov.ardusub
    if a.gyro == "imu":
        return f"{a.compass_message} gyro"
    return "ATTITUDE rates" if a.gyro == "attitude" else None


def heading_source_errors(rov: RovConfig | None, has_mavlink: bool, file: str) -> list[ConfigError]:
    """``heading_source = "mavlink"`` needs the router (a ``[mavlink]`` table) for its heading."""
    if rov is not None and rov.heading_source == "mavlink" and not has_mavlink:
        return [ConfigError(file, "rov.heading_source", 'a [mavlink] table with "mavlink" (the '
                            "heading comes from the autopilot's ATTITUDE through the router)",
                            '"mavlink" without [mavlink]')]
    return []
