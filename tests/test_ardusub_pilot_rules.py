"""ArduSub's rules for the pilot's MANUAL_CONTROL while the bridge steers (issue A).

A real pymavlink pilot (system 255, component 190) and a real pymavlink "autopilot" peer
(system 1, component 1: HEARTBEAT armed in ALT_HOLD, ATTITUDE) talk to the bridge's Runner and
router over UDP on 127.0.0.1. The periods run in lockstep (the autopilot reports, the pilot
sends, the bridge steps once the frames have arrived), except one real-time run; what the
autopilot receives is every MANUAL_CONTROL with all its fields and its sender's ids.

* a tap shorter than one period (press, release 50 ms later) reaches the vehicle: press, then
  release, each at once, with the bridge's yaw;
* buttons2, enabled_extensions, s, t, aux1-6 arrive unchanged (only r is the bridge's);
* the bridge's frames come from the GCS's system id (ArduSub's MAV_GCS_SYSID: GCS_MAVLINK_Sub::
  handle_message drops MANUAL_CONTROL from any other) and the bridge's own component id;
* ``send_without_pilot = false`` (the default): the bridge sends only while the pilot's
  MANUAL_CONTROL or the GCS's HEARTBEAT came within ``pilot_timeout_s``.
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import replace
from typing import Any

import numpy as np
import pytest

from drivers.mavlink import io as mio
from drivers.mavlink.modes import MODES
from firmware_host.mavlink.router import EndpointConfig, MavlinkConfig, open_router
from firmware_host.rov.ardusub import ArduSubRovVehicle
from firmware_host.rov.config import load_rov_config, project_root
from firmware_host.runtime.runner import Runner

PERIOD_S = 0.2
NEUTRAL = (0, 0, 500, 0)


def _wait(cond: Any, what: str, timeout_s: float = 3.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not cond():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.0005)


class Peers:
    """The bridge (Runner + router), a pymavlink autopilot and a pymavlink pilot."""

    def __init__(self, component_id: int = 191, **ardusub: Any) -> None:
        c, _ = load_rov_config(project_root() / "config" / "rov.toml")
        cfg = replace(c, heading_source="mavlink", ardusub=replace(c.ardusub, **ardusub))
        self.cfg = cfg
        self.compid = component_id
        mav = MavlinkConfig(autopilot=EndpointConfig("udpin:127.0.0.1:0"),
                            gcs=(EndpointConfig("udpin:127.0.0.1:0"),),
                            component_id=component_id, statustext_per_s=50.0)
        self.records: list[dict[str, Any]] = []
        self.vehicle = ArduSubRovVehicle(cfg, on_epoch=self.records.append)
        self.runner = Runner(self.vehicle, mavlink=mav, open_router=open_router,
                             handle_signals=False)
        self.runner.start()
        router = self.runner.router
        assert router is not None
        ap_port = router.endpoints[0].link.local_address[1]  # type: ignore[index]
        gcs_port = router.endpoints[1].link.local_address[1]  # type: ignore[index]
        self.ap = mio.MavEndpoint(f"udpout:127.0.0.1:{ap_port}", source_system=1,
                                  source_component=1)
        self.pilot = mio.MavEndpoint(f"udpout:127.0.0.1:{gcs_port}", source_system=255,
                                     source_component=190)
        self.got: list[Any] = []  # every MANUAL_CONTROL the autopilot received, in order
        self.texts: list[str] = []
        self._ap_lock = threading.Lock()
        self.t_ms = 0
        self.ap.send_vehicle_heartbeat(mio.MAV_TYPE_SUBMARINE, 0, 0)  # the router learns it
        _wait(lambda: self.loop.autopilot.received >= 1, "the autopilot's first HEARTBEAT")

    @property
    def loop(self) -> Any:
        assert self.vehicle.loop is not None
        return self.vehicle.loop

    def drain(self) -> int:
        """Take what reached the autopilot; the number of MANUAL_CONTROL so far."""
        with self._ap_lock:
            msg = self.ap.recv(0.0)
            while msg is not None:
                if msg.get_type() == "MANUAL_CONTROL":
                    self.got.append(msg)
                msg = self.ap.recv(0.0)
            return len(self.got)

    def wait_got(self, n: int, what: str) -> None:
        _wait(lambda: self.drain() >= n, what)

    def from_bridge(self) -> int:
        """How many of the frames the autopilot got are the bridge's (its component id)."""
        self.drain()
        return sum(1 for m in self.got if m.get_srcComponent() == self.compid)

    def report(self, armed: bool = True, mode: str = "ALT_HOLD") -> None:
        """The autopilot's 1 Hz HEARTBEAT (sent every period here) and one ATTITUDE."""
        hb, att = self.loop.autopilot.received, self.loop.heading.received
        base = mio.MAV_MODE_FLAG_SAFETY_ARMED if armed else 0
        self.ap.send_vehicle_heartbeat(mio.MAV_TYPE_SUBMARINE, base, MODES["sub"][mode])
        self.t_ms += 200
        self.ap.send_attitude(self.t_ms, 0.0, 0.0, math.radians(150.0))
        _wait(lambda: self.loop.autopilot.received > hb and self.loop.heading.received > att,
              "HEARTBEAT and ATTITUDE at the bridge")

    def send_pilot(self, axes: tuple[int, int, int, int] = NEUTRAL, buttons: int = 0,
                   ext: mio.ManualControlExt | None = None) -> None:
        """One pilot frame; returns once the router has intercepted it."""
        n = self.loop.pilot.received
        if ext is None:
            self.pilot.send_manual_control(1, *axes, buttons)
        else:
            self.pilot.send_manual_control(1, *axes, buttons, ext)
        _wait(lambda: self.loop.pilot.received > n, "the pilot's MANUAL_CONTROL")

    def gcs_heartbeat(self) -> None:
        n = self.loop.pilot.gcs_heartbeats
        self.pilot.send_heartbeat()
        _wait(lambda: self.loop.pilot.gcs_heartbeats > n, "the GCS's HEARTBEAT")

    def step(self) -> dict[str, Any]:
        """One step of the bridge; waits for its frame at the autopilot when it sent one."""
        sent, n = self.loop.sent, self.from_bridge()
        self.runner.step()
        if self.loop.sent > sent:
            _wait(lambda: self.from_bridge() > n, "the bridge's MANUAL_CONTROL")
        return self.records[-1]

    def close(self) -> dict[str, Any]:
        summary = self.runner.close()
        self.ap.close()
        self.pilot.close()
        return summary


def _steering(p: Peers, periods: int = 3) -> None:
    """The pilot present (neutral, 1 frame a period), the vehicle armed: the bridge steers."""
    for _ in range(periods):
        p.report()
        p.send_pilot()
        rec = p.step()
    assert rec["ardusub"] == "steer", rec["ardusub"]


def test_a_50_ms_tap_reaches_the_vehicle_press_then_release() -> None:
    """Four pilot frames 50 ms apart within one period, the second pressed (a 50 ms tap):
    the autopilot gets the press and then the release at once, each with the bridge's yaw and
    the pilot's axes, then the period's frame (released)."""
    p = Peers()
    try:
        _steering(p)
        n0 = p.drain()
        r_bridge = p.got[-1].r  # the yaw of the bridge's last frame
        p.report()
        axes = (120, -40, 610, 30)  # yaw within the dead band: the bridge keeps steering
        for buttons in (0, 1, 0, 0):  # frames at 0, 50, 100, 150 ms: pressed 50 ms
            p.send_pilot(axes, buttons)
        p.wait_got(n0 + 2, "the press and the release")
        rec = p.step()
        tail = p.got[n0:]
    finally:
        summary = p.close()
    assert rec["ardusub"] == "steer"
    assert [m.buttons for m in tail] == [1, 0, 0], [m.buttons for m in tail]
    press, release, period = tail
    for m in (press, release):
        assert (m.x, m.y, m.z) == axes[:3] and m.r == r_bridge  # not the pilot's r = 30
    assert period.r == rec["r_sent"] and (period.x, period.y, period.z) == axes[:3]
    assert summary["button_edges_sent"] == 2


def test_a_press_during_the_step_is_not_undone() -> None:
    """A press that arrives while the bridge computes a period (after it took the period's
    frames, before it sends): the press goes on at once, and the period's frame carries it
    too, not the released buttons of the frames it took (which would be a release and then a
    second press at ArduSub). The arrival is placed there by taking the inbox, then sending."""
    p = Peers()
    try:
        _steering(p)
        p.report()
        p.send_pilot()
        take = p.loop.inbox.take

        def take_then_press() -> list[bytes]:
            frames = take()  # the step has its frames; the pilot presses now
            p.send_pilot(buttons=4)
            return frames

        p.loop.inbox.take = take_then_press
        n0 = p.drain()
        rec = p.step()
        p.loop.inbox.take = take
        p.wait_got(n0 + 2, "the press and the period's frame")
        p.report()
        p.send_pilot(buttons=4)
        p.step()
        tail = [m.buttons for m in p.got[n0:]]
    finally:
        p.close()
    assert rec["ardusub"] == "steer"
    assert tail == [4, 4, 4], tail  # press (at once), the period's frame, the next one


def test_every_edge_arrives_in_order_in_real_time() -> None:
    """Real time (the Runner paces 5 Hz; the pilot sends at 50 Hz in its own thread, seeded
    taps of 1-3 frames on buttons and buttons2): the button states the vehicle gets, with
    repeats collapsed, are exactly the pilot's, in order; no frame of a period undoes an edge
    sent a moment before it (the bridge's 5 Hz frames and the edges cross in time)."""
    p = Peers(send_without_pilot=True)
    rng = np.random.default_rng(41)
    pattern: list[tuple[int, int]] = []
    while len(pattern) < 150:  # 3 s at 50 Hz
        held = int(rng.integers(2, 8))
        pattern += [(0, 0)] * held
        press = (int(rng.integers(1, 1 << 16)), int(rng.integers(0, 4)))
        pattern += [press] * int(rng.integers(1, 4))
    pattern += [(0, 0)] * 10
    stop = threading.Event()

    def collapse(seq: list[tuple[int, int]]) -> list[tuple[int, int]]:
        return [s for i, s in enumerate(seq) if i == 0 or s != seq[i - 1]]

    def wire() -> list[tuple[int, int]]:
        """The button states the vehicle got, repeats collapsed."""
        p.drain()
        return collapse([(int(m.buttons), int(m.buttons2)) for m in list(p.got)])

    def autopilot() -> None:
        nxt = time.monotonic()
        while not stop.is_set():
            base = mio.MAV_MODE_FLAG_SAFETY_ARMED
            p.ap.send_vehicle_heartbeat(mio.MAV_TYPE_SUBMARINE, base, MODES["sub"]["ALT_HOLD"])
            p.t_ms += 100
            p.ap.send_attitude(p.t_ms, 0.0, 0.0, math.radians(150.0))
            p.drain()
            nxt += 0.1
            stop.wait(max(0.0, nxt - time.monotonic()))

    def pilot() -> None:
        nxt = time.monotonic()
        for b, b2 in pattern:
            p.pilot.send_manual_control(1, *NEUTRAL, b, mio.ManualControlExt(buttons2=b2))
            nxt += 0.02
            stop.wait(max(0.0, nxt - time.monotonic()))

    ap = threading.Thread(target=autopilot, daemon=True)
    pl = threading.Thread(target=pilot, daemon=True)
    ap.start()
    try:
        _wait(lambda: p.loop.heading.received > 0, "ATTITUDE")
        pl.start()

        def done() -> bool:  # every pilot frame handled and its last edge at the vehicle
            return (not pl.is_alive() and p.loop.pilot.received == len(pattern)
                    and wire() == collapse(pattern))

        summary = p.runner.run(max_steps=60, until=done)  # paced 5 Hz; closes the runner
    finally:
        stop.set()
        ap.join(2.0)
        pl.join(2.0)
    got = wire()
    p.ap.close()
    p.pilot.close()
    assert got == collapse(pattern), (len(got), len(collapse(pattern)))
    assert summary["ardusub_states"].get("steer", 0) >= 10
    edges = summary["button_edges_sent"]
    assert edges >= 0.5 * (len(collapse(pattern)) - 1), edges  # most sent at once, by edge


def test_extensions_and_axes_arrive_unchanged_only_r_is_the_bridges() -> None:
    p = Peers()
    ext = mio.ManualControlExt(buttons2=0x0105, enabled_extensions=0xFF, s=-300, t=250,
                               aux=(1, -2, 300, -400, 500, -1000))
    axes = (250, -120, 700, 40)
    try:
        _steering(p)
        for _ in range(3):
            p.report()
            n0 = p.drain()
            p.send_pilot(axes, 0x0021, ext)
            rec = p.step()
        last = p.got[-1]
        frames = p.got[n0:]
    finally:
        p.close()
    assert rec["ardusub"] == "steer" and len(frames) == 1
    assert (last.x, last.y, last.z, last.buttons) == (*axes[:3], 0x0021)
    assert mio.ManualControlExt.of(last) == ext
    assert last.r == rec["r_sent"] != axes[3]


def test_the_bridge_sends_from_the_gcs_id_and_its_own_component() -> None:
    """ArduSub (GCS_MAVLINK_Sub::handle_message, MANUAL_CONTROL) takes pilot input only from
    MAV_GCS_SYSID (GCS::sysid_is_gcs), whatever the component: the bridge's frames carry the
    GCS's system id and the bridge's [mavlink] component_id, not the pilot's 255/190."""
    p = Peers(component_id=197)
    try:
        _steering(p)
    finally:
        p.close()
    ids = {(m.get_srcSystem(), m.get_srcComponent()) for m in p.got}
    assert ids == {(255, 190), (255, 197)}  # the pilot's frame before steering, then the bridge's
    assert (p.got[-1].get_srcSystem(), p.got[-1].get_srcComponent()) == (255, 197)


def test_without_a_pilot_or_ground_station_the_bridge_does_not_send() -> None:
    p = Peers()
    try:
        alone = []
        for _ in range(5):
            p.report()
            alone.append(p.step())
        got_alone = p.drain()
        p.gcs_heartbeat()  # the ground station (no joystick): present for pilot_timeout_s
        with_gcs = []
        for _ in range(8):
            p.report()
            with_gcs.append(p.step())
        n_sent = p.loop.sent
    finally:
        summary = p.close()
    assert {r["ardusub"] for r in alone} == {"no_pilot"} and got_alone == 0
    states = [r["ardusub"] for r in with_gcs]
    assert states == ["steer"] * 6 + ["no_pilot"] * 2, states  # 1 s: the heartbeat's age
    assert n_sent == 6 and len(p.got) == 6
    assert summary["gcs_heartbeats_received"] >= 1
    assert summary["ardusub_states"]["no_pilot"] == 7


def test_send_without_pilot_steers_unattended() -> None:
    p = Peers(send_without_pilot=True)
    try:
        recs = []
        for _ in range(5):
            p.report()
            recs.append(p.step())
    finally:
        p.close()
    assert [r["ardusub"] for r in recs] == ["steer"] * 5
    assert len(p.got) >= 4 and {m.buttons for m in p.got} == {0}


@pytest.mark.parametrize("text, found", [
    ("send_without_pilot = 1\n", "rov.ardusub.send_without_pilot"),
])
def test_send_without_pilot_is_checked_at_load(tmp_path: Any, text: str, found: str) -> None:
    from fdi.errors import ConfigError
    from firmware_host.runtime.config import load_bridge_file

    f = tmp_path / "bad.toml"
    f.write_text("[rov.ardusub]\n" + text)
    with pytest.raises(ConfigError) as exc:
        load_bridge_file(f)
    assert found in str(exc.value) and "true or false" in str(exc.value)
