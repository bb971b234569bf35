"""The reference pages and the shape of ``docs/``.

Every configuration key has a doc, a unit (a number) and a range, as ArduPilot checks each
parameter's ``@Param`` block; ``docs/reference/*.md`` are what ``fdi-bridge docs`` writes now;
no page of ``docs/`` is over 600 lines or reads as a log of passes."""

from __future__ import annotations

import re
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Literal, get_type_hints

import pytest

from firmware_host.cli import main, parser_tree
from firmware_host.commands.docgen import COMMON, commands
from firmware_host.commands.reference import REGENERATE, lacks, missing, pages, tables

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
MAX_LINES = 600

# A page that states what is, not the order in which it was found: an ordinal before "pass",
# "tried, not kept" and its kin, a file named after an issue.
CHRONOLOGY = re.compile(
    r"\b(first|second|third|fourth|fifth|sixth|seventh|eighth|ninth|tenth|eleventh|twelfth|"
    r"thirteenth|fourteenth|fifteenth|sixteenth|seventeenth|eighteenth|nineteenth|twentieth|"
    r"\d+(st|nd|rd|th))[ -]pass\b"
    r"|\btried,? (but )?not (kept|landed|merged)\b|\bnot kept\b|\bnone kept\b",
    re.IGNORECASE)


def test_every_config_key_has_doc_unit_and_range() -> None:
    lacking = missing()
    assert not lacking, f"{len(lacking)} keys lack metadata:\n" + "\n".join(lacking)


def test_the_walk_reaches_every_section_and_detector() -> None:
    paths = {t.path for t in tables()}
    for section in ("rover", "rover.detector", "rover.detector.three_zone", "rover.port",
                    "rover.output", "rov", "rov.detector", "rov.ft", "rov.pid", "rov.link",
                    "rov.ardusub", "rov.sim", "insgnss", "mavlink", "mavlink.gcs",
                    "recorder"):
        assert section in paths, section
    n_keys = sum(len(t.keys) for t in tables())
    assert n_keys > 300  # the schema as it is (358 keys holding values or arrays of tables)


def test_a_key_without_metadata_is_reported() -> None:
    """The check itself: a key stripped of its doc, unit and bounds is named for each."""

    @dataclass(frozen=True)
    class Bare:
        gain: float = 1.0
        count: int | None = field(default=None, metadata={"doc": "a count"})
        mode: Literal["a", "b"] = "a"
        label: str = field(default="", metadata={"doc": "a label"})
        told: float = field(default=1.0, metadata={"doc": "a gain", "unit": "-", "ge": 0.0})

    hints = get_type_hints(Bare)
    found = {f.name: lacks(hints[f.name], f.metadata) for f in fields(Bare)}
    assert found == {"gain": ["doc", "unit", "range"], "count": ["unit", "range"],
                     "mode": ["doc"], "label": ["range"], "told": []}


@pytest.mark.parametrize("name", ["config.md", "cli.md"])
def test_committed_reference_is_current(name: str) -> None:
    committed = DOCS / "reference" / name
    assert committed.is_file(), f"{committed} missing: {REGENERATE}"
    assert committed.read_text(encoding="utf-8") == pages(parser_tree())[name], (
        f"docs/reference/{name} is stale: {REGENERATE}")


def test_config_reference_lists_every_key_with_its_default() -> None:
    text = pages(parser_tree())["config.md"]
    assert "| `alpha` | float | `0.05` | - | [1e-15, 0.5] |" in text
    assert "| `gate_sigmas` | float | `6.0` | σ | 0 or [1, 100] |" in text  # its documented off
    assert '| `strategy` | string | `"grey"` |  | "grey", "three_zone", "combined" |' in text
    for table in tables():
        for key in table.keys:
            assert f"| `{key.name}` |" in text


def test_cli_reference_has_every_command_and_option() -> None:
    text = pages(parser_tree())["cli.md"]
    for d in commands(parser_tree())[1:]:
        assert f"\n## fdi-bridge {d.path}\n" in text, d.path
        for o in d.positionals + d.options:
            if o.flags and not set(o.flags) & COMMON:
                assert f"| `{', '.join(o.flags)}` |" in text, (d.path, o.flags)
    assert "/work/" not in text and str(ROOT.parent) not in text  # the same on every machine


def test_docs_command_checks_and_writes(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["docs", "--out", str(tmp_path), "--check"]) == 1  # nothing written yet
    assert "is not current" in capsys.readouterr().out
    assert main(["docs", "--out", str(tmp_path)]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cli.md", "config.md"]
    assert main(["docs", "--out", str(tmp_path), "--check"]) == 0
    (tmp_path / "cli.md").write_text("old\n", encoding="utf-8")
    assert main(["docs", "--out", str(tmp_path), "--check"]) == 1


def _pages() -> list[Path]:
    return sorted(DOCS.rglob("*.md"))


def test_no_docs_page_is_over_600_lines() -> None:
    long = {p.relative_to(ROOT).as_posix(): n for p in _pages()
            if (n := len(p.read_text(encoding="utf-8").splitlines())) > MAX_LINES}
    assert not long, f"pages over {MAX_LINES} lines: {long}"


def test_no_docs_page_is_a_log_of_passes() -> None:
    hits = []
    for p in _pages():
        for i, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1):
            m = CHRONOLOGY.search(line)
            if m:
                hits.append(f"{p.relative_to(ROOT)}:{i}: {m.group(0)!r}")
    named = [p.name for p in _pages() if re.search(r"issue[-_]?\d+", p.name)]
    assert not hits and not named, "\n".join(hits + named)


@pytest.mark.parametrize("text", ["the sixteenth pass", "Fifth pass: the gyro", "(3rd pass)",
                                  "tried, not kept", "four variants tried, none kept"])
def test_the_chronology_pattern_finds_a_pass_log(text: str) -> None:
    assert CHRONOLOGY.search(text)


@pytest.mark.parametrize("text", ["a high-pass filter", "the fix passed on", "pass-through",
                                  "one pass over the data", "kept the first fix"])
def test_the_chronology_pattern_spares_ordinary_words(text: str) -> None:
    assert not CHRONOLOGY.search(text)


def test_links_between_docs_resolve() -> None:
    """A relative link from a page to another file of the repository names a file that
    exists (renamed pages leave no dead link)."""
    dead = []
    for p in [*_pages(), ROOT / "README.md"]:
        for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", p.read_text(encoding="utf-8")):
            if "://" in target or target.startswith("mailto:"):
                continue
            if not (p.parent / target).exists():
                dead.append(f"{p.relative_to(ROOT)} -> {target}")
    assert not dead, "\n".join(dead)
