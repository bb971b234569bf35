"""The one replay driver (:mod:`firmware_host.runtime.replay`) and ``replay --no-records``.

Every replay (rover, Outland ROV, ArduSub ROV, INS/GNSS) runs on
:class:`~firmware_host.runtime.replay.ReplayDriver`. Here: its pacing on the fake clock, its
handling of a stop signal, and that ``--no-records`` writes no ``epochs.jsonl`` and the same
``summary.json`` (the rover's timing fields apart, which differ between any two runs) for the
rover, the Outland ROV and the ArduSub ROV. Byte-identity of ``epochs.jsonl`` with the
previous replay loops is ``tools/replay_identity.py`` and the vehicles' own replay tests.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Literal

import pytest

from firmware_host.cli import main
from firmware_host.devtools.rover_sim import RoverScenario, generate
from firmware_host.rov.ardusub import ArduSubRovVehicle
from firmware_host.rov.base import RovVehicleBase
from firmware_host.rov.vehicle import OutlandRovVehicle
from firmware_host.runtime.replay import ReplayDriver, TxCheck
from firmware_host.runtime.vehicle import Context
from tests.test_rov_replay import _live

ROOT = Path(__file__).resolve().parents[1]
SITL = ROOT.parent / "shared" / "corpus" / "ardusub-sitl"
TIMING = ("processing_ms", "overruns", "wall_s", "epochs_per_s")  # the rover's, per run


class Probe:
    """A vehicle that writes down what the driver did to it (times, checks, finish)."""

    name = "probe"

    def __init__(self, pacing: Literal["period", "data"], stop_at: float | None = None) -> None:
        self.pacing = pacing
        self.stop_at = stop_at  # a stop signal arrives during the step at this time
        self.clock: Any = None
        self.log: list[tuple[str, float]] = []

    def start(self, ctx: Context) -> None:
        self.clock = ctx.clock
        self.epochs = ctx.epochs
        self.log.append(("start", ctx.clock()))

    def step(self, t: float) -> int:
        self.log.append(("step", t))
        if t == self.stop_at:
            raise KeyboardInterrupt  # as signals_interrupt raises it for SIGTERM
        self.epochs.write({"t": t, "clock": self.clock()})
        self.clock.advance(0.5)  # a read that waited out its timeout
        return 1

    def check(self, now: float) -> None:
        self.log.append(("check", now))

    def finish(self) -> None:
        self.log.append(("finish", self.clock()))

    def summary(self) -> dict[str, Any]:
        return {"steps_seen": sum(1 for k, _ in self.log if k == "step")}


def _lines(path: Path) -> list[dict[str, Any]]:
    return [json.loads(x) for x in path.read_text().splitlines()]


def test_period_vehicle_steps_at_the_recorded_times(tmp_path: Path) -> None:
    """Deadline pacing: the clock is set to each recorded time, even behind where a step's
    read left it (the next step starts at its own deadline)."""
    v = Probe("period")
    d = ReplayDriver(tmp_path)
    d.run(v, [0.0, 0.2, 0.4], start=lambda: v.start(Context(d.clock, {}, d.epochs)))
    assert [t for k, t in v.log if k == "step"] == [0.0, 0.2, 0.4]
    assert [(r["t"], r["clock"]) for r in _lines(tmp_path / "epochs.jsonl")] == [
        (0.0, 0.0), (0.2, 0.2), (0.4, 0.4)]
    assert [t for k, t in v.log if k == "check"] == [0.5, 0.7, 0.9]  # after each step's read
    assert v.log[-1][0] == "finish" and d.steps == 3 and d.epochs.lines == 3


def test_data_vehicle_clock_never_goes_back(tmp_path: Path) -> None:
    """Data pacing: a step runs at the clock, which a recorded time earlier than where the
    last read left it does not move back."""
    v = Probe("data")
    d = ReplayDriver(tmp_path)
    d.run(v, [0.0, 0.2, 1.0], start=lambda: v.start(Context(d.clock, {}, d.epochs)))
    assert [t for k, t in v.log if k == "step"] == [0.0, 0.5, 1.0]


def test_a_stop_signal_finishes_and_marks_the_summary_partial(tmp_path: Path) -> None:
    """A signal during a step: the recording's inputs (a pty) are closed, then the vehicle
    finishes, and the summary says it is partial."""

    def steps(v: Probe) -> Any:
        try:
            yield from (0.0, 1.0, 2.0)
        finally:
            v.log.append(("inputs closed", 0.0))

    v = Probe("data", stop_at=1.0)
    d = ReplayDriver(tmp_path)
    d.run(v, steps(v), start=lambda: v.start(Context(d.clock, {}, d.epochs)))
    assert [k for k, _ in v.log] == ["start", "step", "check", "step", "inputs closed", "finish"]
    s = d.write_summary(d.summary(v.summary(), config="c", input={"kind": "probe"}, facts={}))
    assert s["partial"] is True and s["interrupted_by"] == "SIGINT" and s["epochs"] == 1
    assert json.loads((tmp_path / "summary.json").read_text()) == s
    # A caller's own loop (a benchmark) gets the signal instead, with nothing finished.
    v2 = Probe("data", stop_at=1.0)
    d2 = ReplayDriver(None, partial_on_signal=False)
    with pytest.raises(KeyboardInterrupt):
        d2.run(v2, steps(v2), start=lambda: v2.start(Context(d2.clock, {}, d2.epochs)))
    assert [k for k, _ in v2.log] == ["start", "step", "check", "step", "inputs closed"]


def test_summary_order_and_tx_check(tmp_path: Path) -> None:
    tx = TxCheck()
    tx.compare(0, b"a", b"a")
    tx.compare(1, b"b", b"c")
    tx.compare(2, b"d", b"e")
    assert tx.facts() == {"tx_steps_same": 1, "tx_steps_differ": 2,
                          "tx_first_differ_step": 1, "tx_match": False}
    d = ReplayDriver(tmp_path)
    s = d.summary({"actions": {}, "input": {"bytes_in": 3}}, vehicle="v", config="c",
                  input={"file": "f"}, facts={"steps": 0})
    assert list(s) == ["actions", "input", "vehicle", "config", "epochs", "replay"]
    assert s["input"] == {"file": "f"}  # the replay's input replaces the vehicle's
    s = d.summary({"epochs": 7, "input": {"bytes_in": 3}}, config="c", input={"file": "f"},
                  facts={"pty": False}, facts_key="transport", count_records=False,
                  add_to_input=True)
    assert s == {"epochs": 7, "input": {"bytes_in": 3, "file": "f"}, "config": "c",
                 "transport": {"pty": False}}


def test_the_rov_vehicles_share_one_base() -> None:
    """check/idle_s/finish/summary are written once, in RovVehicleBase."""
    for cls in (OutlandRovVehicle, ArduSubRovVehicle):
        assert issubclass(cls, RovVehicleBase)
        for name in ("check", "idle_s", "finish", "summary", "_mark", "_account"):
            assert name not in vars(cls), (cls.__name__, name)


# ------------------------------------------------------------------ --no-records


def _replay_twice(tmp_path: Path, *args: str) -> tuple[dict[str, Any], dict[str, Any]]:
    """The replay with records, then into a directory holding a stale epochs.jsonl with
    ``--no-records``; returns both summaries (as written)."""
    full, bare = tmp_path / "full", tmp_path / "bare"
    assert main(["replay", *args, "--out", str(full)]) == 0
    bare.mkdir()
    (bare / "epochs.jsonl").write_text("{}\n")  # an earlier run's: must not pass for this one
    assert main(["replay", *args, "--out", str(bare), "--no-records"]) == 0
    assert (full / "epochs.jsonl").stat().st_size > 0
    assert sorted(p.name for p in bare.iterdir()) == ["summary.json"]
    return (json.loads((full / "summary.json").read_text()),
            json.loads((bare / "summary.json").read_text()))


@pytest.mark.parametrize("pty", [True, False], ids=["pty", "no-pty"])
def test_rover_summary_is_the_same_without_records(tmp_path: Path, pty: bool,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    log = tmp_path / "in.nmea"
    log.write_bytes(b"".join(d for _, d, _ in generate(
        RoverScenario(rate_hz=10.0, duration_s=60.0, seed=3))))
    a, b = _replay_twice(tmp_path, str(log), "--config", "rover",
                         *(() if pty else ("--no-pty",)))
    assert a["epochs"] == 600 and a["faults"] > 0  # the run had something to find
    for key in TIMING:
        assert key in a and key in b
        a.pop(key), b.pop(key)
    assert a == b and list(a) == list(b)
    out = capsys.readouterr().out
    assert "no epochs.jsonl: --no-records" in out


def test_rov_summary_is_the_same_without_records(tmp_path: Path) -> None:
    cfg, cap, _ = _live(tmp_path, "rs485")
    full, bare = tmp_path / "full", tmp_path / "bare"
    args = ["replay", str(cap), "--config", str(cfg)]
    assert main([*args, "--out", str(full)]) == 0
    assert main([*args, "--out", str(bare), "--no-records"]) == 0
    assert not (bare / "epochs.jsonl").exists()
    assert (bare / "summary.json").read_bytes() == (full / "summary.json").read_bytes()
    assert json.loads((bare / "summary.json").read_text())["epochs"] >= 20


@pytest.mark.skipif(not (SITL / "raw.cap").exists(),
                    reason="the ArduSub SITL corpus (../shared/corpus/ardusub-sitl) is absent")
def test_ardusub_summary_is_the_same_without_records(tmp_path: Path) -> None:
    full, bare = tmp_path / "full", tmp_path / "bare"
    args = ["replay", str(SITL / "raw.cap"), "--config", str(SITL / "raw.toml")]
    assert main([*args, "--out", str(full)]) == 0
    assert main([*args, "--out", str(bare), "--no-records"]) == 0
    assert not (bare / "epochs.jsonl").exists()
    assert (bare / "summary.json").read_bytes() == (full / "summary.json").read_bytes()
    s = json.loads((full / "summary.json").read_text())
    assert s["epochs"] == (full / "epochs.jsonl").read_bytes().count(b"\n") > 100
