"""The ROV through an ArduSub autopilot, end to end over UDP on 127.0.0.1.

The simulated ArduSub (:mod:`firmware_host.devtools.ardusub_sim`: the ROV plant of
``rov_sim``, ATTITUDE at 10 Hz, HEARTBEAT with armed/mode, MANUAL_CONTROL only from the GCS id)
talks to the bridge's router; a pymavlink ground station plays the pilot. The long scenarios run
in lockstep (the sim advances 0.2 s, the bridge's Runner takes one step once the packets have
arrived: real sockets, no wall-clock pacing); one short run is in real time.
"""

from __future__ import annotations

import threading
import time
from dataclasses import replace
from typing import Any

import pytest

from drivers.mavlink import io as mio
from firmware_host.devtools.ardusub_sim import ArduSubSim
from firmware_host.devtools.rov_sim import parse_fault
from firmware_host.mavlink.router import EndpointConfig, MavlinkConfig
from firmware_host.rov.ardusub import ArduSubRovVehicle
from firmware_host.rov.config import RovConfig, load_rov_config, project_root
from firmware_host.runtime.runner import Runner

SETPOINT = 150.0
BOUND_DEG = 1.5  # tests/test_rov_experiment.py: the Outland path's bound after confirmation


def _wait(cond: Any, what: str, timeout_s: float = 3.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not cond():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.0005)


class Bench:
    """The bridge (Runner + router), the simulated ArduSub and a pilot's ground station."""

    def __init__(self, cfg: RovConfig, faults: tuple[str, ...] = (), *, pilot: bool = False,
                 pilot_system_id: int = 255, seed: int = 1, ft: bool = True) -> None:
        mav = MavlinkConfig(autopilot=EndpointConfig("udpin:127.0.0.1:0"),
                            gcs=(EndpointConfig("udpin:127.0.0.1:0"),),
                            pilot_system_id=pilot_system_id, statustext_per_s=50.0)
        self.records: list[dict[str, Any]] = []
        self.cfg = cfg
        self.vehicle = ArduSubRovVehicle(cfg, ft=ft, on_epoch=self.records.append)
        self.runner = Runner(self.vehicle, mavlink=mav, handle_signals=False)
        self.runner.start()
        assert self.runner.router is not None
        ap_port = self.runner.router.endpoints[0].link.local_address[1]  # type: ignore[index]
        gcs_port = self.runner.router.endpoints[1].link.local_address[1]  # type: ignore[index]
        self.sim = ArduSubSim(f"udpout:127.0.0.1:{ap_port}", replace(cfg.sim, seed=seed),
                              [parse_fault(f) for f in faults])
        self.gcs = mio.MavEndpoint(f"udpout:127.0.0.1:{gcs_port}", source_system=255,
                                   source_component=190)
        self.gcs.send_heartbeat()  # the router learns the ground station
        self.pilot = pilot
        self.texts: list[str] = []
        self.true: list[float] = []

    @property
    def loop(self) -> Any:
        assert self.vehicle.loop is not None
        return self.vehicle.loop

    def _drain_gcs(self) -> None:
        msg = self.gcs.recv(0.0)
        while msg is not None:
            if msg.get_type() == "STATUSTEXT":
                self.texts.append(str(msg.text))
            msg = self.gcs.recv(0.0)

    def period(self, pilot_axes: tuple[int, int, int, int] | None = None) -> dict[str, Any]:
        """0.2 s: the sim advances (2 ATTITUDE), the pilot sends, the bridge steps, the sim
        takes the command."""
        sim, loop = self.sim, self.loop
        sim.step(0.1)
        sim.step(0.1)
        if not sim.unplugged:
            _wait(lambda: loop.heading.received >= sim.counters.attitude_sent
                  and loop.autopilot.received >= sim.counters.heartbeat_sent, "ATTITUDE")
        if pilot_axes is not None:
            n = loop.pilot.received
            self.gcs.send_manual_control(1, *pilot_axes)
            _wait(lambda: loop.pilot.received > n, "the pilot's MANUAL_CONTROL")
        sent = loop.sent
        got = sim.counters.accepted + sim.counters.refused
        self.runner.step()
        if loop.sent > sent and not sim.unplugged:
            _wait(lambda: (sim.pump(), sim.counters.accepted + sim.counters.refused > got)[1],
                  "the bridge's MANUAL_CONTROL")
        elif pilot_axes is not None and abs(pilot_axes[3]) > self.cfg.ardusub.yaw_dead_band:
            _wait(lambda: (sim.pump(), sim.counters.accepted + sim.counters.refused > got)[1],
                  "the pilot's MANUAL_CONTROL, forwarded")
        self._drain_gcs()
        self.true.append(sim.plant.heading_true)
        return self.records[-1]

    def close(self) -> dict[str, Any]:
        time.sleep(0.3)
        self._drain_gcs()
        summary = self.runner.close()
        self.sim.close()
        self.gcs.close()
        return summary


@pytest.fixture
def cfg() -> RovConfig:
    c, _ = load_rov_config(project_root() / "config" / "rov.toml")
    return replace(c, heading_source="mavlink")


def err(h: float) -> float:
    return (h - SETPOINT + 180.0) % 360.0 - 180.0


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
    # A bridge whose pilot id is not ArduSub's SYSID_MYGCS: everything it sends is refused.
    b2 = Bench(cfg, pilot_system_id=42)
    try:
        for _ in range(3 * 5):
            b2.period()
    finally:
        b2.close()
    assert b2.sim.counters.accepted == 0 and b2.sim.counters.refused >= 10


def test_real_time_run_through_the_runner(cfg: RovConfig) -> None:
    """A short real-time run (3 s): the sim serves in its own thread, Runner.run paces."""
    b = Bench(replace(cfg, setpoint_deg=110.0))  # the plant starts at 110 deg
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
