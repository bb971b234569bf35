"""A real BlueROV2 dive (the shared ArduSub tlog) replayed through the ArduSub ROV vehicle.

Not the detector alone (tests/test_rov_tlog.py): the vehicle on the Runner behind the router,
fed over UDP on 127.0.0.1 in lockstep with the log's own timestamps (5 Hz ticks, every packet of
a tick sent before the vehicle's step): the autopilot's ATTITUDE (yaw as logged, plus an optional
drift) and HEARTBEAT, the pilot's MANUAL_CONTROL from the ground station, in detect-only mode
(``[rov.ardusub] steer = false``: nothing is sent to the vehicle).
"""

from __future__ import annotations

import math
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest

from drivers.mavlink import io as mio
from firmware_host.mavlink.router import EndpointConfig, MavlinkConfig, open_router
from firmware_host.rov.ardusub import ArduSubRovVehicle
from firmware_host.rov.config import load_rov_config, project_root
from firmware_host.runtime.runner import Runner

TICK_S = 0.2


def _wait(cond: Any, what: str, timeout_s: float = 3.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not cond():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.0002)


def _ticks(path: Path) -> list[list[Any]]:
    """The log's ATTITUDE, HEARTBEAT (autopilot) and MANUAL_CONTROL grouped into 0.2 s ticks
    from the first ATTITUDE (as firmware_host.rov.tlog.load_dive samples it)."""
    msgs = [(r.t_us / 1e6, r) for r in mio.iter_tlog(path) if r.msg is not None and (
        (r.msg.get_type() in ("ATTITUDE", "HEARTBEAT", "RAW_IMU")
         and (r.msg.get_srcSystem(), r.msg.get_srcComponent()) == (1, 1))
        or r.msg.get_type() == "MANUAL_CONTROL")]
    msgs.sort(key=lambda m: m[0])
    first = next(t for t, r in msgs if r.msg.get_type() == "ATTITUDE")
    ticks: list[list[Any]] = [[]]
    tick = first
    for t, rec in msgs:
        while t > tick:
            ticks.append([])
            tick += TICK_S
        ticks[-1].append(rec)
    return ticks


def replay_vehicle(path: Path, drift_deg: float = 0.0, drift_at_s: float | None = None,
                   **ardusub: Any) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """``ardusub``: more ``[rov.ardusub]`` keys (the raw compass: RAW_IMU as logged)."""
    cfg, _ = load_rov_config(project_root() / "config" / "rov.toml")
    ardusub.setdefault("gyro", "none")  # the FIR alone, unless a test says which gyro
    cfg = replace(cfg, heading_source="mavlink",
                  ardusub=replace(cfg.ardusub, steer=False, **ardusub))
    records: list[dict[str, Any]] = []
    v = ArduSubRovVehicle(cfg, on_epoch=records.append)
    mav = MavlinkConfig(autopilot=EndpointConfig("udpin:127.0.0.1:0"),
                        gcs=(EndpointConfig("udpin:127.0.0.1:0"),))
    runner = Runner(v, mavlink=mav, open_router=open_router, handle_signals=False)
    runner.start()
    assert runner.router is not None and v.loop is not None
    loop = v.loop
    ports = [ep.link.local_address[1] for ep in runner.router.endpoints]  # type: ignore[index]
    ap = mio.MavEndpoint(f"udpout:127.0.0.1:{ports[0]}", source_system=1, source_component=1)
    gcs = mio.MavEndpoint(f"udpout:127.0.0.1:{ports[1]}", source_system=255,
                          source_component=190)
    sent = {"att": 0, "hb": 0, "mc": 0, "imu": 0}
    try:
        for k, tick in enumerate(_ticks(path)):
            t = k * TICK_S  # the tick's time from the first ATTITUDE (the record's "t")
            for rec in tick:
                kind = rec.msg.get_type()
                if kind == "ATTITUDE":
                    yaw = rec.msg.yaw
                    if drift_at_s is not None and t >= drift_at_s - 1e-9:
                        yaw += math.radians(drift_deg)
                    ap.send_attitude(rec.msg.time_boot_ms, rec.msg.roll, rec.msg.pitch, yaw)
                    sent["att"] += 1
                elif kind == "HEARTBEAT":
                    ap.send_raw(rec.raw)
                    sent["hb"] += 1
                elif kind == "RAW_IMU":
                    if loop.compass is not None:
                        ap.send_raw(rec.raw)
                        sent["imu"] += 1
                else:
                    gcs.send_raw(rec.raw)
                    sent["mc"] += 1
            _wait(lambda: loop.heading.received >= sent["att"]
                  and loop.autopilot.received >= sent["hb"]
                  and loop.pilot.received >= sent["mc"]
                  and (loop.compass is None or loop.compass.received >= sent["imu"]),
                  f"tick {k}'s packets")
            runner.step()
    finally:
        ap.close()
        gcs.close()
        summary = runner.close()
    return records, summary


@pytest.fixture
def tlog(corpus: Path) -> Path:
    path = corpus / "ardusub" / "small.tlog"
    if not path.exists():
        pytest.skip(f"the ArduSub dive is not in the corpus ({path})")
    return path


def test_clean_dive_through_the_vehicle_no_confirmed_fault(tlog: Path) -> None:
    records, summary = replay_vehicle(tlog)
    assert len(records) > 1250  # > 250 s of dive
    assert not any(r["fault"] for r in records)
    assert not any(r["event"] == "confirmed" for r in records)
    assert summary["manual_control_sent"] == 0  # detect only
    assert summary["ardusub_states"] == {"detect_only": len(records)}
    assert summary["pilot_received"] > 1000
    yaws = [r for r in records if r["heading_meas"] is not None]
    assert len(yaws) > 0.95 * len(records)


def test_drift_in_the_dive_is_confirmed_through_the_vehicle(tlog: Path) -> None:
    records, _ = replay_vehicle(tlog, drift_deg=20.0, drift_at_s=150.0)
    t_conf = next(r["t"] for r in records if r["event"] == "confirmed")
    assert 150.0 <= t_conf <= 152.0
    assert not any(r["fault"] for r in records if r["t"] < 150.0)


DEC_DEG = 15.73  # the dive's COMPASS_DEC (0.2746 rad)


def test_dive_on_the_raw_compass_at_2_hz(tlog: Path) -> None:
    """The dive's RAW_IMU came at 2 Hz (SR0_RAW_SENS = 2): said once, and without the gyro
    nothing is confirmed (3 periods of 5 have no compass: the dropout rule holds)."""
    records, summary = replay_vehicle(tlog, heading="raw_compass", declination_deg=DEC_DEG)
    assert summary["compass_slow_hz"] == pytest.approx(2.0, abs=0.1)
    assert not any(r["event"] == "confirmed" for r in records)
    with_heading = sum(r["heading_meas"] is not None for r in records)
    assert 0.35 * len(records) < with_heading < 0.45 * len(records)


def test_dive_raw_compass_with_the_gyro_flags_a_magnetic_excursion(tlog: Path) -> None:
    """With RAW_IMU's gyro as the witness, one confirmation, at 218.8 s: from 214 s the raw
    compass leaves the gyro by 10-25 deg (it settles ~14 deg below) while the gyro turns less
    than 3 deg, and ATTITUDE's EKF yaw follows the compass only slowly (~0.5 deg/s). No
    ground truth says which was right; the autopilot's own EKF moving towards the compass
    suggests a real disturbance of the magnetometer, not a false alarm of the witness."""
    records, _ = replay_vehicle(tlog, heading="raw_compass", declination_deg=DEC_DEG,
                                gyro="imu")
    confirmed = [r["t"] for r in records if r["event"] == "confirmed"]
    assert len(confirmed) == 1 and 214.0 <= confirmed[0] <= 222.0, confirmed
    t_conf = confirmed[0]

    def median(values: list[float]) -> float:
        v = sorted(values)
        return v[len(v) // 2]

    def raw(t0: float, t1: float) -> float:
        return median([r["heading_meas"] for r in records
                       if t0 <= r["t"] < t1 and r["heading_meas"] is not None])

    moved = raw(219.0, 226.0) - raw(205.0, 211.0)
    rates = [r["yaw_rate"] for r in records if 211.0 <= r["t"] < 226.0 and r["yaw_rate"]]
    gyro_moved = sum(rates) / len(rates) * 15.0
    assert moved < -10.0 and abs(gyro_moved) < 3.0, (moved, gyro_moved)
    at = next(r for r in records if r["t"] == t_conf)
    assert at["heading_attitude"] - at["heading_meas"] > 10.0  # the EKF still far from it
    assert not any(r["fault"] for r in records if r["t"] < 211.0)
