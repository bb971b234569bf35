"""Issue G's whole fault stream through the live INS/GNSS vehicle, at rest (jumps, bursts,
walks at zero speed, a 20 s outage; ArduPilot's gyro drift; a DGPS receiver's error), beside
the plain rover detector on the same epochs (firmware_host/devtools/insgnss_field.py, real
ptys), seed 1 with the filter configured for the receiver (its correlated error as the
filter's Gauss-Markov state, fdi/insgnss.py (G1)-(G6)): the INS's output is never further from
the truth than the rover's by more than 0.5 m (0.18 m); while it coasts its error is at most
twice the accuracy it sends; past the coast limit it sends no-fix.

Not every seed meets the 0.5 m (docs/insgnss-live.md, "The field's fault stream at rest";
``python -m firmware_host.devtools.insgnss_field --seeds 1-24 --oracle``): seeds 1-24 worst
0.51 m (seed 8), held-out seeds 101-124 worst 0.58 m (seed 101, 1 of 24 above 0.5), where a
filter told every fault is 0.45 m and 0.66 m worse than the rover (the walk carrying the
receiver's fix across the truth); seeds 125-148 0.56 m (seed 125; that filter 0.58 m); the
example's white R of 3 m: 1.01 m (seed 22). The coast's check holds on all 72."""

from __future__ import annotations

from pathlib import Path

from firmware_host.devtools import insgnss_field as field


def test_the_field_stream_through_the_ins_is_never_worse_than_the_rover(
        tmp_path: Path) -> None:
    setup = field.field_setup()  # the filter configured for the simulated DGPS receiver
    assert setup.filter.gnss_gm_sigma_m == field.GM_SIGMA_M[0]
    fr = field.compare_field(setup, 1, tmp_path)
    assert fr.run.summary["ins"]["alignment"]["method"] == "attitude"
    excess = fr.excess()
    assert len(excess) >= 240
    worst = max(excess, key=lambda x: x[1])
    assert worst[1] <= 0.5, worst
    faulty = [e for e in fr.epochs if e.rover_err_m is not None and e.rover_err_m > 2.0]
    assert faulty, "the stream's faults moved the rover's output"
    coast = [e for e in fr.epochs if e.coast_s is not None]
    assert len(coast) == 20
    sent = [e for e in coast if e.ins_err_m is not None]
    assert 9 <= len(sent) <= 11
    for e in sent:
        assert e.acc_h_m is not None and e.ins_err_m is not None
        assert e.ins_err_m <= 2.0 * e.acc_h_m, (e.t, e.ins_err_m, e.acc_h_m)
    assert all(e.ins_err_m is None for e in coast[len(sent):])  # then no-fix
    assert fr.run.summary["ins"]["coast_no_fix"] == len(coast) - len(sent)
