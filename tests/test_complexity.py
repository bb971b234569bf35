"""No function in fdi/ above cyclomatic complexity 25 (radon cc) nor above 80 lines (issue 42).

The estimators are read against their papers; a function past these sizes is no longer read.
``KNOWN`` lists the functions outside the rover isolator that were over a limit when the test
was written, with the size they had then: they may shrink (and must leave the list once within
both limits), never grow. Regenerate the numbers with
``radon cc -s -n D fdi/`` (complexity) and this file's ``_sizes`` (lines).
"""

from __future__ import annotations

from pathlib import Path

import pytest

radon_complexity = pytest.importorskip("radon.complexity", reason="radon (the test extra)")

FDI = Path(__file__).resolve().parent.parent / "fdi"
MAX_CC = 25
MAX_LINES = 80
# (file, function): (complexity, lines) when this test was written
KNOWN: dict[tuple[str, str], tuple[int, int]] = {
}


def _sizes() -> dict[tuple[str, str], tuple[int, int]]:
    """Every function and method of fdi/: (complexity, lines)."""
    out: dict[tuple[str, str], tuple[int, int]] = {}
    for path in sorted(FDI.glob("*.py")):
        for block in radon_complexity.cc_visit(path.read_text(encoding="utf-8")):
            if block.letter == "C":  # a class: its methods are listed on their own
                continue
            out[(path.name, block.fullname)] = (block.complexity,
                                                block.endline - block.lineno + 1)
    return out


def test_no_function_in_fdi_over_the_limits() -> None:
    over = {key: size for key, size in _sizes().items()
            if (size[0] > MAX_CC or size[1] > MAX_LINES) and key not in KNOWN}
    assert not over, f"over complexity {MAX_CC} or {MAX_LINES} lines: {over}"


def test_known_functions_do_not_grow_and_leave_the_list_once_within() -> None:
    sizes = _sizes()
    for key, (cc, lines) in KNOWN.items():
        assert key in sizes, f"{key} no longer exists: remove it from KNOWN"
        now = sizes[key]
        assert now[0] <= cc and now[1] <= lines, f"{key} grew: {now} against {(cc, lines)}"
        assert now[0] > MAX_CC or now[1] > MAX_LINES, f"{key} is within the limits: remove it"


def test_the_rover_isolator_and_its_hold_are_within_the_limits() -> None:
    sizes = _sizes()
    ours = {key: size for key, size in sizes.items()
            if key[0] in ("rover.py", "rover_rules.py", "rover_evidence.py", "level.py")}
    assert ("rover.py", "RoverIsolator._step") in ours and ("level.py", "LevelHold.step") in ours
    assert max(cc for cc, _ in ours.values()) <= MAX_CC
    assert max(n for _, n in ours.values()) <= MAX_LINES
