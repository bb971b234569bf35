"""Alignment of the live INS/GNSS vehicle at rest with a MEMS gyro (issue G): the heading
comes from the autopilot's ATTITUDE yaw where the link carries it (``heading_source =
"auto"``, the default), without waiting for the 3 m/s of a GNSS course, and the wait reason
names what is awaited. The simulated autopilot plays over real ptys."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from firmware_host.devtools import insgnss_sim as sim
from firmware_host.devtools.insgnss_live import run_live

T_TAKEOFF = 43200.0 - 20.0  # GNSS time (s of the day) of the take-off roll's start


def _setup(gyro_bias_deg_h: float, **live: object) -> sim.InsGnssSetup:
    base = sim.load_setup(None)
    flt = replace(base.filter, imu=replace(base.filter.imu, gyro_bias_deg_h=gyro_bias_deg_h))
    return replace(base, filter=flt, sim=replace(base.sim, epochs=20, rest_s=40),
                   live=replace(base.live, **live))  # type: ignore[arg-type]


def test_a_mems_gyro_aligns_at_rest_from_attitude_by_default(tmp_path: Path) -> None:
    """A MEMS gyro (10 deg/h cannot gyrocompass), ATTITUDE on the link, default heading
    source: aligned at rest by "attitude" after ``rest_align_s``, before the take-off roll,
    ZUPTs at rest after it; the wait reason says levelling, heading from ATTITUDE."""
    setup = _setup(10.0)
    assert setup.live.heading_source == "auto"
    data = sim.generate(setup, "clean", 1)
    lr = run_live(setup, data, tmp_path, seed=1, attitude_error_deg=1.0)
    ins = lr.summary["ins"]
    assert ins["alignment"]["method"] == "attitude"
    assert ins["aligned_at"] < T_TAKEOFF - 5.0
    assert ins["zupts"] > 0
    assert ins["align_wait"]["at rest: levelling (heading from ATTITUDE)"] > 20
    assert not any("gyrocompass" in k or "course" in k for k in ins["align_wait"])


def test_heading_source_attitude_says_what_it_waits_for(tmp_path: Path) -> None:
    """``heading_source = "attitude"`` with a gyro that could gyrocompass: the wait at rest is
    "levelling (heading from ATTITUDE)", never "levelling and gyrocompassing"."""
    setup = _setup(0.01, heading_source="attitude")
    data = sim.generate(setup, "clean", 2)
    lr = run_live(setup, data, tmp_path, seed=2, attitude_error_deg=1.0)
    ins = lr.summary["ins"]
    assert ins["alignment"]["method"] == "attitude"
    assert ins["aligned_at"] < T_TAKEOFF - 5.0
    assert ins["align_wait"]["at rest: levelling (heading from ATTITUDE)"] > 20
    assert "at rest: levelling and gyrocompassing" not in ins["align_wait"]
