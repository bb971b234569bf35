"""``fdi-bridge fuzz --pipeline`` (issue 43, item 2): the whole pipeline, as ``replay`` feeds it
(framer, codec, epoch builder, detector, records, NMEA and MAVLink outputs), on checksum-valid
sentences with mutated fields. Seeded and short here; the long run's figures are in the
commit that added it.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from firmware_host import cli
from firmware_host.devtools.fuzz import NOT_NUMBERS, field_table, run_pipeline_fuzz

# The numeric fields of the sentences the rover's detector reads (indices after the address).
DETECTOR_FIELDS = {
    "GGA": (0, 1, 3, 5, 6, 7, 8, 10, 12, 13),
    "RMC": (0, 2, 4, 6, 7, 8, 9),
    "VTG": (0, 2, 4, 6),
    "GST": (0, 1, 2, 3, 4, 5, 6, 7),
}


def test_1e308_nan_inf_in_each_numeric_field_is_rejected_and_counted() -> None:
    """Each put once into a clean session through the pipeline: counted as exactly one
    ``bad_field`` (before: 1e308 passed in 30 of the 56 fields, in GST's sigmas and VTG's
    km/h it crashed the detector, and nan and inf passed in the fields the bridge does not
    read)."""
    table = field_table(seed=0)
    expected = {f"{kind}[{i}]={v}" for kind, idx in DETECTOR_FIELDS.items() for i in idx
                for v in NOT_NUMBERS}
    assert expected <= set(table)
    assert {k: v for k, v in table.items() if v != "bad_field"} == {}
    assert len(table) == 168  # every supported sentence's numeric fields x 3 values


def test_short_seeded_pipeline_fuzz_has_no_exception() -> None:
    rep = run_pipeline_fuzz(max_inputs=4000, seed=1)
    assert rep["inputs"] == 4000
    assert rep["exceptions"] == 0, rep["examples"]
    assert rep["invariant_failures"] == 0, rep["examples"]
    # The mutations reach both sides: refused by reason, and accepted (in-range values).
    assert rep["refused"] > 2000 and rep["accepted"] > 300, rep
    assert rep["rejects"]["bad_field"] > 1500 and rep["rejects"]["short"] > 0, rep["rejects"]


def test_fuzz_pipeline_command(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "fuzz.json"
    assert cli.main(["fuzz", "--pipeline", "-n", "300", "--seed", "2", "--json",
                     "--out", str(out)]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep == json.loads(out.read_text())
    assert rep["inputs"] == 300 and rep["exceptions"] == 0 and rep["failures"] == 0
    assert rep["fields"] == {"cases": 168, "rejected_as_bad_field": 168, "missed": {}}
