"""MAVLink IMU messages to SI units; the real ArduSub log is read and refused (2 Hz)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from drivers.mavlink.imu import RawImuScale, imu_from_message, iter_imu
from fdi.errors import DecodeError, EstimatorError
from fdi.insgnss import InsGnssFilter, InsGnssParams, check_imu_rate, measure_imu_rate

ROOT = Path(__file__).resolve().parents[1]
TLOG = ROOT.parent / "shared" / "corpus" / "ardusub" / "small.tlog"
G = 9.80665


class Msg:
    """A duck-typed MAVLink message: ``get_type()`` and attributes."""

    def __init__(self, kind: str, **fields: Any) -> None:
        self._kind = kind
        self.__dict__.update(fields)

    def get_type(self) -> str:
        return self._kind


IMU_FIELDS = dict(xacc=10, yacc=-20, zacc=-1000, xgyro=5, ygyro=-7, zgyro=100)


def test_raw_imu_is_ardupilot_mg_and_mrad() -> None:
    s = imu_from_message(Msg("RAW_IMU", time_usec=2_500_000, id=0, **IMU_FIELDS))
    assert s is not None and s.source == "RAW_IMU" and s.imu_id == 0
    assert s.t_s == pytest.approx(2.5)
    assert s.accel_m_s2 == pytest.approx((0.01 * G, -0.02 * G, -G))
    assert s.gyro_rad_s == pytest.approx((0.005, -0.007, 0.1))
    counts = imu_from_message(
        Msg("RAW_IMU", time_usec=0, **IMU_FIELDS), RawImuScale(accel_m_s2_per_lsb=1e-3)
    )
    assert counts is not None and counts.accel_m_s2[2] == pytest.approx(-1.0)


def test_scaled_imu2_units_and_time() -> None:
    s = imu_from_message(Msg("SCALED_IMU2", time_boot_ms=1234, **IMU_FIELDS))
    assert s is not None and s.imu_id == 1
    assert s.t_s == pytest.approx(1.234)
    assert s.accel_m_s2[2] == pytest.approx(-G)
    assert s.gyro_rad_s[2] == pytest.approx(0.1)


def test_highres_imu_is_already_si() -> None:
    s = imu_from_message(Msg("HIGHRES_IMU", time_usec=1_000_000, xacc=0.1, yacc=0.2,
                             zacc=-9.81, xgyro=0.01, ygyro=0.02, zgyro=0.03))
    assert s is not None
    assert s.accel_m_s2 == pytest.approx((0.1, 0.2, -9.81))
    assert s.gyro_rad_s == pytest.approx((0.01, 0.02, 0.03))


def test_no_inertial_data_and_other_messages() -> None:
    zeros = dict.fromkeys(IMU_FIELDS, 0)
    assert imu_from_message(Msg("SCALED_IMU2", time_boot_ms=1, **zeros)) is None
    assert imu_from_message(Msg("HEARTBEAT")) is None
    with pytest.raises(DecodeError, match="imu-field"):
        imu_from_message(Msg("RAW_IMU", time_usec=1, xacc=1))
    msgs = [None, Msg("HEARTBEAT"), Msg("RAW_IMU", time_usec=1, **IMU_FIELDS),
            Msg("SCALED_IMU2", time_boot_ms=1, **IMU_FIELDS)]
    assert [s.source for s in iter_imu(msgs)] == ["RAW_IMU", "SCALED_IMU2"]
    assert [s.source for s in iter_imu(msgs, "SCALED_IMU2")] == ["SCALED_IMU2"]


@pytest.fixture(scope="module")
def tlog_raw_imu() -> list:
    if not TLOG.is_file():
        pytest.skip(f"ArduSub corpus not found at {TLOG}")
    mavlink_io = pytest.importorskip("drivers.mavlink.io")
    return list(iter_imu((r.msg for r in mavlink_io.iter_tlog(TLOG)), "RAW_IMU"))


def test_real_tlog_units(tlog_raw_imu: list) -> None:
    assert len(tlog_raw_imu) == 528
    acc = np.array([s.accel_m_s2 for s in tlog_raw_imu])
    gyr = np.array([s.gyro_rad_s for s in tlog_raw_imu])
    # a diving ROV: specific force about 1 g, mostly on −z (FRD), rates well under 1 rad/s
    assert np.median(np.linalg.norm(acc, axis=1)) == pytest.approx(G, abs=0.15)
    assert np.median(acc[:, 2]) < -0.9 * G
    assert np.percentile(np.abs(gyr), 99) < 1.0


def test_real_tlog_rate_is_refused(tlog_raw_imu: list) -> None:
    rate = measure_imu_rate([s.t_s for s in tlog_raw_imu])
    assert rate == pytest.approx(2.0, abs=0.1)
    params = InsGnssParams()
    with pytest.raises(EstimatorError, match=r"rate 2 Hz is below the 20 Hz"):
        check_imu_rate(rate, params.min_imu_rate_hz, "RAW_IMU")
    first = tlog_raw_imu[0]
    kf = InsGnssFilter(params, first.t_s, (0, 0, 0), (0, 0, 0), (0, 0, 0))
    with pytest.raises(EstimatorError, match="below the 20 Hz"):
        for s in tlog_raw_imu[1:]:
            kf.propagate(s.t_s, s.gyro_rad_s, s.accel_m_s2)
