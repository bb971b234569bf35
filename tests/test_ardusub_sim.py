"""The ROV through an ArduSub autopilot, end to end over UDP on 127.0.0.1.

The simulated ArduSub (:mod:`firmware_host.devtools.ardusub_sim`: the ROV plant of
``rov_sim``, ATTITUDE at 10 Hz, HEARTBEAT with armed/mode, MANUAL_CONTROL only from the GCS id)
talks to the bridge's router; a pymavlink ground station plays the pilot. The long scenarios run
in lockstep (the sim advances 0.2 s, the bridge's Runner takes one step once the packets have
arrived: real sockets, no wall-clock pacing); one short run is in real time.
"""

from __future__ import annotations

import threading
from dataclasses import replace

import pytest

from firmware_host.rov.config import RovConfig, load_rov_config, project_root
from tests.ardusub_bench import BOUND_DEG, Bench, _wait, err


@pytest.fixture
def cfg() -> RovConfig:
    c, _ = load_rov_config(project_root() / "config" / "rov.toml")
    return replace(c, heading_source="mavlink", ardusub=replace(c.ardusub, gyro="none"))


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_drift_30_at_70_s_confirmed_and_heading_held(cfg: RovConfig, seed: int) -> None:
    b = Bench(cfg, ("drift:30@70",), seed=seed)
    try:
        recs = [b.period() for _ in range(130 * 5)]
    finally:
        summary = b.close()
    t_of = [round((k + 1) * 0.2, 3) for k in range(len(recs))]  # sim time at each step
    events = [(t, r["event"]) for t, r in zip(t_of, recs, strict=True) if r["event"]]
    assert all(t >= 70.0 for t, _ in events), events  # nothing before the fault
    t_sus = next(t for t, e in events if e == "suspect")
    t_conf = next(t for t, e in events if e == "confirmed")
    assert 70.0 <= t_sus <= 70.4 and 0 < t_conf - t_sus <= 5 * 0.2 + 1e-9, events
    after = [abs(err(h)) for t, h in zip(t_of, b.true, strict=True) if t >= t_conf]
    assert max(after) < BOUND_DEG, max(after)
    before = [abs(err(h)) for t, h in zip(t_of, b.true, strict=True) if 40.0 <= t < 70.0]
    assert max(before) < BOUND_DEG
    assert summary["ardusub_states"] == {"steer": len(recs)}
    assert b.sim.counters.refused == 0 and b.sim.counters.failsafes == 0
    assert any("fault confirmed" in t for t in b.texts), b.texts


def test_without_ft_the_drift_is_followed(cfg: RovConfig) -> None:
    """The same run with substitution off: the hold follows the drifted compass (the bound
    above is not met by doing nothing)."""
    b = Bench(cfg, ("drift:30@70",), ft=False)
    try:
        for _ in range(110 * 5):
            b.period()
    finally:
        b.close()
    tail = [err(h) for h in b.true[-50:]]
    assert sum(tail) / len(tail) == pytest.approx(-30.0, abs=1.5)


def test_unplugged_5_s_hold_then_neutral_then_recovery(cfg: RovConfig) -> None:
    b = Bench(cfg)
    try:
        recs = [b.period() for _ in range(40 * 5)]
        b.sim.unplugged = True
        cut = [b.period() for _ in range(5 * 5)]
        b.sim.unplugged = False
        back = [b.period() for _ in range(20 * 5)]
    finally:
        b.close()
    assert all(r["action"] == "control" for r in recs[-50:])
    actions = [r["action"] for r in cut]
    n_hold = actions.count("hold")
    assert actions[:n_hold] == ["hold"] * n_hold and 4 <= n_hold <= 6  # dropout_hold_s = 1 s
    assert set(actions[n_hold:]) == {"neutral"}
    sent = [r["r_sent"] for r in cut if r["r_sent"] is not None]
    assert len(set(sent[:n_hold])) == 1 and sent[n_hold] == 0 and set(sent[n_hold:]) == {0}
    assert 14 <= len(sent) <= 16  # heartbeat_timeout_s = 3 s: then not sending at all
    assert cut[-1]["ardusub"] == "no_heartbeat"
    assert back[0]["action"] == "control"  # the first ATTITUDE: the hold resumes
    steer_again = next(i for i, r in enumerate(back) if r["ardusub"] == "steer")
    assert steer_again <= 6  # with the next 1 Hz HEARTBEAT
    assert max(abs(err(h)) for h in b.true[-25:]) < BOUND_DEG  # held again
    said = " | ".join(b.texts)
    for text in ("holding last command", "neutral thrust", "telemetry back",
                 "no autopilot heartbeat", "steering yaw"):
        assert text in said, said


def test_pilot_yaw_takes_over_and_hands_back(cfg: RovConfig) -> None:
    b = Bench(cfg)
    try:
        for _ in range(30 * 5):
            b.period((300, -50, 600, 0))  # forward, a little left, a little up; yaw centred
        axes = b.sim.last_axes
        sent_before = b.loop.sent
        # While the bridge steers, the pilot's own frames are not forwarded (one stream).
        pilot_forwarded = b.sim.counters.accepted - sent_before
        turn = [b.period((300, -50, 600, 600)) for _ in range(3 * 5)]
        sent_during = b.loop.sent - sent_before
        centred = [b.period((300, -50, 600, 0)) for _ in range(4 * 5)]
    finally:
        summary = b.close()
    assert axes is not None and axes[:3] == (300, -50, 600)  # the pilot's axes, unchanged
    assert pilot_forwarded == 1, pilot_forwarded  # the first, before the first step decided
    assert all(r["ardusub"] == "pilot" for r in turn) and sent_during == 0
    assert b.sim.last_axes is not None
    assert any(r == 600 for _, r in b.sim.counters.r_log)  # the pilot's yaw reached ArduSub
    n_pilot = [r["ardusub"] for r in centred].count("pilot")
    assert 9 <= n_pilot <= 11  # pilot_release_s = 2 s centred, then the bridge holds again
    assert centred[-1]["ardusub"] == "steer"
    held = centred[-1]["setpoint"]
    assert abs(err(held)) > 5.0  # the heading the pilot left, not the configured one
    assert summary["pilot_takeovers"] == 1
    assert any("pilot yaw" in t for t in b.texts)


def test_other_modes_disarmed_and_a_foreign_gcs_id_are_not_commanded(cfg: RovConfig) -> None:
    b = Bench(cfg)
    try:
        for _ in range(5 * 5):
            b.period()
        b.sim.set_mode("AUTO")
        auto = [b.period() for _ in range(2 * 5)]
        b.sim.set_mode("ALT_HOLD", armed=False)
        disarmed = [b.period() for _ in range(2 * 5)]
    finally:
        b.close()
    assert all(r["r_sent"] is None for r in auto[5:] + disarmed[5:])
    assert auto[-1]["ardusub"] == "mode" and disarmed[-1]["ardusub"] == "disarmed"
    assert sum("mode AUTO not steered" in t for t in b.texts) == 1  # said once
    # A bridge whose pilot id is not ArduSub's MAV_GCS_SYSID: everything it sends is refused
    # (it sends with no ground station of id 42 present: send_without_pilot).
    b2 = Bench(replace(cfg, ardusub=replace(cfg.ardusub, send_without_pilot=True)),
               pilot_system_id=42)
    try:
        for _ in range(3 * 5):
            b2.period()
    finally:
        b2.close()
    assert b2.sim.counters.accepted == 0 and b2.sim.counters.refused >= 10


def test_real_time_run_through_the_runner(cfg: RovConfig) -> None:
    """A short real-time run (3 s): the sim serves in its own thread, Runner.run paces."""
    b = Bench(replace(cfg, setpoint_deg=110.0,  # the plant starts at 110 deg; unattended
                      ardusub=replace(cfg.ardusub, send_without_pilot=True)))
    stop = threading.Event()
    th = threading.Thread(target=b.sim.serve, args=(stop,), daemon=True)
    th.start()
    try:
        _wait(lambda: b.loop.heading.received > 0, "ATTITUDE", 3.0)
        summary = b.runner.run(max_steps=15)
    finally:
        stop.set()
        th.join(2.0)
        b.close()
    assert summary["steps"] >= 15 and summary["attitude_received"] >= 20
    assert b.sim.counters.accepted >= 10 and b.sim.counters.refused == 0
