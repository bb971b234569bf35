"""``sim rover-frozen`` (issue 42): a frozen receiver on a curved path, the generator, the
score, and the default preset against the bullet (no output more than 1 m further from the
truth than the receiver was when it froze; none rather than a worse one) on one seed."""

from __future__ import annotations

import math
from typing import Any

import pytest

from fdi.geodesy import LocalFrame
from firmware_host import cli
from firmware_host.devtools.rover_frozen import CurveScenario, generate_curves, score
from firmware_host.devtools.rover_harness import replay_stream
from firmware_host.runtime.config import load_config


def _rmc(data: bytes) -> list[str]:
    line = next(x for x in data.decode().split("\r\n") if x.startswith("$GPRMC"))
    return line.split("*")[0].split(",")


def test_the_receiver_freezes_whole_on_a_curved_path() -> None:
    run = list(generate_curves(CurveScenario(rate_hz=5.0, duration_s=300.0, seed=4)))
    truth = [tr for _, _, tr in run]
    events: dict[int, list[list[str]]] = {}
    for _, data, tr in run:
        if tr["fault"]:
            events.setdefault(tr["fault_event"], []).append(_rmc(data))
    assert len(events) >= 4
    for rmcs in events.values():  # position, speed and course repeated (time goes on)
        assert len({tuple(f[3:9]) for f in rmcs}) == 1 and len({f[1] for f in rmcs}) > 1
    moving = [tr["speed_true"] for tr in truth if tr["speed_true"] > 0.5]
    assert max(moving) <= 2.0 + 1e-9 and min(tr["speed_true"] for tr in truth) == 0.0
    turning = [abs(tr["turn_rate_dps"]) for tr in truth]
    assert sum(w > 3.0 for w in turning) > len(turning) / 3  # mostly in turns


def test_score_measures_the_excess_over_the_receiver_at_the_freeze() -> None:
    run = list(generate_curves(CurveScenario(rate_hz=1.0, duration_s=120.0, seed=2)))
    truth = [tr for _, _, tr in run]
    ref = truth[0]
    frame = LocalFrame(ref["true_lat"], ref["true_lon"], ref["true_alt"])
    epochs: list[dict[str, Any]] = []
    for tr in truth:  # the raw receiver 0.3 m east of the truth; the output 1.5 m north of
        # it from the freeze's third epoch, none at its fifth
        i = tr["k"] - min(t["k"] for t in truth if t["fault_event"] == tr["fault_event"]) if (
            tr["fault"]) else -1
        lat, lon, _ = frame.to_lla(tr["true_e"] + 0.3, tr["true_n"], tr["true_alt"])
        olat, olon, _ = frame.to_lla(tr["true_e"] + 0.3, tr["true_n"] + (1.5 if i >= 2 else 0),
                                     tr["true_alt"])
        epochs.append({"utc": tr["utc"], "raw_lat": lat, "raw_lon": lon, "fault": i >= 0,
                       "lat": None if i == 4 else olat, "lon": None if i == 4 else olon,
                       "action": "replace" if i >= 0 else "accept"})
    events = score(epochs, truth)
    assert events
    ev = events[0]
    assert abs(ev.e0_m - 0.3) < 1e-3 and ev.none == 1
    assert abs(ev.worst_excess_m - (math.hypot(0.3, 1.5) - 0.3)) < 1e-3
    assert ev.over == round(ev.duration_s) - 2 and ev.outputs == round(ev.duration_s) - 1


def test_the_default_preset_meets_the_bullet_on_a_seed() -> None:
    cfg = load_config("rover")
    events = []
    for rate in (1.0, 10.0):
        sc = CurveScenario(rate_hz=rate, duration_s=400.0, seed=3, model="coarse")
        events += score(*replay_stream(cfg, generate_curves(sc)))
    assert len(events) >= 12 and sum(e.max_turn_dps >= 3.0 for e in events) >= 6
    assert all(e.over == 0 and e.worst_excess_m <= 1.0 for e in events)
    assert all(e.none > 0 for e in events if e.duration_s > 2.0)  # past the coast: nothing


def test_the_command_prints_its_table_and_refuses_a_model_without_a_curved_drive(
        capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["sim", "rover-frozen", "--seeds", "1", "--rates", "1", "--duration",
                     "120", "--models", "dgps"]) == 0
    out = capsys.readouterr().out
    assert "worst excess m (seed)" in out and "dgps" in out
    assert cli.main(["sim", "rover-frozen", "--seeds", "1", "--models", "gm"]) == 2
    assert "--models: gm" in capsys.readouterr().err
