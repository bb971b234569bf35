"""The rover's detector on values the codec would never pass (issue 43, item 2): no math error.

The codec refuses them (tests/test_nmea_numbers.py); these guards keep any other caller of
:class:`fdi.rover.RoverIsolator` from the two crashes of the issue and from a third found by
the pipeline fuzzer (``fdi-bridge fuzz --pipeline``): a 2D fix after a refused one took the
refused fix's height.
"""

from __future__ import annotations

import io
import json
import math

import numpy as np
import pytest

from drivers.gps.nmea import with_checksum
from fdi.drift import NO_TEST, DriftTest
from fdi.rover import TIME_RESET_EPOCHS, FixInput, RoverIsolator
from firmware_host.devtools.rover_sim import RoverScenario, generate
from firmware_host.rover.pipeline import RoverPipeline
from firmware_host.runtime.config import load_config

CONFIGS = [None, "rover-paper", "rover-three-zone-paper", "rover-combined-paper"]
HUGE = [1e308, math.inf, math.nan, 1e154]


def _run(cfg: str | None, field: str, value: float) -> list[tuple[float, float, float]]:
    """300 clean epochs at 10 Hz (seeded noise), ``field`` set to ``value`` in epochs
    100-109; the outputs."""
    rng = np.random.default_rng(7)
    iso = RoverIsolator(load_config(cfg).rover.detector)
    out = []
    for k in range(300):
        t = 0.1 * k
        enu = (0.3 * t + float(rng.normal(0.0, 0.05)), 0.1 * t, float(rng.normal(0.0, 0.1)))
        fix = {"t_s": t, "enu": enu, "speed_mps": 0.316, "course_deg": 71.57,
               "sd_enu_m": (0.3, 0.3, 0.6), "num_sats": 9, "hdop": 0.9}
        if 100 <= k < 110:
            fix[field] = (value, value, value) if field == "sd_enu_m" else value
        d = iso.step(FixInput(**fix))  # type: ignore[arg-type]
        if d.out_enu is not None:
            out.append(d.out_enu)
    return out


def test_isolator_takes_huge_and_non_finite_speed_course_and_sigma() -> None:
    """Before: speed 1e308 -> StopIteration (the drift test), GST sigma 1e308 ->
    OverflowError (its square), course inf -> ValueError (its sine). A course or sigma that
    is no number is not used (the outputs stay finite); a speed of 1e308 integrates to
    positions no output could carry (the codec refuses speeds over 1 000 knots): here only
    that no epoch raises (and the detector flags them: the default's Doppler tests do)."""
    for cfg in CONFIGS:
        for field in ("speed_mps", "course_deg", "sd_enu_m"):
            for value in HUGE:
                outputs = _run(cfg, field, value)
                if field != "speed_mps":
                    assert len(outputs) >= 290, (cfg, field, value)
                    assert all(math.isfinite(x) for o in outputs for x in o[:2]), (
                        cfg, field, value)


def test_gst_sigma_whose_square_overflows_gives_the_configured_sigma() -> None:
    p = load_config(None).rover.detector
    iso = RoverIsolator(p)
    fix = FixInput(0.0, (0.0, 0.0, 0.0), sd_enu_m=(1e308, 0.3, 0.6))
    s, su = p.sigma_m, p.sigma_up_m
    assert iso._r(fix) == (s * s, s * s, su * su)
    ok = FixInput(0.0, (0.0, 0.0, 0.0), sd_enu_m=(0.3, 0.3, 0.6))
    assert iso._r(ok) == pytest.approx((0.09, 0.09, 0.36), rel=1e-12)


def test_drift_test_on_non_finite_values_is_no_test() -> None:
    drift = DriftTest([1.0, 5.0], [0.1, 0.3], lag_sd_s=0.05)
    for k in range(100):
        drift.commit(0.1 * k, (0.01 * k, 0.0), (0.1, 0.0))
    # NaN statistics at every horizon: before, StopIteration choosing the reference
    assert drift.test(10.0, (math.nan, 0.0), (0.1, 0.0)) == NO_TEST
    assert drift.test(10.0, (math.inf, 0.0), (math.inf, 0.0)) == NO_TEST  # inf / inf
    assert drift.test(10.0, (1.0, 0.0), (0.1, 0.0)).g > 0.0  # a finite one is a test


def test_a_2d_fix_after_a_refused_one_keeps_the_last_height_passed_on() -> None:
    """One GGA 2 400 km off (latitude ``1000``: 10 deg N, a valid NMEA number) and the next
    epoch's GGA lost (RMC only, a 2D fix): before, the 2D fix held the refused fix's height
    (460 km below the frame's plane) and the output altitude went to -248 km."""
    sc = RoverScenario(rate_hz=10.0, duration_s=60.0, seed=5, gst=True)
    lines: list[bytes] = []
    n = 0
    for _, data, _ in generate(sc):
        for line in data.split(b"\r\n"):
            if line.startswith(b"$GPGGA"):
                n += 1
                if n == 201:
                    continue  # the GGA lost: this epoch is RMC only
                if n == 200:
                    fields = line[1 : line.rindex(b"*")].decode().split(",")
                    fields[2] = "1000"
                    line = with_checksum(",".join(fields)).rstrip(b"\r\n")
            if line:
                lines.append(line + b"\r\n")
    jsonl = io.StringIO()
    pipeline = RoverPipeline(load_config(None).rover, jsonl=jsonl)
    pipeline.feed(b"".join(lines))
    pipeline.finish()
    records = [json.loads(x) for x in jsonl.getvalue().splitlines()]
    assert len(records) == 600
    raw = [r["raw_alt"] for r in records if r["raw_alt"] is not None]
    out = [r["alt"] for r in records if r["alt"] is not None]
    assert len(out) >= 590
    # Every output altitude within the receiver's own (7.7-9.4 m), 0.5 m to spare.
    assert min(raw) - 0.5 <= min(out) and max(out) <= max(raw) + 0.5, (min(out), max(out))
    assert all(abs(r["lat"] - 32.021) < 0.001 for r in records if r["lat"] is not None)


@pytest.mark.parametrize("cfg", CONFIGS)
def test_one_sentence_whose_clock_jumped_back_does_not_restart_the_filter(cfg: str | None
                                                                          ) -> None:
    """The pipeline fuzzer's case (1 M inputs, seed 1): one GGA at 10:00:00 in a track at
    10:01:36, its latitude 13 deg away (a checksum-valid corrupt sentence). It restarted the
    filter on its fix and the next fixes went out 166 km below the ground. Now it is not
    passed on; a clock that really jumped back is believed after TIME_RESET_EPOCHS fixes."""
    iso = RoverIsolator(load_config(cfg).rover.detector)

    def fix(t: float, enu: tuple[float, float, float]) -> FixInput:
        return FixInput(t_s=t, enu=enu, speed_mps=0.316, course_deg=71.57,
                        sd_enu_m=(0.3, 0.3, 0.6), num_sats=9, hdop=0.9)

    rng = np.random.default_rng(3)
    for k in range(200):
        t = 0.1 * k
        iso.step(fix(t, (0.3 * t + float(rng.normal(0.0, 0.05)), 0.1 * t, 0.0)))
    far = iso.step(fix(19.9 - 96.0, (0.0, -1_457_000.0, -166_000.0)))
    assert far.out_enu is None and far.reason == "time_backwards"
    worst_up = 0.0
    for k in range(200, 260):
        t = 0.1 * k
        d = iso.step(fix(t, (0.3 * t, 0.1 * t, 0.0)))
        if d.out_enu is not None:
            worst_up = max(worst_up, abs(d.out_enu[2]))
    assert worst_up < 5.0
    # a real jump back: the third fix in a row on the new time base is passed on
    outs = [iso.step(fix(30.0 - 100.0 + 0.1 * i, (0.0, 0.0, 0.0))).out_enu
            for i in range(TIME_RESET_EPOCHS)]
    assert outs[:-1] == [None] * (TIME_RESET_EPOCHS - 1) and outs[-1] is not None
