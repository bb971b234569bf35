"""Schema of the INS/GNSS filter and its simulator: ``[insgnss]`` (``config/insgnss*.toml``).

Loading and validation: :func:`firmware_host.runtime.config.load_bridge_file`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from fdi.insgnss import ImuErrorModel, InsGnssParams


@dataclass(frozen=True)
class InsGnssSimParams:
    """Generator parameters (the ``[sim]`` table)."""

    epochs: int = field(default=501, metadata={"ge": 20, "doc": "GNSS epochs, 1 s apart"})
    imu_rate_hz: int = field(default=100, metadata={"ge": 1, "le": 1000})
    speed_m_s: float = field(default=60.0, metadata={"gt": 0.0})
    imu: ImuErrorModel = field(default_factory=ImuErrorModel)
    gnss_sigma_h_m: float = field(default=3.0, metadata={"ge": 0.0})
    gnss_sigma_v_m: float = field(default=5.0, metadata={"ge": 0.0})
    gnss_sigma_vel_m_s: float = field(default=0.1, metadata={"ge": 0.0})
    fault_h_m: float = field(default=100.0, metadata={"doc": "over-limit fault, east and north"})
    fault_v_m: float = field(default=20.0, metadata={"doc": "over-limit fault, up"})
    deviation_h_m: float = field(default=20.0, metadata={"doc": "deviation fault, east/north"})
    deviation_v_m: float = field(default=4.0, metadata={"doc": "deviation fault, up"})
    random_faults: int = field(default=100, metadata={"ge": 0})
    table2_fault_h_m: float = field(
        default=20.0, metadata={"ge": 0.0, "doc": "table2-calibrated: 1σ of the east/north fault"})
    table2_fault_v_m: float = field(
        default=20.0, metadata={"ge": 0.0, "doc": "table2-calibrated: 1σ of the up fault"})


@dataclass(frozen=True)
class InsGnssSetup:
    """The ``[insgnss]`` table: ``[insgnss.filter]`` and ``[insgnss.sim]``."""

    filter: InsGnssParams = field(default_factory=InsGnssParams)
    sim: InsGnssSimParams = field(default_factory=InsGnssSimParams)
