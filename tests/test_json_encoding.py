"""The fast JSON Lines encoder (orjson, the ``fast`` extra) writes exactly what the standard
library writes: on random values, on the records of generated runs and on the corpus logs.

``epochs.jsonl`` is the replay contract: it must not change by a byte with the encoder.
"""

from __future__ import annotations

import io
import json
import math
import random
import struct
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware_host.commands.replay import load_input, replay_direct
from firmware_host.devtools.rover_sim import RoverScenario, write_run
from firmware_host.rover.pipeline import RoverPipeline
from firmware_host.runtime import records
from firmware_host.runtime.config import BridgeConfig, load_config
from firmware_host.runtime.records import encode_line, encode_line_stdlib

orjson = pytest.importorskip("orjson", reason="the fast extra (orjson) is not installed")

RUNS = [  # (seed, error model, rate Hz, duration s, GST, ZDA, fault kinds)
    (11, "gm", 10.0, 60.0, False, False, ("jump", "burst")),
    (12, "dgps", 5.0, 60.0, True, False, ("ramp", "frozen", "outage")),
    (13, "multipath", 10.0, 60.0, False, True, ("multipath", "jump")),
    (14, "coarse", 1.0, 200.0, True, True, ("jump", "burst", "ramp")),
]

scalars = (st.none() | st.booleans() | st.integers() | st.integers(-2**70, 2**70)
           | st.floats(allow_nan=True, allow_infinity=True) | st.floats(-1e-3, 1e-3)
           | st.floats(1e14, 1e18) | st.text(max_size=8))
values = st.recursive(scalars, lambda inner: st.lists(inner, max_size=4)
                      | st.dictionaries(st.text(max_size=6), inner, max_size=4), max_leaves=12)


@settings(max_examples=1500, deadline=None)
@given(st.dictionaries(st.text(max_size=10), values, max_size=8))
def test_fast_encoder_writes_what_json_writes(record: dict[str, Any]) -> None:
    assert encode_line(record) == encode_line_stdlib(record)


@settings(max_examples=3000, deadline=None)
@given(st.floats(allow_nan=True, allow_infinity=True))
def test_the_float_range_said_safe_is_spelled_alike(x: float) -> None:
    """The claim :func:`records._same_in_orjson` rests on, tested on orjson itself."""
    if records._same_in_orjson(x):
        assert orjson.dumps(x) == json.dumps(x).encode()
    else:
        assert x != 0.0 and not (1e-4 <= abs(x) < 1e16)


def test_values_orjson_spells_differently_take_the_standard_library() -> None:
    for rec in ({"x": 5e-05}, {"x": 1e-07}, {"x": math.nan}, {"x": -math.inf}, {"x": 2**70},
                {"s": "é"}, {"s": "\x7f"}, {"s": "a\nb"}, {"é": 1}, {"a": [1, {"b": 1e-9}]}):
        line = encode_line(rec)
        assert line == encode_line_stdlib(rec), rec
    assert encode_line({1: 2}) == '{"1":2}\n'  # a non-string key: json's conversion


def _records(inp: Path, cfg: BridgeConfig) -> tuple[list[dict[str, Any]], str]:
    out = io.StringIO()
    pipe = RoverPipeline(cfg.rover, jsonl=out)
    got: list[dict[str, Any]] = []
    process = pipe.process

    def keep(epoch: Any) -> Any:
        outcome = process(epoch)
        got.append(outcome.record)
        return outcome

    pipe.process = keep  # type: ignore[method-assign]
    replay_direct(load_input(inp), pipe)
    return got, out.getvalue()


def _check(recs: list[dict[str, Any]], text: str) -> int:
    """Every record's line as the standard library writes it; returns how many orjson wrote."""
    assert text == "".join(encode_line_stdlib(r) for r in recs)
    return sum(records._flat_same_in_orjson(r) for r in recs)


@pytest.mark.parametrize("run", RUNS, ids=lambda r: f"seed{r[0]}-{r[1]}")
def test_generated_runs_are_byte_identical(run: tuple[Any, ...], tmp_path: Path) -> None:
    seed, model, rate, dur, gst, zda, kinds = run
    write_run(RoverScenario(rate_hz=rate, duration_s=dur, seed=seed, error_model=model,
                            gst=gst, zda=zda, kinds=kinds), tmp_path)
    for cfg in (BridgeConfig(), load_config("rover-combined-paper")):
        recs, text = _records(tmp_path / "rover.nmea", cfg)
        assert len(recs) >= dur * rate * 0.9
        fast = _check(recs, text)
        assert fast >= 0.9 * len(recs)  # the fast encoder did the work, not the fallback


def test_corpus_logs_are_byte_identical(corpus: Path) -> None:
    logs = sorted((corpus / "gpsd").glob("*.log")) + sorted((corpus / "ardusub").glob("nmea*"))
    assert len(logs) >= 17
    total = fast = 0
    for log in logs:
        recs, text = _records(log, BridgeConfig())
        fast += _check(recs, text)
        total += len(recs)
    assert total > 1000 and fast >= 0.9 * total


def test_without_orjson_the_file_is_the_same(tmp_path: Path, monkeypatch: pytest.MonkeyPatch
                                              ) -> None:
    write_run(RoverScenario(rate_hz=10.0, duration_s=30.0, seed=21), tmp_path)
    _, fast_text = _records(tmp_path / "rover.nmea", BridgeConfig())
    monkeypatch.setattr(records, "_orjson", None)
    _, slow_text = _records(tmp_path / "rover.nmea", BridgeConfig())
    assert fast_text == slow_text and fast_text


@settings(max_examples=3000, deadline=None)
@given(st.lists(st.none() | st.floats(allow_nan=True, allow_infinity=True)
                | st.floats(-1e-3, 1e-3) | st.floats(1e14, 1e18) | st.integers(-2**70, 2**70),
                max_size=6))
def test_numbers_said_alike_are_what_the_full_test_says(values: list[Any]) -> None:
    """The pipeline's own test of its numbers is the full test's on floats and None; an
    integer it may refuse (from 1e16 on) where the full test would not (never the reverse)."""
    full = all(records._same_in_orjson(v) for v in values)
    if all(type(v) is not int for v in values):
        assert records.numbers_spelled_alike(values) == full
    elif records.numbers_spelled_alike(values):
        assert full


def _plain_flags(inp: Path, cfg: BridgeConfig) -> tuple[list[tuple[dict[str, Any], bool]], str]:
    out = io.StringIO()
    pipe = RoverPipeline(cfg.rover, jsonl=out)
    got: list[tuple[dict[str, Any], bool]] = []
    make = pipe._record

    def keep(*args: Any) -> tuple[dict[str, Any], bool]:
        rec, plain = make(*args)
        got.append((rec, plain))
        return rec, plain

    pipe._record = keep  # type: ignore[method-assign]
    replay_direct(load_input(inp), pipe)
    return got, out.getvalue()


@pytest.mark.parametrize("run", RUNS[:2], ids=lambda r: f"seed{r[0]}-{r[1]}")
def test_records_the_pipeline_calls_plain_pass_the_full_test(run: tuple[Any, ...],
                                                             tmp_path: Path) -> None:
    """The rover pipeline checks its records itself (cheaper: it knows their fields); a
    record it calls plain passes :func:`records._flat_same_in_orjson`, and most are plain."""
    seed, model, rate, dur, gst, zda, kinds = run
    write_run(RoverScenario(rate_hz=rate, duration_s=dur, seed=seed, error_model=model,
                            gst=gst, zda=zda, kinds=kinds), tmp_path)
    for cfg in (BridgeConfig(), load_config("rover-combined-paper")):
        got, text = _plain_flags(tmp_path / "rover.nmea", cfg)
        assert text == "".join(encode_line_stdlib(r) for r, _ in got)
        assert all(records._flat_same_in_orjson(r) for r, plain in got if plain)
        if cfg.rover.detector.strategy == "grey":
            assert sum(plain for _, plain in got) >= 0.9 * len(got)


def test_a_fix_near_longitude_zero_is_not_plain(tmp_path: Path) -> None:
    """0.3 thousandths of a minute east of Greenwich: 5e-06 degrees, which orjson spells
    0.000005 and json 5e-06: the pipeline's test sends that record to the standard library."""
    from drivers.gps.nmea import with_checksum

    lines = b"".join(
        with_checksum(f"GPGGA,1000{s:02d}.00,5130.00000000,N,00000.0003,E,1,09,0.9,10.0,M,"
                      "47.0,M,,")
        + with_checksum(f"GPRMC,1000{s:02d}.00,A,5130.00000000,N,00000.0003,E,0.0,0.0,120510,,"
                        ",A")
        for s in range(5))
    (tmp_path / "greenwich.nmea").write_bytes(lines)
    got, text = _plain_flags(tmp_path / "greenwich.nmea", BridgeConfig())
    assert got and text == "".join(encode_line_stdlib(r) for r, _ in got)
    assert all(r["raw_lon"] == 0.0003 / 60.0 and not plain for r, plain in got)
    assert '"raw_lon":4.9999999999999996e-06,' in text  # json's spelling


def _bits(x: Any) -> Any:
    return (type(x), struct.pack("<d", x)) if isinstance(x, float) else (type(x), x)


def test_round4_and_round2_are_round_bit_for_bit() -> None:
    """The records' rounding (records.round4/round2) gives round()'s float, sign of zero
    and NaN included: on ties and near-ties at every scale, random doubles of every
    exponent, small values of both signs, and integers."""
    rng = random.Random(19)
    cases: list[Any] = [0.0, -0.0, math.nan, math.inf, -math.inf, 5e-324, -5e-324, 1e300, 5, -3,
                        0, True, 214748.3647, 214748.36475, -214748.36475, 21474836.47,
                        21474836.475, 0.00005, -0.00005, 0.005, -0.005, 1.00005, 18.81245]
    for _ in range(400_000):
        k = rng.random()
        if k < 0.25:
            x = rng.uniform(-200.0, 200.0)
        elif k < 0.45:  # ties and near-ties of 4 and 2 decimals
            x = (rng.randrange(-10**9, 10**9) + rng.choice([0.5, -0.5, 0.4999, 0.50001])
                 ) / rng.choice([10000.0, 100.0])
        elif k < 0.65:
            x = struct.unpack("<d", rng.randbytes(8))[0]
        elif k < 0.8:
            x = rng.uniform(-1e-3, 1e-3)
        else:
            x = rng.uniform(-3e7, 3e7)
        cases.append(x)
    for x in cases:
        assert _bits(records.round4(x)) == _bits(round(x, 4)), repr(x)
        assert _bits(records.round2(x)) == _bits(round(x, 2)), repr(x)


@settings(max_examples=5000, deadline=None)
@given(st.floats(allow_nan=True, allow_infinity=True) | st.floats(-1e5, 1e5))
def test_round4_and_round2_on_any_float(x: float) -> None:
    assert _bits(records.round4(x)) == _bits(round(x, 4))
    assert _bits(records.round2(x)) == _bits(round(x, 2))


@settings(max_examples=3000, deadline=None)
@given(st.lists(st.none() | st.floats(allow_nan=True, allow_infinity=True)
                | st.floats(-1e-3, 1e-3) | st.floats(-3e5, 3e5) | st.floats(1e14, 1e18)
                | st.integers(-2**70, 2**70) | st.sampled_from([0.00005, -0.00005, 214748.36475]),
                max_size=20))
def test_round4_all_is_round4_and_says_plain_as_the_number_test(values: list[Any]) -> None:
    """The pipeline's one rounding call: each value as :func:`records.round4` rounds it (bit
    for bit), and plain exactly when :func:`records.numbers_spelled_alike` passes them."""
    rounded, plain = records.round4_all(values)
    assert [_bits(v) for v in rounded] == [
        _bits(None if x is None else records.round4(x)) for x in values]
    assert plain == records.numbers_spelled_alike(rounded)
