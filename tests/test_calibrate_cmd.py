"""``fdi-bridge calibrate``: the drift test calibrated once on a clean recording (issue 13).

A generated clean drive of one receiver is recorded (capture) and calibrated; the written
configuration loads, carries the σ and the measured Doppler lag (the harness's
``--offline-calibration`` finds the same; the lag is also checked on exact drives),
and on a later drive of the same receiver finds a ramp that begins in the first minutes
sooner than the wide starting σ do. Bad input is a clear error naming the file."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from firmware_host import cli
from firmware_host.devtools import rover_harness as H
from firmware_host.devtools.rover_sim import draw_field_model, write_run
from firmware_host.rover.calibration import LAG_RAMP_SIGMAS, LAG_SD_FLOOR_S, estimate_lag
from firmware_host.runtime.config import load_config


def _drive(tmp: Path, name: str, *, seed: int, receiver: int, duration_s: float,
           rate_hz: float = 5.0, model: str = "dgps") -> Path:
    """A clean drive of the generator's receiver ``receiver``, as the harness's offline
    calibration makes it, recorded as a capture."""
    out = tmp / name
    write_run(H.clean_drive(model, seed, receiver, rate_hz, duration_s), out)
    return out / "rover.cap"


def test_calibrate_writes_a_config_with_the_receiver_s_sigma(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    cap = _drive(tmp_path, "clean", seed=100_903, receiver=903, duration_s=600.0)
    out = tmp_path / "mine.toml"
    assert cli.main(["calibrate", str(cap), "--config", "rover", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    sigma_line = next(ln for ln in printed.splitlines() if ln.startswith("drift_sigma_m = "))
    cfg = load_config(str(out))
    d, default = cfg.rover.detector, load_config("rover").rover.detector
    assert cfg.name == "rover-calibrated"
    assert sigma_line == "drift_sigma_m = [" + ", ".join(f"{x:g}" for x in d.drift_sigma_m) + "]"
    assert list(d.drift_sigma_m) == sorted(d.drift_sigma_m)
    # A dgps receiver: under the wide starting values; the same numbers as the harness's
    # offline calibration of that receiver (the same drive, from the capture).
    assert all(s < w for s, w in zip(d.drift_sigma_m, default.drift_sigma_m, strict=True))
    ref = H.offline_calibrated(load_config("rover"), "dgps", 903, 5.0, 600.0)
    assert d.drift_sigma_m == ref.rover.detector.drift_sigma_m
    # The day's calibration at start may widen them, not narrow them; everything else is
    # the configuration it came from (it still calibrates at start).
    assert d.drift_floor_frac == pytest.approx(1.0 / 1.5, abs=1e-4)
    assert default.drift_floor_frac == 0.2 and "drift_floor_frac = 0.6667" in printed
    assert d.drift_calibrate_s == default.drift_calibrate_s == 300.0
    assert d.drift_horizons_s == default.drift_horizons_s and d.gate_m == default.gate_m
    # The Doppler's lag is measured on the drive (this receiver's is drawn 0.05-0.3 s), and
    # written with the σ that were calibrated with it.
    true_lag = draw_field_model("dgps", 903).lag_s
    assert abs(d.drift_lag_s - true_lag) <= 0.03, (d.drift_lag_s, true_lag)
    assert d.drift_lag_sd_s == LAG_SD_FLOOR_S < default.drift_lag_sd_s
    assert (d.drift_lag_s, d.drift_lag_sd_s) == (ref.rover.detector.drift_lag_s,
                                                 ref.rover.detector.drift_lag_sd_s)
    assert f"drift_lag_s = {d.drift_lag_s:g}" in printed and "Doppler lag " in printed
    # With the lag measured, the ramp's 10 s flag at the warning's level (the σ are tighter).
    assert d.ramp_sigmas == LAG_RAMP_SIGMAS > default.ramp_sigmas
    assert f"ramp_sigmas = {LAG_RAMP_SIGMAS:g}" in printed


def _records(lag_s: float, *, turn: bool, rate_hz: float = 10.0, seconds: float = 300.0
             ) -> list[dict[str, Any]]:
    """A tractor on a circle of 20 m at 2 m/s (or a straight line) whose Doppler is the true
    velocity ``lag_s`` ago, with 1 cm of seeded noise on the position, as pipeline records."""
    rng = np.random.default_rng(7)
    out = []
    w = 2.0 / 20.0 if turn else 0.0
    for k in range(round(seconds * rate_hz)):
        t = k / rate_hz
        if turn:
            e, n = 20.0 * math.sin(w * t), 20.0 * (1.0 - math.cos(w * t))
        else:
            e, n = 0.0, 2.0 * t
        # Course over ground (clockwise from north) of the velocity lag_s ago: 90° − ω(t − δ).
        course = (90.0 - math.degrees(w * (t - lag_s))) % 360.0 if turn else 0.0
        out.append({"utc": 36000.0 + t, "e": e + float(rng.normal(0, 0.01)),
                    "n": n + float(rng.normal(0, 0.01)), "speed": 2.0, "course": course})
    return out


@pytest.mark.parametrize("lag_s", [0.0, 0.12, 0.35])
def test_the_doppler_lag_is_measured_where_the_drive_turns(lag_s: float) -> None:
    est = estimate_lag([_records(lag_s, turn=True)])
    assert est is not None and est.pairs > 1000
    assert est.lag_s == pytest.approx(lag_s, abs=0.01)
    assert est.sd_s == LAG_SD_FLOOR_S  # a standard error far under the floor
    assert estimate_lag([_records(lag_s, turn=False)]) is None  # a straight drive: no evidence


def test_a_calibrated_receiver_finds_an_early_ramp_sooner(tmp_path: Path) -> None:
    """The harness's run `multipath` 1 Hz seed 905 has a 0.17 m/s ramp 58 s in: from the
    wide starting σ the drift test finds it after 27 s; calibrated on a clean drive of the
    same receiver (fdi-bridge calibrate on its recording), after 9 s, within the ramp
    bullet's 10 s."""
    cap = _drive(tmp_path, "clean", seed=100_905, receiver=905, duration_s=1200.0,
                 rate_hz=1.0, model="multipath")
    out = tmp_path / "mine.toml"
    assert cli.main(["calibrate", str(cap), "--out", str(out)]) == 0
    sc = H.scenario("multipath", 905, 1.0, 400.0)
    delays = []
    for cfg in (load_config("rover"), load_config(str(out))):
        m = H.measure(*H.replay(cfg, sc))
        (ramp,) = [e for e in m.events if e.kind == "ramp" and e.start_s % 86400 < 36100]
        assert 0.16 < ramp.rate_mps < 0.17
        delays.append(ramp.delay_s)
    assert delays[0] is None or delays[0] > 20.0
    assert delays[1] is not None and delays[1] <= 10.0


def test_a_short_recording_is_a_clear_error(tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    cap = _drive(tmp_path, "short", seed=5, receiver=5, duration_s=120.0)
    assert cli.main(["calibrate", str(cap)]) == 1
    err = capsys.readouterr().err
    assert str(cap) in err and "200 s" in err and "Traceback" not in err


def test_a_file_with_no_fixes_and_a_config_without_the_drift_test(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    junk = tmp_path / "notes.txt"
    junk.write_text("not a GPS log\n", encoding="utf-8")
    assert cli.main(["calibrate", str(junk)]) == 1
    assert "no position fixes" in capsys.readouterr().err
    cap = _drive(tmp_path, "clean", seed=6, receiver=6, duration_s=60.0)
    assert cli.main(["calibrate", str(cap), "--config", "rover-paper"]) == 2
    assert "drift test does not run" in capsys.readouterr().err


def test_the_floor_reaches_the_drift_test() -> None:
    import dataclasses

    from fdi.rover import RoverIsolator

    det = load_config("rover").rover.detector
    for frac in (0.2, 0.6667):
        iso = RoverIsolator(dataclasses.replace(det, drift_floor_frac=frac))
        assert iso._drift is not None and iso._drift.floor_frac == frac


def test_an_output_that_cannot_be_written_is_a_clear_error(
        tmp_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    cap = _drive(tmp_path, "clean", seed=100_903, receiver=903, duration_s=300.0)

    def full_disk(self: Path, *a: object, **k: object) -> int:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(Path, "write_text", full_disk)
    assert cli.main(["calibrate", str(cap), "--out", str(tmp_path / "mine.toml")]) == 1
    err = capsys.readouterr().err
    assert "mine.toml: cannot write the configuration: No space left on device" in err
    assert "Traceback" not in err


def _slow_drift_line(capsys: pytest.CaptureFixture[str], cap: Path) -> str:
    assert cli.main(["calibrate", str(cap)]) == 0
    return next(ln for ln in capsys.readouterr().out.splitlines()
                if ln.startswith("slow drifts"))


def _p(line: str, bullet: str) -> tuple[float, float]:
    """The two probabilities printed for ``bullet`` (like '0.1 m/s within 10 s')."""
    part = line.split(bullet + ": at most ")[1]
    told, rest = part.split(" (direction unknown ", 1)
    return float(told), float(rest.split(")")[0])


def test_calibrate_bounds_what_a_test_could_find_of_a_slow_drift(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The receiver's own recordings say how small a drift any test could find in time
    (firmware_host/devtools/ramp_oracle.py): on the `gm` receiver (a 60 s Gauss-Markov
    error) at 1 Hz a 0.1 m/s ramp within 10 s is not certain even for the oracle; on a
    `dgps` receiver at 5 Hz it is. A recording too short for the bound says so, and the
    calibration is still made."""
    gm = _slow_drift_line(capsys, _drive(tmp_path, "gm", seed=100_001, receiver=1,
                                         duration_s=600.0, rate_hz=1.0, model="gm"))
    told, unknown = _p(gm, "0.1 m/s within 10 s")
    assert 0.5 < unknown < told < 0.95, gm
    dgps = _slow_drift_line(capsys, _drive(tmp_path, "dgps", seed=100_903, receiver=903,
                                           duration_s=600.0))
    assert _p(dgps, "0.1 m/s within 10 s")[1] >= 0.99, dgps
    short = _slow_drift_line(capsys, _drive(tmp_path, "short", seed=100_903, receiver=903,
                                            duration_s=250.0))
    assert short.startswith("slow drifts: no bound") and "no Doppler chain longer" in short


def test_calibrate_says_what_the_receiver_sends_against_its_line(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Issue E: the receiver's actual rate and sentence set, and whether they fit the line: the
    capture's own baud rate for a capture; for a plain log, ``[rover.port] baudrate`` (9600 by
    default, where 5 Hz of GGA+RMC+VTG does not fit)."""
    cap = _drive(tmp_path, "clean", seed=100_904, receiver=904, duration_s=600.0)
    assert cli.main(["calibrate", str(cap)]) == 0
    line = next(ln for ln in capsys.readouterr().out.splitlines() if ln.startswith(str(cap)))
    assert "the receiver sends 5 Hz of GGA+RMC+VTG" in line, line
    assert "; fits the capture's 19200 baud" in line, line
    nmea = cap.with_suffix(".nmea")
    assert nmea.is_file()
    assert cli.main(["calibrate", str(nmea)]) == 0
    line = next(ln for ln in capsys.readouterr().out.splitlines() if ln.startswith(str(nmea)))
    assert "the receiver sends 5 Hz of GGA+RMC+VTG" in line, line
    assert "; does not fit [rover.port] 9600 baud" in line and "at most 4 Hz fits" in line, line
