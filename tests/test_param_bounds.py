"""Issue C item 1: a ground station cannot set what a config file may not hold.

The MAVLink parameter table (``FDI_ALPHA`` ...) is built from the detector's field metadata, and
a PARAM_SET is checked with the loader's own check: the same values pass both ways, and those
are values the detector works with (``FDI_ALPHA = 1e-20`` made ``1 - alpha == 1.0`` and the
bridge exit "internal error: ValueError", after saving it to ``param_file``: a crash loop). A
refused PARAM_SET is answered with the value in force; a refused value found in ``param_file``
at start is logged and ignored.

Real parts in the last two tests: ``fdi-bridge run`` as a subprocess, the receiver on a real pty
at 10 Hz, pymavlink peers on 127.0.0.1 UDP as the autopilot and the ground station.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from drivers.mavlink import io as mio
from drivers.ptypair import PtyPair
from fdi.errors import ConfigError
from fdi.rover import RoverDetectorParams
from firmware_host.devtools.rover_sim import RoverScenario, generate
from firmware_host.mavlink.params import ParamSpec, ParamStore
from firmware_host.runtime.config import parse_bridge_file

ROOT = Path(__file__).resolve().parents[1]

# The documented "off" values of the table (0 turns the test or screen off); every other
# parameter refuses 0.
OFF_AT_ZERO = {
    "gate_sigmas", "drift_warn_sigmas", "ramp_sigmas", "grey_fed_sigmas", "stale_p", "max_hdop",
    "min_sats", "max_coast_s", "drift_calibrate_s", "drift_precal_s", "drift_floor_frac",
    "drift_cal_k", "drift_cal_min_h", "ramp_window_s", "drift_lag_s", "drift_lag_sd_s",
    "stale_move_m", "stale_move_quanta", "hold_exit_s", "hold_level_s", "hold_output_s",
    "step_pair_s", "frozen_coast_m",
}


def _table() -> tuple[ParamStore, dict[str, str]]:
    store = ParamStore()
    return store, store.register_dataclass("FDI", RoverDetectorParams())


def _file_accepts(key: str, value: float, integer: bool) -> bool:
    text = int(value) if integer else value
    try:
        parse_bridge_file({"rover": {"detector": {key: text}}}, "probe.toml")
    except ConfigError:
        return False
    return True


def _probes(spec: ParamSpec) -> list[float]:
    values = [0.0, 1e-38, 1e-20, 1e-15, 1e-6, 0.5, 1.0, 3.0, 50.0, 1e5, 1e308, -1.0, -1e-38,
              spec.default]
    for bound in (spec.min, spec.max):
        if math.isfinite(bound):
            values += [bound, math.nextafter(bound, -math.inf), math.nextafter(bound, math.inf)]
    if spec.integer:
        values = sorted({float(round(v)) for v in values if abs(v) < 1e9})
    return values


def test_a_parameter_takes_exactly_what_a_config_file_takes() -> None:
    """One validation: for every parameter of the table, at its bounds, just outside them and at
    the values a fuzzer tries, PARAM_SET accepts exactly what the loader accepts."""
    store, names = _table()
    assert len(names) == 48  # every int/float of RoverDetectorParams (test_param_names.py)
    checked = 0
    for key, name in names.items():
        spec = store.spec(name)
        for value in _probes(spec):
            by_param = ParamStore()
            by_param.register_dataclass("FDI", RoverDetectorParams())
            ok_param = by_param.set(name, value)
            ok_file = _file_accepts(key, value, spec.integer)
            assert ok_param == ok_file, (name, value, ok_param, ok_file)
            checked += 1
    assert checked > 800


def test_the_table_holds_only_values_the_detector_works_with() -> None:
    """alpha in [1e-15, 0.5]; no float takes 1e-38 or 1e308; counts at least 1; 0 only where it
    is the documented "off"."""
    store, names = _table()
    alpha = store.spec("FDI_ALPHA")
    assert (alpha.min, alpha.max) == (1e-15, 0.5)
    for key, name in names.items():
        spec = store.spec(name)
        assert store.set(name, 1e308) is False, name
        assert store.set(name, -1.0) is False, name
        if not spec.integer:
            assert store.set(name, 1e-38) is False, name
        assert store.set(name, 0.0) is (key in OFF_AT_ZERO), name
        assert store.set(name, spec.default) is True, name
    for key in ("max_consecutive", "recover_epochs", "window"):
        assert store.spec(names[key]).min >= 1
    for key in ("gate_sigmas", "doppler_sigmas", "drift_sigmas", "hold_exit_sigmas"):
        assert store.spec(names[key]).min == 1.0  # the stated floor of a width in σ
    # Every one of them still builds a detector that steps (the bounds are not too wide).
    from fdi.rover import FixInput, RoverIsolator
    for name in store.names():
        spec = store.spec(name)
        for value in (spec.min, spec.max):
            trial = ParamStore()
            fields = trial.register_dataclass("FDI", RoverDetectorParams())
            assert trial.set(name, value), (name, value)
            iso = RoverIsolator(trial.dataclass_view(RoverDetectorParams(), fields))
            for k in range(30):
                iso.step(FixInput(float(k), (0.1 * k, 0.0, 0.0), 0.1, 90.0, None, 8, 0.9))


def test_a_refused_set_changes_nothing_and_is_logged(tmp_path: Path,
                                                     caplog: pytest.LogCaptureFixture) -> None:
    path = tmp_path / "params.toml"
    store = ParamStore(path)
    store.register_dataclass("FDI", RoverDetectorParams())
    changes: list[tuple[str, float]] = []
    store.on_change(lambda n, v: changes.append((n, v)))
    with caplog.at_level(logging.WARNING, "fdi_bridge.params"):
        assert store.set("FDI_ALPHA", 1e-20) is False
        assert store.set("FDI_MAX_CONSECUT", 0.0) is False
        assert store.set("FDI_GATE_SIGMAS", 1e-38) is False
    assert store.get("FDI_ALPHA") == 0.05 and store.get("FDI_MAX_CONSECUT") == 5.0
    assert store.rejected == 3 and changes == [] and not path.exists()
    assert "PARAM_SET FDI_ALPHA: expected a number >= 1e-15, found 1e-20; refused, 0.05 " \
           "stays in force" in caplog.text
    assert "PARAM_SET FDI_GATE_SIGMAS: expected 0.0 (off) or a number >= 1.0" in caplog.text
    assert store.set("FDI_ALPHA", 0.01) and store.set("FDI_GATE_SIGMAS", 0.0)  # the off value
    # A bound as a ground station sends it (float32: 0.01 -> 0.0099999998) is the bound.
    assert store.set("FDI_GATE_M", float(np.float32(0.01))) and store.get("FDI_GATE_M") == 0.01
    assert not store.set("FDI_GATE_M", float(np.float32(0.0099)))
    assert "FDI_ALPHA = 0.01" in path.read_text() and changes[0] == ("FDI_ALPHA", 0.01)


def test_a_bad_parameter_file_is_reported_and_ignored(tmp_path: Path,
                                                      caplog: pytest.LogCaptureFixture) -> None:
    """The crash-loop case: values an older bridge saved (or a person wrote) that the loader
    refuses are logged with file, name, expected and found, and the configured value is used;
    the file is written again without them. The good ones stay."""
    path = tmp_path / "params.toml"
    path.write_text("[params]\nFDI_ALPHA = 1e-20\nFDI_WINDOW = 8\nFDI_MAX_CONSECUT = 0\n"
                    "FDI_SIGMA_M = 'x'\nFDI_GATE_M = nan\nOTHER_P = 3.5\n")
    with caplog.at_level(logging.WARNING, "fdi_bridge.params"):
        store = ParamStore(path)
        store.register_dataclass("FDI", RoverDetectorParams())
    assert store.get("FDI_ALPHA") == 0.05 and store.get("FDI_MAX_CONSECUT") == 5.0
    assert store.get("FDI_WINDOW") == 8.0 and store.get("FDI_SIGMA_M") == 0.35
    assert store.ignored_overrides == 4
    assert (f"parameter file {path}: FDI_ALPHA: expected a number >= 1e-15, found 1e-20; "
            "ignored, 0.05 (the configured value) in force") in caplog.text
    assert f"parameter file {path}: FDI_MAX_CONSECUT: expected a number >= 1, found 0.0" \
           in caplog.text
    assert f"parameter file {path}: params.FDI_SIGMA_M: expected a finite number, found 'x'" \
           in caplog.text
    text = path.read_text()
    assert "FDI_WINDOW = 8.0" in text and "OTHER_P = 3.5" in text  # another table's: kept
    for gone in ("FDI_ALPHA", "FDI_MAX_CONSECUT", "FDI_SIGMA_M", "FDI_GATE_M"):
        assert gone not in text


def test_a_parameter_file_that_is_not_toml_is_ignored_and_kept(tmp_path: Path,
                                                               caplog: pytest.LogCaptureFixture
                                                               ) -> None:
    path = tmp_path / "params.toml"
    path.write_text("[params\nFDI_ALPHA = 0.01\n")
    with caplog.at_level(logging.WARNING, "fdi_bridge.params"):
        store = ParamStore(path)
        store.register_dataclass("FDI", RoverDetectorParams())
    assert store.get("FDI_ALPHA") == 0.05
    assert f"parameter file {path}: (syntax): expected valid TOML" in caplog.text
    assert store.set("FDI_ALPHA", 0.02)
    assert (tmp_path / "params.toml.bad").read_text() == "[params\nFDI_ALPHA = 0.01\n"
    assert "FDI_ALPHA = 0.02" in path.read_text()


# --------------------------------------------------------------------------- the running bridge


CONFIG = """name = "param-bounds"
[rover]
silence_s = 1.0
[rover.port]
url = "{gps}"
timeout_s = 0.05
[mavlink]
tlog_dir = ""
param_file = "{params}"
[mavlink.autopilot]
url = "udpin:127.0.0.1:{ap}"
[[mavlink.gcs]]
url = "udpin:127.0.0.1:{gcs}"
"""


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _wait(cond: Callable[[], bool], what: str, deadline_s: float = 20.0) -> None:
    end = time.monotonic() + deadline_s
    while not cond():
        if time.monotonic() > end:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.01)  # polling receiver threads, bounded by the deadline


class _Peer(threading.Thread):
    """A pymavlink peer (udpout to the bridge) that records what it receives and sends a
    HEARTBEAT every 0.5 s, so that the bridge learns it whenever its socket opens."""

    def __init__(self, port: int, sysid: int, compid: int) -> None:
        super().__init__(daemon=True)
        self.ep = mio.MavEndpoint(f"udpout:127.0.0.1:{port}", source_system=sysid,
                                  source_component=compid)
        self.msgs: list[Any] = []
        self.halt = threading.Event()

    def run(self) -> None:
        next_hb = 0.0
        while not self.halt.is_set():
            if time.monotonic() >= next_hb:
                self.ep.send_heartbeat()
                next_hb = time.monotonic() + 0.5
            try:
                msg = self.ep.recv(0.05)
            except OSError:  # ICMP port unreachable before the bridge binds
                continue
            if msg is not None:
                self.msgs.append(msg)

    def of(self, kind: str) -> list[Any]:
        return [m for m in list(self.msgs) if m.get_type() == kind]

    def param(self, name: str) -> list[float]:
        return [m.param_value for m in self.of("PARAM_VALUE") if m.param_id == name]

    def close(self) -> None:
        self.halt.set()
        self.join(timeout=2.0)
        self.ep.close()


class _Receiver(threading.Thread):
    """The GPS receiver: a simulated drive's NMEA on the pty at 10 Hz until stopped."""

    def __init__(self, pty: PtyPair) -> None:
        super().__init__(daemon=True)
        sc = RoverScenario(rate_hz=10.0, duration_s=120.0, seed=5, fault_every_s=1e9)
        self.chunks = [data for _, data, _ in generate(sc)]
        self.pty = pty
        self.halt = threading.Event()

    def run(self) -> None:
        for chunk in self.chunks:
            if self.halt.is_set():
                return
            self.pty.write(chunk)
            self.pty.read(0.0)
            self.halt.wait(0.1)  # the receiver's rate

    def stop(self) -> None:
        self.halt.set()
        self.join(timeout=5.0)


class _Bridge:
    """``fdi-bridge run`` with a [rover] and a [mavlink] table, its receiver and two peers."""

    def __init__(self, tmp_path: Path) -> None:
        self.params = tmp_path / "params.toml"
        ap, gcs = _free_udp_port(), _free_udp_port()
        self.cfg = tmp_path / "bridge.toml"
        self.cfg.write_text(CONFIG.format(gps=tmp_path / "gps", params=self.params, ap=ap,
                                          gcs=gcs))
        self.pty = PtyPair(link=tmp_path / "gps", baudrate=9600)
        self.receiver = _Receiver(self.pty)
        self.autopilot = _Peer(ap, 1, 1)
        self.gcs = _Peer(gcs, 255, 190)
        self.stderr = tmp_path / "stderr.txt"
        self.proc: subprocess.Popen[bytes] | None = None

    def start(self) -> None:
        with self.stderr.open("wb") as err:
            self.proc = subprocess.Popen(
                [sys.executable, "-m", "firmware_host.cli", "run", "--config", str(self.cfg),
                 "--duration", "60"], cwd=self.cfg.parent, stdout=subprocess.DEVNULL,
                stderr=err, env=dict(os.environ, PYTHONPATH=str(ROOT)))
        self.receiver.start()
        self.autopilot.start()
        self.gcs.start()

    def alive(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def gps_inputs(self) -> int:
        return len(self.autopilot.of("GPS_INPUT"))

    def wait_gps_inputs(self, n: int, what: str) -> None:
        _wait(lambda: self.gps_inputs() >= n or not self.alive(), what)
        assert self.alive(), self.stderr.read_text()
        assert self.gps_inputs() >= n

    def stop(self) -> int:
        assert self.proc is not None
        if self.alive():
            self.proc.send_signal(signal.SIGTERM)
        try:
            return self.proc.wait(timeout=20.0)
        finally:
            self.receiver.stop()
            self.autopilot.close()
            self.gcs.close()
            self.pty.close()


def test_a_ground_station_cannot_set_an_alpha_the_detector_cannot_use(tmp_path: Path) -> None:
    bridge = _Bridge(tmp_path)
    bridge.start()
    try:
        bridge.wait_gps_inputs(10, "GPS_INPUT at the autopilot")
        bridge.gcs.ep.send_param_set(1, 191, "FDI_ALPHA", 1e-20)
        _wait(lambda: bool(bridge.gcs.param("FDI_ALPHA")), "the PARAM_VALUE answer")
        answer = bridge.gcs.param("FDI_ALPHA")[0]
        assert answer == pytest.approx(0.05, rel=1e-6)  # the value in force (float32 on the wire)
        # (each answer may come twice to a server endpoint's peer: issue C item 9, the router's)
        assert not bridge.params.exists()  # nothing saved
        n = bridge.gps_inputs()
        bridge.wait_gps_inputs(n + 20, "20 more epochs after the refused PARAM_SET")
        # A value it may use is taken, answered and saved (the path is open, not shut).
        bridge.gcs.ep.send_param_set(1, 191, "FDI_ALPHA", 0.01)
        _wait(lambda: bridge.gcs.param("FDI_ALPHA")[-1] != answer, "the second answer")
        assert bridge.gcs.param("FDI_ALPHA")[-1] == pytest.approx(0.01, rel=1e-6)
        n = bridge.gps_inputs()
        bridge.wait_gps_inputs(n + 10, "10 more epochs after the accepted PARAM_SET")
    finally:
        rc = bridge.stop()
    stderr = bridge.stderr.read_text()
    assert rc == 0, stderr
    assert "internal error" not in stderr and "Traceback" not in stderr
    assert "PARAM_SET FDI_ALPHA: expected a number >= 1e-15" in stderr
    assert "FDI_ALPHA = 0.009999999776482582" in bridge.params.read_text()  # float32 0.01


def test_a_param_file_holding_a_refused_alpha_starts_and_says_so(tmp_path: Path) -> None:
    """The crash loop: FDI_ALPHA = 1e-20 in param_file at start (an older bridge saved it)."""
    bridge = _Bridge(tmp_path)
    bridge.params.write_text("[params]\nFDI_ALPHA = 1e-20\nFDI_WINDOW = 8\n")
    bridge.start()
    try:
        bridge.wait_gps_inputs(20, "GPS_INPUT at the autopilot")
        for name in ("FDI_ALPHA", "FDI_WINDOW"):
            bridge.gcs.ep.send_param_request_read(1, 191, name, -1)
        _wait(lambda: bool(bridge.gcs.param("FDI_ALPHA") and bridge.gcs.param("FDI_WINDOW")),
              "the PARAM_VALUE answers")
        assert bridge.gcs.param("FDI_ALPHA")[0] == pytest.approx(0.05, rel=1e-6)
        assert bridge.gcs.param("FDI_WINDOW")[0] == 8.0  # the good value of the file is used
    finally:
        rc = bridge.stop()
    stderr = bridge.stderr.read_text()
    assert rc == 0, stderr
    assert "internal error" not in stderr and "Traceback" not in stderr
    assert (f"parameter file {bridge.params}: FDI_ALPHA: expected a number >= 1e-15, found "
            "1e-20; ignored, 0.05 (the configured value) in force") in stderr
    text = bridge.params.read_text()
    assert "FDI_ALPHA" not in text and "FDI_WINDOW = 8.0" in text


def test_a_seeded_draw_of_values_agrees_too() -> None:
    """Beyond the fixed probes: 20 values drawn log-uniformly over 1e-40 .. 1e10, either sign,
    for every fifth parameter, as a fuzzer would try them: PARAM_SET and the file agree."""
    rng = np.random.default_rng(20261207)
    store, names = _table()
    for key, name in list(names.items())[::5]:
        spec = store.spec(name)
        for value in 10.0 ** rng.uniform(-40, 10, 20) * rng.choice([-1.0, 1.0], 20):
            value = float(round(value)) if spec.integer else float(value)
            trial = ParamStore()
            trial.register_dataclass("FDI", RoverDetectorParams())
            assert trial.set(name, value) == _file_accepts(key, value, spec.integer), \
                (name, value)


def test_register_dataclass_keeps_the_cross_checks() -> None:
    """A dataclass's own __post_init__ is part of the one validation."""

    @dataclasses.dataclass(frozen=True)
    class Two:
        lo: float = dataclasses.field(default=1.0, metadata={"ge": 0.0, "le": 10.0})
        hi: float = dataclasses.field(default=2.0, metadata={"ge": 0.0, "le": 10.0})

        def __post_init__(self) -> None:
            if not self.lo < self.hi:
                raise ValueError(f"lo ({self.lo}) must be below hi ({self.hi})")

    store = ParamStore()
    store.register_dataclass("T", Two())
    assert store.set("T_LO", 3.0) is False and store.get("T_LO") == 1.0
    assert store.set("T_HI", 5.0) and store.set("T_LO", 3.0)
