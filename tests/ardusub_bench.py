"""The bench of the ArduSub ROV tests: the bridge (Runner + router), the simulated ArduSub
(:mod:`firmware_host.devtools.ardusub_sim`) and a pilot's ground station, over UDP on
127.0.0.1, stepped in lockstep (the sim advances 0.2 s, the bridge's Runner takes one step once
the packets have arrived: real sockets, no wall-clock pacing)."""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path
from typing import Any

from drivers.mavlink import io as mio
from firmware_host.devtools.ardusub_sim import ArduSubSim
from firmware_host.devtools.rov_sim import parse_fault
from firmware_host.mavlink.router import EndpointConfig, MavlinkConfig, open_router
from firmware_host.rov.ardusub import ArduSubRovVehicle
from firmware_host.rov.config import RovConfig
from firmware_host.runtime.recorder import FlightRecorder
from firmware_host.runtime.runner import Runner

SETPOINT = 150.0
BOUND_DEG = 1.5  # tests/test_rov_experiment.py: the Outland path's bound after confirmation


def err(h: float, setpoint: float = SETPOINT) -> float:
    return (h - setpoint + 180.0) % 360.0 - 180.0


def _wait(cond: Any, what: str, timeout_s: float = 3.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not cond():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.0005)


class Bench:
    """The bridge (Runner + router), the simulated ArduSub and a pilot's ground station."""

    def __init__(self, cfg: RovConfig, faults: tuple[str, ...] = (), *, pilot: bool = False,
                 pilot_system_id: int = 255, seed: int = 1, ft: bool = True,
                 sim: dict[str, Any] | None = None, recorder: FlightRecorder | None = None,
                 out_dir: Path | None = None) -> None:
        mav = MavlinkConfig(autopilot=EndpointConfig("udpin:127.0.0.1:0"),
                            gcs=(EndpointConfig("udpin:127.0.0.1:0"),),
                            pilot_system_id=pilot_system_id, statustext_per_s=50.0)
        self.records: list[dict[str, Any]] = []
        self.cfg = cfg
        self.vehicle = ArduSubRovVehicle(cfg, ft=ft, on_epoch=self.records.append)
        self.runner = Runner(self.vehicle, mavlink=mav, open_router=open_router,
                             handle_signals=False, recorder=recorder,
                             out_dir=out_dir)
        self.runner.start()
        assert self.runner.router is not None
        ap_port = self.runner.router.endpoints[0].link.local_address[1]  # type: ignore[index]
        gcs_port = self.runner.router.endpoints[1].link.local_address[1]  # type: ignore[index]
        self.sim = ArduSubSim(f"udpout:127.0.0.1:{ap_port}", replace(cfg.sim, seed=seed),
                              [parse_fault(f) for f in faults], **(sim or {}))
        self.gcs = mio.MavEndpoint(f"udpout:127.0.0.1:{gcs_port}", source_system=255,
                                   source_component=190)
        self.gcs.send_heartbeat()  # the router learns the ground station
        # The ground station's 1 Hz HEARTBEAT, every 5 periods (0: none); it counts as the
        # pilot's presence only with the bridge's pilot_system_id (255, as this GCS's).
        self.gcs_heartbeat_every = 5 if pilot_system_id == 255 else 0
        self.periods = 0
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
                  and loop.autopilot.received >= sim.counters.heartbeat_sent
                  and (loop.compass is None or loop.compass.received >= sim.counters.imu_sent),
                  "ATTITUDE")
        every = self.gcs_heartbeat_every
        if every and self.periods % every == 0:  # the bridge sends only with a GCS or pilot
            n = loop.pilot.gcs_heartbeats
            self.gcs.send_heartbeat()
            _wait(lambda: loop.pilot.gcs_heartbeats > n, "the ground station's HEARTBEAT")
        self.periods += 1
        if pilot_axes is not None:
            n = loop.pilot.received
            self.gcs.send_manual_control(1, *pilot_axes)
            _wait(lambda: loop.pilot.received > n, "the pilot's MANUAL_CONTROL")
        sent = loop.sent
        got = self._got()
        self.runner.step()
        if loop.sent > sent and not sim.unplugged:
            _wait(lambda: (sim.pump(), self._got() > got)[1],
                  "the bridge's MANUAL_CONTROL")
        elif pilot_axes is not None and abs(pilot_axes[3]) > self.cfg.ardusub.yaw_dead_band:
            _wait(lambda: (sim.pump(), self._got() > got)[1],
                  "the pilot's MANUAL_CONTROL, forwarded")
        self._drain_gcs()
        self.true.append(sim.plant.heading_true)
        return self.records[-1]

    def _got(self) -> int:
        c = self.sim.counters
        return c.accepted + c.refused + c.rc_accepted + c.rc_refused

    def close(self) -> dict[str, Any]:
        time.sleep(0.3)
        self._drain_gcs()
        summary = self.runner.close()
        self.sim.close()
        self.gcs.close()
        return summary
