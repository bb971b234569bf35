"""The live INS/GNSS vehicle end to end: a simulated autopilot writes real MAVLink IMU packets to
one pty and NMEA to another (firmware_host/devtools/insgnss_live.py), the vehicle runs on the
Runner and writes epochs.jsonl / summary.json. Runs are shortened (150 of the paper's 501
epochs) and played 50x faster than real time to keep the wall time modest; the full-length
numbers (all six scenario/seed pairs) are measured in docs/insgnss-live.md."""

from __future__ import annotations

import json
import threading
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from drivers.mavlink.io import MavEndpoint
from drivers.ptypair import PtyPair
from firmware_host.cli import main
from firmware_host.commands.launch import vehicle_from_file
from firmware_host.devtools import insgnss_sim as sim
from firmware_host.devtools.insgnss_live import (
    LinkImpairment,
    LiveRun,
    compare,
    nmea_epoch,
    offline_aligned,
    rms,
    run_live,
    unread,
)
from firmware_host.insgnss.vehicle import InsGnssVehicle
from firmware_host.runtime.config import CONFIG_DIR, BridgeConfig, load_bridge_file
from firmware_host.runtime.runner import Runner

EPOCHS = 150


def _setup(rest_s: int = 0, epochs: int = EPOCHS) -> sim.InsGnssSetup:
    setup = sim.load_setup(None)  # the paper preset, as `sim insgnss` by default
    # paper-random keeps the paper's density of faults: 100 in 500 epochs
    return replace(setup, sim=replace(setup.sim, epochs=epochs, rest_s=rest_s,
                                      random_faults=round(100 * (epochs - 1) / 500)))


def _check_records(lr: LiveRun) -> None:
    modes = [r["mode"] for r in lr.records]
    assert modes[:2] == ["rover", "rover"]  # aligning: the rover detector alone
    assert modes.count("ins") >= EPOCHS - 4
    ins = next(r for r in lr.records if r["mode"] == "ins")
    for key in ("zones", "dm", "actions", "innov", "pos", "vel", "rpy_deg", "sigma_pos",
                "sigma_att_deg", "acc_h_m", "acc_v_m", "lla"):
        assert key in ins["ins"], key
    assert "action" in ins and "utc" in ins  # the rover's record keys too
    summary = lr.summary
    assert summary["vehicle"] == "insgnss"
    assert summary["ins"]["time_map"] == "system_time"
    assert summary["ins"]["refused"] == ""


@pytest.mark.slow
@pytest.mark.parametrize("scenario,seed", [("paper-single", 1), ("paper-random", 1)])
def test_live_vehicle_within_10_percent_of_sim_insgnss(scenario: sim.Scenario, seed: int,
                                                       tmp_path: Path) -> None:
    """The done-means of issue 12 at full length (the paper's 501 epochs) on the two worst of
    the six pairs (docs/insgnss-live.md has all six, and seeds 4-5): the scenario starts like
    a real vehicle (120 s at rest, a 20 s take-off roll, then the paper's flight) in both runs;
    the live vehicle aligns itself at rest (levelling, gyrocompassing, ZUPTs) and its 3-D
    position RMS over the paper's epochs is within 10 % of ``sim insgnss`` on the same seed
    (the offline filter started from the truth, with the same ZUPTs at rest), below "none" by
    the same factor within 10 %."""
    c = compare(_setup(rest_s=120, epochs=501), scenario, seed, tmp_path)
    ins = c.run.summary["ins"]
    assert ins["alignment"]["method"] == "gyrocompass"
    assert ins["zupts"] > 50  # at rest after the alignment
    assert c.live_epochs == c.offline_epochs == 500  # every paper epoch by the INS
    assert 0.9 <= c.ratio <= 1.1, c.row()
    assert 0.9 <= c.factor_live / c.factor_offline <= 1.1, c.row()


@pytest.mark.parametrize("scenario,seed", [("paper-single", 2), ("paper-random", 1)])
def test_live_vehicle_is_the_offline_filter(scenario: sim.Scenario, seed: int,
                                            tmp_path: Path) -> None:
    """Aligned in flight (no rest: heading from the GNSS course), over real ptys the live
    vehicle gives the offline filter's result on the same data with the same alignment (its
    timing, ordering and time mapping add nothing), and the gate beats no gate by far."""
    setup = _setup()
    data = sim.generate(setup, scenario, seed)
    lr = run_live(setup, data, tmp_path, seed=seed)
    _check_records(lr)
    assert lr.summary["ins"]["alignment"]["method"] == "gnss course"
    j0 = int(lr.epochs[0]) - 1  # the alignment epoch
    ref = offline_aligned(data, setup.filter, j0)
    none = offline_aligned(data, setup.filter, j0, "none")
    assert len(ref) == len(lr.pos_err)
    assert rms(lr.pos_err) == pytest.approx(rms(ref), rel=0.01)
    assert rms(lr.pos_err) < rms(none) / 3.0
    on_disk = json.loads((tmp_path / "summary.json").read_text(encoding="utf-8"))
    assert on_disk["ins"]["epochs"] == lr.summary["ins"]["epochs"]


def test_a_telemetry_link_changes_little(tmp_path: Path) -> None:
    """10 % of the IMU packets dropped, 1 % duplicated, bursts held 200 ms every 2 s and let go
    in random order: the samples are put in order by their own stamps; the RMS moves by less
    than 20 %."""
    setup = _setup()
    data = sim.generate(setup, "paper-single", 1)
    clean = run_live(setup, data, tmp_path / "clean", seed=1)
    bad = run_live(setup, data, tmp_path / "bad", seed=1,
                   impair=LinkImpairment(drop=0.1, duplicate=0.01, burst_every_s=2.0,
                                         burst_s=0.2, shuffle_bursts=True))
    imu = bad.summary["ins"]["imu"]
    assert imu["duplicates"] > 0
    assert imu["out_of_order"] > 0
    assert imu["integrated"] < clean.summary["ins"]["imu"]["integrated"] * 0.95
    assert bad.summary["ins"]["resets"] == {}
    assert list(bad.epochs) == list(clean.epochs)
    assert abs(rms(bad.pos_err) / rms(clean.pos_err) - 1.0) < 0.2


def test_raw_imu_integers_work_too(tmp_path: Path) -> None:
    """RAW_IMU in ArduPilot's mG / mrad/s integers (quantised): still far better than no gate."""
    setup = replace(sim.load_setup(None), sim=replace(_setup().sim, epochs=80))
    data = sim.generate(setup, "paper-single", 2)
    lr = run_live(setup, data, tmp_path, imu_message="RAW_IMU", seed=2)
    assert lr.summary["ins"]["epochs"].get("ins", 0) >= 76
    none = offline_aligned(data, setup.filter, int(lr.epochs[0]) - 1, "none")
    assert rms(lr.pos_err) < rms(none) / 3.0


def test_a_slow_imu_is_refused_and_the_rover_detector_runs(tmp_path: Path,
                                                           caplog: pytest.LogCaptureFixture
                                                           ) -> None:
    """10 Hz IMU (below the 20 Hz minimum): refused once, said in the summary, every epoch
    through the rover detector."""
    setup = replace(sim.load_setup(None), sim=replace(_setup().sim, epochs=30))
    data = sim.generate(setup, "clean", 1)
    with caplog.at_level("ERROR", logger="fdi_bridge.insgnss"):
        lr = run_live(setup, data, tmp_path, decimate=10, seed=1)
    ins = lr.summary["ins"]
    assert "below the 20 Hz" in ins["refused"]
    assert ins["epochs"] == {"rover": 30}
    assert {r["mode"] for r in lr.records} == {"rover"}
    assert sum("below the 20 Hz" in r.getMessage() for r in caplog.records) == 1


def test_the_example_config_is_the_live_vehicle() -> None:
    bf = load_bridge_file(CONFIG_DIR / "insgnss-live-example.toml")
    vehicle, recorder = vehicle_from_file(bf)
    assert isinstance(vehicle, InsGnssVehicle)
    assert recorder is None
    assert [p.name for p in vehicle.ports()] == ["gps", "imu"]
    assert vehicle.live.imu_message == "RAW_IMU"
    assert "127.0.0.1" in vehicle.live.imu_url
    assert vehicle.params.use_velocity is False


def test_the_records_depend_on_the_data_not_on_arrival(tmp_path: Path) -> None:
    """The same data played twice, once at 50x and once at 20x real time: byte-identical
    epochs.jsonl (what a replay of the recording needs; the replay command itself does not
    drive this vehicle yet)."""
    setup = replace(sim.load_setup(None), sim=replace(_setup().sim, epochs=40))
    data = sim.generate(setup, "paper-single", 3)
    run_live(setup, data, tmp_path / "a", seed=3, speed=50.0)
    run_live(setup, data, tmp_path / "b", seed=3, speed=20.0)
    a = (tmp_path / "a" / "epochs.jsonl").read_bytes()
    assert a.count(b"\n") == 40
    assert a == (tmp_path / "b" / "epochs.jsonl").read_bytes()


def test_gps_input_carries_the_filter_covariance(tmp_path: Path) -> None:
    """GPS_INPUT over a real UDP socket on 127.0.0.1: one per epoch, the INS epochs with the
    accuracies of the filter's covariance, larger on the epochs whose fix was replaced."""
    setup = replace(sim.load_setup(None), sim=replace(_setup().sim, epochs=40))
    data = sim.generate(setup, "paper-single", 1)
    with MavEndpoint("udpin:127.0.0.1:0") as rx:
        addr = rx.local_address
        assert addr is not None
        lr = run_live(setup, data, tmp_path, seed=1, mavlink_url=f"udpout:127.0.0.1:{addr[1]}")
        got = []
        while (msg := rx.recv(timeout_s=0.2)) is not None:
            if msg.get_type() == "GPS_INPUT":
                got.append(msg)
    ins = [r for r in lr.records if r["mode"] == "ins"]
    sent = lr.records[:len(got)]
    assert len(got) >= 38  # the last epoch(s) at shutdown are recorded, not sent
    acc = {round(float(m.time_week_ms)): m for m in got}
    assert len(acc) == len(got)
    pairs = [(r, g) for r, g in zip(sent, got, strict=True) if r["mode"] == "ins"]
    assert len(pairs) >= len(ins) - 2
    for r, g in pairs:
        assert g.horiz_accuracy == pytest.approx(r["ins"]["acc_h_m"], rel=1e-5)
        assert g.vert_accuracy == pytest.approx(r["ins"]["acc_v_m"], rel=1e-5)
        la, lo, _ = r["ins"]["lla"]
        # the record keeps 9 decimals, GPS_INPUT 1e-7 deg of the unrounded value
        assert abs(g.lat - la * 1e7) <= 0.51 and abs(g.lon - lo * 1e7) <= 0.51
    replaced = [g.horiz_accuracy for r, g in pairs if "replace" in r["ins"]["actions"][:2]]
    accepted = [g.horiz_accuracy for r, g in pairs if r["ins"]["actions"][:2] == ["accept"] * 2]
    assert replaced and accepted
    # sqrt(P⁻ + R) against sqrt(P⁺) (the first epochs after the alignment have a large P⁺)
    assert min(replaced) > 2.0 * float(np.median(accepted))


def _replay_config(tmp_path: Path) -> Path:
    """The file the simulated session ran with (run_live: the paper preset, the rover's
    defaults, HIGHRES_IMU); the ports are never opened by a replay."""
    cfg = tmp_path / "live.toml"
    cfg.write_text((CONFIG_DIR / "insgnss-paper.toml").read_text(encoding="utf-8")
                   + '\n[rover]\n[rover.port]\nurl = "/dev/ttyUSB0"\ntimeout_s = 0.02\n'
                   '[insgnss.live]\nimu_url = "/dev/ttyAMA1"\nimu_message = "HIGHRES_IMU"\n',
                   encoding="utf-8")
    return cfg


def test_replay_of_the_recording_is_byte_for_byte(tmp_path: Path) -> None:
    """``fdi-bridge run`` with the recorder on (over an impaired IMU link: drops, duplicates,
    shuffled bursts), then ``fdi-bridge replay`` of its capture: the same epochs.jsonl, byte
    for byte; with another filter strategy the records differ (the comparison can fail)."""
    setup = replace(_setup(rest_s=40), sim=replace(_setup().sim, epochs=40, rest_s=40))
    data = sim.generate(setup, "paper-single", 1)
    lr = run_live(setup, data, tmp_path / "live", seed=1, record_dir=tmp_path / "rec",
                  impair=LinkImpairment(drop=0.1, duplicate=0.01, burst_every_s=2.0,
                                        shuffle_bursts=True))
    assert lr.summary["ins"]["epochs"]["ins"] > 50 and lr.summary["ins"]["zupts"] > 0
    (cap,) = sorted((tmp_path / "rec").glob("*.cap"))
    cfg = _replay_config(tmp_path)
    assert main(["replay", str(cap), "--config", str(cfg), "--out", str(tmp_path / "re")]) == 0
    want = (tmp_path / "live" / "epochs.jsonl").read_bytes()
    assert want.count(b"\n") == 100  # 60 s of lead-in and 40 paper epochs
    assert (tmp_path / "re" / "epochs.jsonl").read_bytes() == want
    s = json.loads((tmp_path / "re" / "summary.json").read_text(encoding="utf-8"))
    assert s["vehicle"] == "insgnss"
    for key in ("epochs", "imu", "aligned_at", "zupts"):
        assert s["ins"][key] == lr.summary["ins"][key], key
    other = tmp_path / "other.toml"
    other.write_text(cfg.read_text(encoding="utf-8").replace(
        'strategy = "three_zone"', 'strategy = "none"'), encoding="utf-8")
    assert main(["replay", str(cap), "--config", str(other), "--out", str(tmp_path / "o")]) == 0
    assert (tmp_path / "o" / "epochs.jsonl").read_bytes() != want


def test_replay_needs_the_live_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    setup = replace(_setup(), sim=replace(_setup().sim, epochs=20))
    data = sim.generate(setup, "clean", 1)
    run_live(setup, data, tmp_path / "live", seed=1, record_dir=tmp_path / "rec")
    (cap,) = sorted((tmp_path / "rec").glob("*.cap"))
    assert main(["replay", str(cap), "--out", str(tmp_path / "re")]) == 1
    assert "give --config" in capsys.readouterr().err


def test_a_mems_gyro_does_not_gyrocompass(tmp_path: Path) -> None:
    """The filter configured for a MEMS gyro (10 deg/h: the Earth's rate is 12.5 deg/h here)
    does not take a heading from it at rest; it waits, and aligns by the GNSS course once in
    steady flight (after the take-off roll's acceleration)."""
    base = _setup()
    mems = replace(base.filter, imu=replace(base.filter.imu, gyro_bias_deg_h=10.0))
    setup = replace(base, filter=mems, sim=replace(base.sim, epochs=20, rest_s=40))
    data = sim.generate(setup, "clean", 1)
    lr = run_live(setup, data, tmp_path, seed=1)
    ins = lr.summary["ins"]
    assert ins["alignment"]["method"] == "gnss course"
    assert ins["align_wait"]["at rest, the gyro cannot gyrocompass and no ATTITUDE: heading "
                             "from the course"] > 0
    assert ins["aligned_at"] > 43200.0 - 20.0  # not before the take-off roll
    assert ins["zupts"] == 0


def test_demo_insgnss_runs_end_to_end(tmp_path: Path, capsys: pytest.CaptureFixture[str]
                                      ) -> None:
    """``fdi-bridge demo insgnss``: ptys and GPS_INPUT on 127.0.0.1, the comparison printed."""
    out = tmp_path / "demo"
    assert main(["demo", "insgnss", "--epochs", "20", "--rest", "40", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "aligned by gyrocompass" in text and "live / sim" in text
    assert "GPS_INPUT received on 127.0.0.1:" in text
    assert " 0 GPS_INPUT" not in text
    assert (out / "epochs.jsonl").read_bytes().count(b"\n") == 80
    assert main(["demo", "insgnss", "--epochs", "5", "--out", str(out)]) == 2


def test_the_imu_over_the_routers_autopilot_link(tmp_path: Path) -> None:
    """``imu_url = "router"`` with a ``[mavlink]`` router: the IMU goes as UDP datagrams on
    127.0.0.1 to the router's autopilot link, the vehicle takes it from there (no IMU port of
    its own); the same filter result as over its own pty, and the recording replays byte for
    byte (the router's packets are recorded as ``imu rx``). The router run is played at 10x
    (1000 IMU datagrams/s of wall clock, not 5000) and rests 60 s (not 40) before the 30 s
    the gyrocompass needs: with 40 s at 50x the vehicle aligned by the GNSS course in 2 of the
    4 full-suite runs of one session (a rest broken by late or lost datagrams? not reproduced: 8
    of 8 alone under load aligned at rest, one with 21 of 9900 datagrams lost)."""
    setup = replace(_setup(), sim=replace(_setup().sim, epochs=40, rest_s=60))
    data = sim.generate(setup, "paper-single", 1)
    pty = run_live(setup, data, tmp_path / "pty", seed=1)
    rt = run_live(setup, data, tmp_path / "router", seed=1, via_router=True,
                  record_dir=tmp_path / "rec", speed=10.0)
    ins = rt.summary["ins"]
    assert ins["refused"] == "" and ins["alignment"]["method"] == "gyrocompass"
    assert ins["imu"]["received"] >= 0.99 * pty.summary["ins"]["imu"]["received"]
    assert len(rt.pos_err) == len(pty.pos_err) == 39
    assert abs(rms(rt.pos_err) / rms(pty.pos_err) - 1.0) < 0.1
    (cap,) = sorted((tmp_path / "rec").glob("*.cap"))
    cfg = _replay_config(tmp_path)
    cfg.write_text(cfg.read_text(encoding="utf-8").replace('"/dev/ttyAMA1"', '"router"'),
                   encoding="utf-8")
    assert main(["replay", str(cap), "--config", str(cfg), "--out", str(tmp_path / "re")]) == 0
    assert (tmp_path / "re" / "epochs.jsonl").read_bytes() == (
        tmp_path / "router" / "epochs.jsonl").read_bytes()


def test_router_imu_without_a_router_is_refused(tmp_path: Path) -> None:
    """``imu_url = "router"`` but no ``[mavlink]``: said, in the summary, the rover detector
    alone (and no IMU port opened)."""
    base = BridgeConfig()
    setup = replace(_setup(), live=replace(_setup().live, imu_url="router"))
    with PtyPair() as gps:
        cfg = replace(base, rover=replace(base.rover, port=replace(base.rover.port, url=gps.url,
                                                                   timeout_s=0.02)))
        vehicle = InsGnssVehicle(cfg, setup)
        assert [p.name for p in vehicle.ports()] == ["gps"]
        def feed() -> None:
            for j in range(6):
                gps.write(nmea_epoch(float(j), (34.25, 8.5, 300.0), (10.0, 0.0)))
                time.sleep(0.05)  # the receiver's epochs, apart

        runner = Runner(vehicle, out_dir=tmp_path, handle_signals=False, duration_s=60.0)
        runner.start()  # the port opens before anything is sent
        thread = threading.Thread(target=feed, daemon=True)
        thread.start()
        summary = runner.run(until=lambda: not thread.is_alive() and unread(gps) == 0)
        thread.join(2.0)
    assert "needs the router" in summary["ins"]["refused"]
    assert set(summary["ins"]["epochs"]) == {"rover"} and summary["ins"]["epochs"]["rover"] >= 5


def test_heading_from_the_autopilots_attitude(tmp_path: Path) -> None:
    """``heading_source = "attitude"``: at rest the heading is the autopilot's ATTITUDE yaw
    (here 2 deg off, its compass error) with ``attitude_sigma_deg``, not the gyrocompass; the
    filter starts from it and still beats no gate by far."""
    base = _setup()
    setup = replace(base, sim=replace(base.sim, epochs=80, rest_s=40),
                    live=replace(base.live, heading_source="attitude"))
    data = sim.generate(setup, "paper-single", 2)
    lr = run_live(setup, data, tmp_path, seed=2, attitude_error_deg=2.0)
    ins = lr.summary["ins"]
    assert ins["alignment"]["method"] == "attitude"
    assert ins["alignment"]["sigma_yaw_deg"] == pytest.approx(setup.live.attitude_sigma_deg)
    first = next(r for r in lr.records if r["mode"] == "ins")
    assert first["ins"]["rpy_deg"][2] == pytest.approx(30.0 + 2.0, abs=0.5)
    none = sim.run_method(data, setup.filter, "none")
    assert len(lr.pos_err) == 79
    assert rms(lr.pos_err) < rms(none.pos_err) / 3.0
