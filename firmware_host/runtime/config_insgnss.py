"""Schema of the INS/GNSS filter and its simulator: ``[insgnss]`` (``config/insgnss*.toml``).

Loading and validation: :func:`firmware_host.runtime.config.load_bridge_file`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

from fdi.insgnss_params import ImuErrorModel, InsGnssParams


@dataclass(frozen=True)
class InsGnssSimParams:
    """Generator parameters (the ``[sim]`` table)."""

    epochs: int = field(default=501, metadata={
        "ge": 20, "doc": "GNSS epochs, 1 s apart", "unit": "epochs"})
    imu_rate_hz: int = field(default=100, metadata={
        "ge": 1, "le": 1000, "unit": "Hz", "doc": "the simulated IMU's sample rate"})
    speed_m_s: float = field(default=60.0, metadata={
        "gt": 0.0, "unit": "m/s", "doc": "the simulated vehicle's speed (the paper's: 60)"})
    imu: ImuErrorModel = field(default_factory=ImuErrorModel)
    gnss_sigma_h_m: float = field(default=3.0, metadata={
        "ge": 0.0, "unit": "m", "doc": "simulated GNSS noise: east/north 1σ"})
    gnss_sigma_v_m: float = field(default=5.0, metadata={
        "ge": 0.0, "unit": "m", "doc": "simulated GNSS noise: up 1σ"})
    gnss_sigma_vel_m_s: float = field(default=0.1, metadata={
        "ge": 0.0, "unit": "m/s", "doc": "simulated GNSS velocity noise 1σ"})
    fault_h_m: float = field(default=100.0, metadata={
        "doc": "over-limit fault, east and north", "ge": -10000.0, "le": 10000.0, "unit": "m"})
    fault_v_m: float = field(default=20.0, metadata={
        "doc": "over-limit fault, up", "ge": -10000.0, "le": 10000.0, "unit": "m"})
    deviation_h_m: float = field(default=20.0, metadata={
        "doc": "deviation fault, east/north", "ge": -10000.0, "le": 10000.0, "unit": "m"})
    deviation_v_m: float = field(default=4.0, metadata={
        "doc": "deviation fault, up", "ge": -10000.0, "le": 10000.0, "unit": "m"})
    random_faults: int = field(default=100, metadata={
        "ge": 0, "unit": "epochs", "doc": "paper-random scenario: the over-limit fault on this "
                                          "many epochs drawn at random"})
    table2_fault_h_m: float = field(default=20.0, metadata={
        "ge": 0.0, "doc": "table2-calibrated: 1σ of the east/north fault", "unit": "m"})
    table2_fault_v_m: float = field(default=20.0, metadata={
        "ge": 0.0, "doc": "table2-calibrated: 1σ of the up fault", "unit": "m"})
    gyro_drift_deg_s_per_min: float = field(default=0.0, metadata={
        "ge": 0.0, "doc": "a drift added to every gyro axis as ArduPilot's simulated IMU "
                          "(SIM_DRIFT_SPEED, 0.05 there): it grows this fast from the "
                          "autopilot's boot for gyro_drift_time_min, then falls back, and so on",
        "unit": "(deg/s)/min"})
    gyro_drift_time_min: float = field(default=5.0, metadata={
        "gt": 0.0, "doc": "SIM_DRIFT_TIME: minutes of rise (and of fall)", "unit": "min"})
    rest_s: int = field(default=0, metadata={
        "ge": 0, "le": 3600, "doc": "lead-in before the paper's t = 0: this long at rest (a real "
                                    "vehicle's coarse alignment), no faults", "unit": "s"})
    takeoff_s: int = field(default=20, metadata={
        "ge": 1, "le": 600, "doc": "with rest_s > 0: then a straight take-off roll from 0 to "
                                   "speed_m_s over this long, ending at the paper's t = 0",
        "unit": "s"})

    @property
    def lead_s(self) -> int:
        """Seconds (GNSS epochs) of lead-in before the paper's t = 0 (rest, take-off roll)."""
        return self.rest_s + self.takeoff_s if self.rest_s > 0 else 0


@dataclass(frozen=True)
class InsGnssLiveParams:
    """The live vehicle (``[insgnss.live]``, firmware_host/insgnss/vehicle.py): where the IMU
    comes from and how its samples are put in order. The GNSS receiver is ``[rover]``'s port."""

    imu_url: str = field(default="", metadata={
        "url": "imu",
        "doc": "the autopilot's MAVLink link carrying the IMU (a serial device, a pty, "
               "socket://HOST:PORT); \"router\": the [mavlink] router's autopilot link; "
               "empty: no INS, the rover detector alone"})
    imu_baudrate: int = field(default=921600, metadata={
        "gt": 0, "unit": "baud", "doc": "line speed of a serial imu_url"})
    imu_message: Literal["RAW_IMU", "HIGHRES_IMU", "SCALED_IMU", "SCALED_IMU2",
                         "SCALED_IMU3"] = field(default="RAW_IMU", metadata={
        "doc": "the MAVLink message that carries the IMU samples"})
    hold_s: float = field(default=0.3, metadata={
        "ge": 0.0, "le": 10.0, "doc": "an epoch waits for IMU samples stamped this long after it "
                                      "(late and out-of-order samples of a telemetry link)",
        "unit": "s"})
    max_wait_s: float = field(default=1.0, metadata={
        "ge": 0.001, "le": 60.0, "doc": "wall-clock wait for those samples before the epoch goes "
                                        "without", "unit": "s"})
    rate_samples: int = field(default=50, metadata={
        "ge": 10, "doc": "IMU samples whose median interval decides the rate check",
        "unit": "samples"})
    align_s: float = field(default=1.0, metadata={
        "gt": 0.0, "doc": "accelerometer averaging time for the levelling", "unit": "s"})
    align_max_gyro_deg_s: float = field(default=2.0, metadata={
        "gt": 0.0, "unit": "deg/s", "doc": "at rest: nothing turns faster than this"})
    align_max_accel_dev_m_s2: float = field(default=0.5, metadata={
        "gt": 0.0, "unit": "m/s^2", "doc": "at rest: |f| within this of g"})
    align_min_speed_m_s: float = field(default=3.0, metadata={
        "gt": 0.0, "doc": "GNSS speed from which its course is the heading", "unit": "m/s"})
    heading_source: Literal["auto", "gnss", "attitude"] = field(default="auto", metadata={
        "doc": "auto: gyrocompass when the configured gyro can, else the autopilot's ATTITUDE "
               "yaw when the link carries it, else the GNSS course once moving; gnss: the "
               "course (or gyrocompass); attitude: the ATTITUDE yaw only"})
    attitude_sigma_deg: float = field(default=3.0, metadata={
        "gt": 0.0, "doc": "heading_source = attitude: 1σ of the autopilot's yaw", "unit": "deg"})
    course_sigma_deg: float = field(default=1.0, metadata={
        "ge": 0.0, "doc": "heading from the GNSS course: its 1σ at least this (sideslip, crab)",
        "unit": "deg"})
    rest_align_s: float = field(default=30.0, metadata={
        "gt": 0.0, "doc": "at rest this long: level, gyrocompass (or ATTITUDE yaw) and start the "
                          "INS", "unit": "s"})
    rest_max_speed_m_s: float = field(default=0.5, metadata={
        "gt": 0.0, "doc": "at rest: GNSS speed at most this", "unit": "m/s"})
    rest_max_accel_m_s2: float = field(default=0.05, metadata={
        "gt": 0.0, "doc": "at rest: the mean specific force changes by at most this from one "
                          "epoch to the next", "unit": "m/s^2"})
    rest_sigma_vel_m_s: float = field(default=0.01, metadata={
        "gt": 0.0, "doc": "at rest: 1σ of the zero-velocity update (ZUPT) of every epoch",
        "unit": "m/s"})
    gyrocompass_max_sigma_deg: float = field(default=1.0, metadata={
        "gt": 0.0, "doc": "gyrocompass only when the configured gyro gives this heading 1σ "
                          "(navigation grade); else heading from the GNSS course once moving",
        "unit": "deg"})
    rest_sigma_gyro_deg_s: float = field(default=0.02, metadata={
        "gt": 0.0, "doc": "at rest: 1σ of the zero-angular-rate update (ZARU) of the gyro biases "
                          "on the epoch's mean gyro, beside the white noise (RAW_IMU's 1 mrad/s "
                          "steps, vibration)", "unit": "deg/s"})
    coast_max_s: float = field(default=10.0, metadata={
        "ge": 0.0, "le": 600.0, "doc": "GNSS outage: the INS's coast goes out as a 3D fix (its "
                                       "own accuracy) for at most this long, then no-fix "
                                       "(ArduPilot: ~10 s of useful inertial position)",
        "unit": "s"})
    coast_max_acc_h_m: float = field(default=3.0, metadata={
        "gt": 0.0, "doc": "GNSS outage: no-fix as soon as the coast's claimed horizontal "
                          "accuracy is worse than this (no better than a plain fix)", "unit": "m"})


@dataclass(frozen=True)
class InsGnssSetup:
    """The ``[insgnss]`` table: ``[insgnss.filter]``, ``[insgnss.sim]``, ``[insgnss.live]``."""

    filter: InsGnssParams = field(default_factory=InsGnssParams)
    sim: InsGnssSimParams = field(default_factory=InsGnssSimParams)
    live: InsGnssLiveParams = field(default_factory=InsGnssLiveParams)
