"""The one runtime, driven by a FakeClock (no wall-clock waits) unless a real peer is needed.

Pacing (period on absolute deadlines; data as it arrives), ``--duration``, SIGTERM (a real
signal to this process), the summary and ``epochs.jsonl``, ports reopened with the vehicle's
backoff cap (the rover's ``reconnect_max_s``, with and without a router), recorder taps on every
port direction and on the MAVLink output, shutdown sending nothing stale, and the ArduSub ROV
on a router over UDP on 127.0.0.1.
"""

from __future__ import annotations

import itertools
import json
import math
import os
import signal
import threading
import time
from dataclasses import replace
from pathlib import Path
from typing import Any, Literal

import pytest

from drivers.capture import CaptureReader
from drivers.mavlink import io as mio
from drivers.transport import SerialSettings
from fdi.errors import ConfigError, PortError
from firmware_host.devtools.rover_sim import RoverScenario, generate
from firmware_host.devtools.soak import SimDevice, sim_opener
from firmware_host.mavlink.router import EndpointConfig, MavlinkConfig, open_router
from firmware_host.rov.ardusub import ArduSubRovVehicle
from firmware_host.rov.config import RovConfig
from firmware_host.rover.vehicle import RoverVehicle
from firmware_host.runtime.config import BridgeConfig, RoverConfig
from firmware_host.runtime.config_rov import ArduSubConfig
from firmware_host.runtime.loop import FakeClock
from firmware_host.runtime.mavout import EncoderOutput, packer_output
from firmware_host.runtime.recorder import FlightRecorder, RecorderConfig
from firmware_host.runtime.runner import Runner
from firmware_host.runtime.vehicle import Context, MavlinkSpec, PortSpec


class Ticker:
    """A minimal period-paced vehicle: one record per step, with the deadline it ran at."""

    name = "ticker"
    pacing: Literal["period"] = "period"

    def __init__(self, period_s: float = 0.2, on_step: Any = None) -> None:
        self.period_s = period_s
        self.on_step = on_step
        self.times: list[float] = []
        self.checks = 0
        self.finished = False
        self.ctx: Context | None = None

    def ports(self) -> list[PortSpec]:
        return []

    def mavlink(self) -> MavlinkSpec | None:
        return None

    def outputs(self) -> tuple[str, ...]:
        return ()

    def status_fields(self) -> dict[str, Any]:
        return {}

    def status_detail(self) -> tuple[str, ...]:
        return ()

    def start(self, ctx: Context) -> None:
        self.ctx = ctx

    def step(self, t: float) -> int:
        self.times.append(t)
        assert self.ctx is not None
        self.ctx.epochs.write({"k": len(self.times), "t": round(t, 3)})
        if self.on_step is not None:
            self.on_step(len(self.times))
        return 1

    def check(self, now: float) -> None:
        self.checks += 1

    def idle_s(self) -> float:
        return 0.0

    def finish(self) -> None:
        self.finished = True

    def summary(self) -> dict[str, Any]:
        return {"steps_seen": len(self.times)}


def test_period_pacing_on_absolute_deadlines_until_the_duration(tmp_path: Path) -> None:
    clock = FakeClock(100.0)
    v = Ticker(0.2)
    summary = Runner(v, out_dir=tmp_path, duration_s=2.0, clock=clock,
                     sleep=clock.sleep).run()
    assert v.times == pytest.approx([100.0 + 0.2 * k for k in range(10)])
    assert v.checks == 10 and v.finished
    assert summary["runtime"]["stopped_by"] == "duration" and summary["overruns"] == 0
    lines = (tmp_path / "epochs.jsonl").read_text().splitlines()
    assert [json.loads(x)["k"] for x in lines] == list(range(1, 11))
    assert json.loads((tmp_path / "summary.json").read_text())["steps_seen"] == 10


def test_sigterm_stops_cleanly_and_restores_the_handler(tmp_path: Path) -> None:
    """A real SIGTERM to this process while the runner runs in the main thread."""
    before = signal.getsignal(signal.SIGTERM)

    def on_step(k: int) -> None:
        if k == 3:
            os.kill(os.getpid(), signal.SIGTERM)

    v = Ticker(0.01, on_step)
    summary = Runner(v, out_dir=tmp_path, duration_s=30.0).run()
    assert summary["runtime"]["stopped_by"] == "SIGTERM"
    assert 3 <= len(v.times) <= 4 and v.finished  # the step after the signal never starts
    assert (tmp_path / "summary.json").exists()
    assert signal.getsignal(signal.SIGTERM) is before


def _gps_device(clock: FakeClock, n: int, gap: tuple[float, float] | None = None,
                unplugged: list[tuple[float, float]] | None = None) -> SimDevice:
    sc = RoverScenario(rate_hz=10.0, duration_s=n / 10.0, seed=4, fault_every_s=1e9)
    chunks = [data for _, data, _ in generate(sc)]
    state = {"k": 0}

    def produce(now: float) -> bytes:
        out = b""
        while state["k"] < len(chunks) and state["k"] * 0.1 <= now + 1e-9:
            k = state["k"]
            if gap is None or not gap[0] <= k * 0.1 < gap[1]:
                out += chunks[k]
            state["k"] += 1
        return out

    return SimDevice("gps", clock, produce, unplugged=unplugged or [])


def _rover_cfg(**kw: Any) -> BridgeConfig:
    return BridgeConfig(rover=replace(RoverConfig(), port=SerialSettings(url="sim://gps"), **kw))


def test_data_pacing_records_outputs_and_taps(tmp_path: Path) -> None:
    """The rover by its epochs on a fake clock: every epoch in epochs.jsonl, GPS_INPUT through
    the one MAVLink output, every byte read and sent in the recording."""
    clock = FakeClock(0.0)
    dev = _gps_device(clock, 50)
    rec = FlightRecorder(tmp_path / "rec", RecorderConfig(), clock=clock)
    gps_inputs: list[bytes] = []
    out = packer_output(tap=gps_inputs.append, clock=clock)
    runner = Runner(RoverVehicle(_rover_cfg()), out_dir=tmp_path / "out", recorder=rec,
                    mavlink_output=out, clock=clock, opener=sim_opener({"sim://gps": dev}),
                    handle_signals=False)
    runner.start()
    for k in range(60):
        clock.now = k * 0.1
        runner.step()
    summary = runner.close()
    assert summary["epochs"] == 50 and summary["port"]["bytes_rx"] == dev.generated
    assert summary["outputs"]["MavlinkGpsSink"]["gps_input_sent"] == 50
    assert len(gps_inputs) >= 50 and out.packets == len(gps_inputs)
    assert (tmp_path / "out" / "epochs.jsonl").read_text().count("\n") == 50
    files = rec.recordings()
    reader = CaptureReader(files[0])
    assert [c.name for c in reader.channels] == ["gps rx"]
    assert sum(len(r.data) for r in reader) == dev.generated


def test_rover_port_backoff_follows_reconnect_max_s_also_with_a_router() -> None:
    """The MAVLink mode's rover used a fixed 5 s; now the runner opens every vehicle's ports
    with the vehicle's cap: rover.reconnect_max_s = 0.4 here, router attached."""
    clock = FakeClock(0.0)
    opens: list[float] = []

    def opener(settings: SerialSettings) -> Any:
        opens.append(clock())
        raise PortError(f"could not open {settings.url!r}: no such file")

    mav = MavlinkConfig(autopilot=EndpointConfig("udpin:127.0.0.1:0"),
                        gcs=(EndpointConfig("udpin:127.0.0.1:0"),))
    v = RoverVehicle(_rover_cfg(reconnect_max_s=0.4))
    runner = Runner(v, mavlink=mav, open_router=open_router, clock=clock, sleep=clock.sleep,
                    opener=opener,
                    duration_s=10.0, handle_signals=False)
    summary = runner.run()
    gaps = [round(b - a, 3) for a, b in itertools.pairwise(opens)]
    assert gaps[:3] == pytest.approx([0.1, 0.2, 0.4], abs=0.011)
    assert max(gaps) <= 0.4 + 0.011 and len(gaps) >= 20
    assert summary["router"]["own_sent"] >= 1  # the router ran (its heartbeat)
    assert summary["epochs"] == 0 and summary["failsafe"]["silences"] == 1


class RecordingOutput:
    """A MavlinkOutput that keeps every call."""

    def __init__(self, clock: FakeClock) -> None:
        self.clock = clock
        self.calls: list[tuple[float, str, Any]] = []

    def send_heartbeat(self) -> None:
        self.calls.append((self.clock(), "heartbeat", None))

    def send_statustext(self, severity: int, text: str) -> None:
        self.calls.append((self.clock(), "statustext", (severity, text)))

    def request_mode(self, target_system: int, mode: str, vehicle: str = "rover") -> None:
        self.calls.append((self.clock(), "mode", mode))

    def send_gps_input(self, fix: mio.GpsInputFix) -> None:
        self.calls.append((self.clock(), "gps_input", fix))

    def send_named_value(self, name: str, value: float) -> None:
        self.calls.append((self.clock(), "named_value", (name, value)))

    def send_manual_control(self, target_system: int, x: int, y: int, z: int, r: int,
                            buttons: int = 0) -> None:
        self.calls.append((self.clock(), "manual_control", (x, y, z, r)))

    def counters(self) -> dict[str, int]:
        return {"packets": len(self.calls)}

    def close(self) -> None:
        pass


@pytest.mark.parametrize("n_epochs", [1, 2])
def test_shutdown_records_the_pending_epoch_and_sends_nothing(tmp_path: Path,
                                                              n_epochs: int) -> None:
    clock = FakeClock(0.0)
    dev = _gps_device(clock, n_epochs)
    out = RecordingOutput(clock)
    runner = Runner(RoverVehicle(_rover_cfg(silence_s=1.0)), out_dir=tmp_path, clock=clock,
                    sleep=clock.sleep, mavlink_output=out,
                    opener=sim_opener({"sim://gps": dev}), duration_s=3.0,
                    handle_signals=False)
    summary = runner.run()
    gps = [(t, f) for t, kind, f in out.calls if kind == "gps_input"]
    texts = [a[1] for _, kind, a in out.calls if kind == "statustext"]
    assert gps[-1][1].fix_type == 1  # the last word is the no-fix, not the stale epoch
    timed = [f.time_usec for _, f in gps if f.time_usec]
    assert timed == sorted(timed)
    assert any("no valid data" in t for t in texts) and not any("back" in t for t in texts)
    assert summary["epochs"] == n_epochs and summary["shutdown"]["pending_not_sent"] == 1
    assert (tmp_path / "epochs.jsonl").read_text().count("\n") == n_epochs


def test_vehicle_that_fails_to_start_leaves_nothing_open() -> None:
    """The ArduSub ROV needs a router: a configuration error, and the runner closes cleanly."""
    runner = Runner(ArduSubRovVehicle(RovConfig()), handle_signals=False)
    with pytest.raises(ConfigError, match="mavlink"):
        runner.run()
    assert runner.summary()["runtime"]["iterations"] == 0


def test_serial_mavlink_output_is_built_by_the_factory(tmp_path: Path) -> None:
    """A vehicle's own serial MAVLink URL: the runner builds the resilient, tapped output."""
    clock = FakeClock(0.0)
    dev = _gps_device(clock, 5)
    ap = SimDevice("ap", clock, lambda now: b"")
    rec = FlightRecorder(tmp_path / "rec", RecorderConfig(), clock=clock)
    cfg = _rover_cfg()
    cfg = replace(cfg, rover=replace(cfg.rover, output=replace(cfg.rover.output,
                                                               mavlink_url="sim://ap")))
    runner = Runner(RoverVehicle(cfg), recorder=rec, clock=clock, handle_signals=False,
                    opener=sim_opener({"sim://gps": dev, "sim://ap": ap}))
    runner.start()
    assert isinstance(runner.mavlink_output, EncoderOutput)
    assert runner.mavlink_output.port is not None  # a serial line: a ResilientPort
    for k in range(10):
        clock.now = k * 0.1
        runner.step()
    summary = runner.close()
    assert summary["mavlink_out"]["packets"] >= 5 and summary["mavlink_out"]["send_errors"] == 0
    by_ch = summary["recorder"]["bytes_by_channel"]
    assert by_ch["mavlink tx"] > 0 and set(by_ch) == {"gps rx", "mavlink tx"}


def test_ardusub_rov_on_the_runner_through_a_router() -> None:
    """The ROV with its heading from an autopilot (ATTITUDE in, MANUAL_CONTROL out), on the
    runtime with a router over UDP on 127.0.0.1 (real time, 20 Hz, 40 steps)."""
    cfg = RovConfig(period_s=0.05, ardusub=ArduSubConfig(send_without_pilot=True))  # no GCS
    mav = MavlinkConfig(autopilot=EndpointConfig("udpin:127.0.0.1:0"),
                        gcs=(EndpointConfig("udpin:127.0.0.1:0"),))
    records: list[dict[str, Any]] = []
    v = ArduSubRovVehicle(cfg, on_epoch=records.append)
    runner = Runner(v, mavlink=mav, open_router=open_router, handle_signals=False)
    runner.start()
    assert runner.router is not None
    port = runner.router.endpoints[0].link.local_address[1]  # type: ignore[index]
    ap = mio.MavEndpoint(f"udpout:127.0.0.1:{port}", source_system=1, source_component=1)
    halt = threading.Event()
    controls: list[Any] = []

    def autopilot() -> None:  # ATTITUDE at 50 Hz, heading 120 deg; collect MANUAL_CONTROL
        k = 0
        while not halt.is_set():
            if k % 10 == 0:  # armed in ALT_HOLD (2): the bridge steers only then
                ap.send_vehicle_heartbeat(mio.MAV_TYPE_SUBMARINE,
                                          mio.MAV_MODE_FLAG_SAFETY_ARMED, 2)
            ap.send_attitude(k * 20, 0.0, 0.0, math.radians(120.0))
            k += 1
            msg = ap.recv(0.02)
            while msg is not None:
                if msg.get_type() == "MANUAL_CONTROL":
                    controls.append(msg)
                msg = ap.recv(0.0)

    th = threading.Thread(target=autopilot, daemon=True)
    th.start()
    try:
        deadline = time.monotonic() + 5.0
        while not v.loop or v.loop.heading.received == 0:
            assert time.monotonic() < deadline, "no ATTITUDE reached the vehicle"
            time.sleep(0.01)
        summary = runner.run(max_steps=40)
        wait = time.monotonic() + 2.0
        while len(controls) < 30 and time.monotonic() < wait:
            time.sleep(0.01)
    finally:
        halt.set()
        th.join(2.0)
        ap.close()
        runner.close()
    assert summary["vehicle"] == "rov-ardusub" and summary["steps"] >= 40
    measured = [r["heading_meas"] for r in records if r["heading_meas"] is not None]
    assert len(measured) >= 35 and all(abs(h - 120.0) < 0.01 for h in measured)
    assert len(controls) >= 30
    assert all((m.get_srcSystem(), m.target) == (255, 1) for m in controls)
    assert summary["attitude_received"] >= 35
