"""The live INS/GNSS vehicle's IMU link (issue G): over ``socket://`` (a real TCP connection on
127.0.0.1, as SITL's second TCP port) at 50 Hz the INS integrates at least 99 % of the samples;
an IMU stream that slows below ``min_imu_rate_hz`` after a good start, measured on the samples
actually integrated, stops the INS with a warning (the rover detector meanwhile), and a replay
of the same recording decides the same."""

from __future__ import annotations

import logging
import re
from dataclasses import replace
from pathlib import Path

import pytest

from firmware_host.devtools import insgnss_sim as sim
from firmware_host.devtools.insgnss_live import UTC0, LinkImpairment, run_live
from firmware_host.runtime.config import CONFIG_DIR, insgnss_setup, load_bridge_file

DAY0 = float(UTC0 % 86400.0)  # the records' t: seconds of the day


def _setup(rest_s: int) -> sim.InsGnssSetup:
    base = sim.load_setup(None)
    return replace(base, sim=replace(base.sim, epochs=20, rest_s=rest_s, random_faults=0))


def test_an_ins_fed_by_socket_at_50_hz_integrates_every_sample(tmp_path: Path) -> None:
    """The live example's filter and live settings (config/insgnss-live-example.toml, whose
    IMU is ``socket://127.0.0.1:5762``: here the port of the test's listener), RAW_IMU at
    50 Hz with ATTITUDE for the heading at rest, as SITL's TCP port sends them."""
    ex = insgnss_setup(load_bridge_file(CONFIG_DIR / "insgnss-live-example.toml"))
    assert ex.live.imu_url.startswith("socket://127.0.0.1:")
    base = _setup(60)
    setup = replace(base, filter=ex.filter, live=ex.live,
                    sim=replace(base.sim, imu=ex.sim.imu))
    data = sim.generate(setup, "clean", 1)
    lr = run_live(setup, data, tmp_path, seed=1, imu_message="RAW_IMU", decimate=2,
                  imu_socket=True, speed=10.0, attitude_error_deg=1.0)
    ins = lr.summary["ins"]
    imu = ins["imu"]
    assert not ins["refused"] and ins["imu_rate_hz"] == pytest.approx(50.0, rel=0.01)
    sent = (len(data.traj.t) - 1) // 2 + 1  # every other 100 Hz sample from k = 1
    assert imu["received"] >= 0.99 * sent, (imu, sent)
    assert ins["aligned_at"] is not None and ins["alignment"]["method"] == "attitude"
    # every sample after the alignment is integrated (the last epochs' samples too)
    after = 50.0 * (float(data.gnss_t[-1]) - (ins["aligned_at"] - DAY0))
    assert imu["integrated"] >= 0.99 * after, (imu, after)
    assert imu["late"] == 0 and ins["resets"] == {}


def test_a_stream_that_slows_below_the_minimum_stops_the_ins(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """100 Hz until 30 s after the alignment, then one sample in 10 (10 Hz, below the 20 Hz
    minimum; the gaps of 0.1 s stay below max_imu_gap_s, so nothing else notices)."""
    setup = _setup(60)
    data = sim.generate(setup, "clean", 1)
    thin = LinkImpairment(thin_from_s=-10.0, thin_keep=10)
    with caplog.at_level(logging.WARNING, logger="fdi_bridge.insgnss"):
        lr = run_live(setup, data, tmp_path, seed=1, impair=thin)
    ins = lr.summary["ins"]
    assert not ins["refused"]  # the first samples were fine
    assert ins["rate_drops"] >= 1 and "imu_rate" in ins["resets"]
    said = [r.getMessage() for r in caplog.records if "imu_rate" in r.getMessage()]
    assert said and "below min_imu_rate_hz 20" in said[0], said
    late = [r for r in lr.records if float(r["t"]) - DAY0 > -5.0]
    assert late and all(r["mode"] == "rover" for r in late)  # the rover detector meanwhile


def test_the_status_line_says_the_ins_is_coasting(tmp_path: Path) -> None:
    """The operator sees the coast (issue G): a GNSS outage over the last epochs, the vehicle's
    status line section then is "INS coasting, N s, accuracy X m" or, past the limit,
    "INS coast limit, N s: no fix", beside the IMU's rate."""
    setup = _setup(60)
    data = sim.generate(setup, "clean", 1)
    lr = run_live(setup, data, tmp_path, seed=1, outage=(float(data.gnss_t[-1]) - 4.5, 1e9))
    assert len(lr.status) == 2 and lr.status[1] == "imu 100 Hz", lr.status
    assert re.fullmatch(r"INS coast(ing, [45] s, accuracy [\d.]+ m| limit, [45] s: no fix)",
                        lr.status[0]), lr.status
