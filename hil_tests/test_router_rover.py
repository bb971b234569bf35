"""The rover pipeline behind the MAVLink router, over real loopback UDP and a real pty.

A generated capture is replayed through a pty into the rover pipeline, whose outputs go through
the router (one process): a pymavlink autopilot stand-in receives GPS_INPUT at the GPS rate with
the corrected positions and raised accuracy on replaced fixes, STATUSTEXT and HOLD on the alarm;
a pymavlink ground station receives the detector statistics as NAMED_VALUE_FLOAT at the
configured rate and tunes the detector over the parameter protocol.
"""

from __future__ import annotations

import io
import json
import math
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from drivers.mavlink import io as mio
from firmware_host.commands.replay import load_input, replay_through_pty
from firmware_host.devtools.rover_sim import RoverScenario, write_run
from firmware_host.mavlink.router import EndpointConfig, MavlinkConfig, Router
from firmware_host.rover.mavlink import STAT_NAMES, LiveRoverIsolator, attach_rover
from firmware_host.rover.outputs import gps_week_ms, unix_time
from firmware_host.rover.pipeline import RoverPipeline
from firmware_host.runtime.config import RoverConfig


def _wait(cond: Callable[[], bool], what: str, deadline_s: float = 10.0) -> None:
    end = time.monotonic() + deadline_s
    while not cond():
        if time.monotonic() > end:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.001)  # polling a receiver thread, bounded by the deadline


class _Station(threading.Thread):
    """A pymavlink peer that records every message it receives, with its arrival time."""

    def __init__(self, port: int, sysid: int, compid: int) -> None:
        super().__init__(daemon=True)
        self.ep = mio.MavEndpoint(
            f"udpout:127.0.0.1:{port}", source_system=sysid, source_component=compid
        )
        self.msgs: list[tuple[float, Any]] = []
        self.halt = threading.Event()

    def run(self) -> None:
        while not self.halt.is_set():
            msg = self.ep.recv(0.05)
            if msg is not None:
                self.msgs.append((time.monotonic(), msg))

    def of(self, kind: str) -> list[Any]:
        return [m for _, m in list(self.msgs) if m.get_type() == kind]

    def times(self, kind: str) -> list[float]:
        return [t for t, m in list(self.msgs) if m.get_type() == kind]

    def close(self) -> None:
        self.halt.set()
        self.join(timeout=2.0)
        self.ep.close()


def _setup(stats_hz: float) -> tuple[Router, _Station, _Station]:
    cfg = MavlinkConfig(
        autopilot=EndpointConfig("udpin:127.0.0.1:0"),
        gcs=(EndpointConfig("udpin:127.0.0.1:0"),),
        stats_hz=stats_hz,
        statustext_per_s=20.0,
    )
    router = Router(cfg)
    router.start()
    ports = [ep.link.local_address[1] for ep in router.endpoints]  # type: ignore[index]
    autopilot = _Station(ports[0], 1, 1)
    gcs = _Station(ports[1], 255, 190)
    for st in (autopilot, gcs):
        st.start()
        st.ep.send_heartbeat()  # the router learns both peers and their system ids
    _wait(lambda: all(ep.link.has_peer() for ep in router.endpoints), "both peers")
    return router, autopilot, gcs


def _replay(
    tmp_path: Path,
    sc: RoverScenario,
    router: Router,
    speed: float,
    before: Callable[[], None] = lambda: None,
) -> tuple[RoverPipeline, list[dict[str, Any]], float]:
    write_run(sc, tmp_path / "run")
    jsonl = io.StringIO()
    pipeline = RoverPipeline(RoverConfig(), jsonl=jsonl)
    attach_rover(pipeline, router)
    before()
    t0 = time.monotonic()
    replay_through_pty(load_input(tmp_path / "run" / "rover.nmea"), pipeline, speed=speed)
    wall = time.monotonic() - t0
    epochs = [json.loads(x) for x in jsonl.getvalue().splitlines() if x]
    return pipeline, epochs, wall


def test_gps_input_through_the_router_at_the_gps_rate(tmp_path: Path) -> None:
    rate_hz, speed, stats_hz = 5.0, 20.0, 10.0
    sc = RoverScenario(rate_hz=rate_hz, duration_s=60.0, seed=3)
    router, autopilot, gcs = _setup(stats_hz)
    try:

        def tune() -> None:  # from the ground station, before the run: an 8-epoch window
            gcs.ep.send_param_set(1, 191, "FDI_WINDOW", 8.0)
            _wait(lambda: any(m.param_id == "FDI_WINDOW" for m in gcs.of("PARAM_VALUE")),
                  "the PARAM_VALUE answer")  # fmt: skip

        pipeline, epochs, wall = _replay(tmp_path, sc, router, speed, tune)
        n = len(epochs)
        _wait(lambda: len(autopilot.of("GPS_INPUT")) >= n, f"{n} GPS_INPUT at the autopilot")
        _wait(lambda: len(gcs.of("NAMED_VALUE_FLOAT")) >= 6, "statistics at the GCS")
    finally:
        router.close()
        autopilot.close()
        gcs.close()
    assert n == 300
    gps = autopilot.of("GPS_INPUT")
    assert len(gps) == n  # one per epoch, nothing lost or duplicated
    # At the GPS rate: fix times 1 / rate apart, and arrivals paced with the receiver.
    t_fix = np.array([m.time_usec for m in gps], dtype=np.int64)
    assert set(np.diff(t_fix).tolist()) == {round(1e6 / rate_hz)}
    arrivals = np.diff(autopilot.times("GPS_INPUT"))
    assert abs(float(np.median(arrivals)) - 1.0 / (rate_hz * speed)) < 0.3 / (rate_hz * speed)
    # The corrected positions, with the accuracy raised (x3, the configured factor) on
    # replaced fixes: without GST, h_acc = σ √2 max(1, HDOP), σ = 0.35 m.
    replaced = 0
    for e, m in zip(epochs, gps, strict=True):
        week, ms = gps_week_ms(unix_time(RoverScenario().date, e["utc"]))
        assert (m.time_week, m.time_week_ms) == (week, ms)
        assert (m.lat, m.lon) == (round(e["lat"] * 1e7), round(e["lon"] * 1e7))
        assert m.get_srcSystem() == 1 and m.get_srcComponent() == 191
        h_acc = 0.35 * math.sqrt(2.0) * max(1.0, e["hdop"])
        if e["action"] == "accept":
            assert m.fix_type == 4
        else:
            assert e["action"] == "replace" and m.fix_type == 3
            assert (e["lat"], e["lon"]) != (e["raw_lat"], e["raw_lon"])
            h_acc *= 3.0
            replaced += 1
        assert math.isclose(m.horiz_accuracy, h_acc, rel_tol=1e-6)
        assert math.isclose(m.speed_accuracy, 0.3 if e["action"] != "accept" else 0.1,
                            rel_tol=1e-6)  # fmt: skip
    assert replaced >= 3
    # The detector ran with the ground station's window from its first epoch.
    assert isinstance(pipeline.isolator, LiveRoverIsolator)
    assert pipeline.isolator.p.window == 8 and pipeline.isolator.changes_applied == 1
    # Statistics at the configured rate, never to the autopilot... (they go to every link;
    # the autopilot ignores them), with values that say what the detector saw.
    nvf = gcs.of("NAMED_VALUE_FLOAT")
    names = {m.name for m in nvf}
    assert names == set(STAT_NAMES)
    per_name = len([m for m in nvf if m.name == "GPS_FAULT"])
    assert abs(per_name - stats_hz * wall) <= 0.25 * stats_hz * wall + 2
    for m in nvf:
        assert math.isfinite(m.value)
        if m.name in ("GPS_FAULT", "GPS_ALARM"):
            assert m.value in (0.0, 1.0)
    t_boot = [m.time_boot_ms for m in nvf if m.name == "GPS_FAULT"]
    assert np.all(np.diff(t_boot) > 0)


def test_alarm_statustext_and_hold_through_the_router(tmp_path: Path) -> None:
    sc = RoverScenario(rate_hz=5.0, duration_s=150.0, seed=6, kinds=("frozen",),
                       frozen_s=20.0, fault_every_s=60.0)  # fmt: skip
    router, autopilot, gcs = _setup(0.0)
    try:
        _, epochs, _ = _replay(tmp_path, sc, router, speed=100.0)
        n = len(epochs)
        _wait(lambda: len(autopilot.of("GPS_INPUT")) >= n, f"{n} GPS_INPUT at the autopilot")
        _wait(lambda: any("cleared" in m.text for m in gcs.of("STATUSTEXT")), "recovery text")
    finally:
        router.close()
        autopilot.close()
        gcs.close()
    assert any(e["alarm_raised"] for e in epochs)
    texts = gcs.of("STATUSTEXT")
    assert any(m.severity == 2 and "auto-nav stop" in m.text for m in texts)
    assert any(m.severity == 5 and "alarm cleared" in m.text for m in texts)
    cmds = autopilot.of("COMMAND_LONG")
    assert cmds and (cmds[0].command, cmds[0].param2) == (176, 4)  # DO_SET_MODE, Rover HOLD
    assert (cmds[0].target_system, cmds[0].target_component) == (1, 1)
    assert not gcs.of("COMMAND_LONG")  # addressed to the autopilot only
    for e, m in zip(epochs, autopilot.of("GPS_INPUT"), strict=True):
        if e["action"] == "alarm":
            assert m.fix_type <= 1 and m.lat == 0
