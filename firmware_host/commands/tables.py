"""One output style for humans: aligned tables with units and sensible rounding.

Commands print results through these helpers (machines use ``--json``):

* :func:`fmt` rounds a number to three significant digits, never in exponent form, with no
  trailing noise (``0.6202000000000112`` -> ``0.62``, ``1714.7`` -> ``1715``); ``None`` and NaN
  print as ``-``;
* :func:`table` aligns columns under their labels, numbers to the right;
* :func:`fields` is a two-column table of labelled values with their units (a summary).
"""

from __future__ import annotations

import math
import shutil
import sys
from collections.abc import Mapping, Sequence
from typing import Any

DASH = "-"


def fmt(value: Any, digits: int = 3) -> str:
    """``value`` for a human: numbers to ``digits`` significant digits (integers as they are)."""
    if value is None:
        return DASH
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return DASH
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        if value == 0.0:
            return "0"
        decimals = max(0, digits - 1 - math.floor(math.log10(abs(value))))
        text = f"{value:.{decimals}f}"
        if "." in text:
            text = text.rstrip("0").rstrip(".")
        return "0" if text in ("-0", "") else text
    if isinstance(value, Mapping):
        return ", ".join(f"{k} {fmt(v, digits)}" for k, v in value.items()) or DASH
    if isinstance(value, list | tuple):
        return ", ".join(fmt(v, digits) for v in value) or DASH
    return str(value)


def _is_number(cell: Any) -> bool:
    return isinstance(cell, int | float) and not isinstance(cell, bool)


def table(headers: Sequence[str], rows: Sequence[Sequence[Any]], *, digits: int = 3,
          indent: str = "") -> str:
    """Rows under their column labels, each column as wide as its widest cell; numbers are
    right-aligned, text left-aligned. Cells are formatted with :func:`fmt`."""
    cells = [[fmt(c, digits) for c in row] for row in rows]
    numeric = [bool(rows) and all(_is_number(r[i]) or r[i] is None for r in rows)
               for i in range(len(headers))]
    widths = [max([len(h), *(len(r[i]) for r in cells)]) for i, h in enumerate(headers)]

    def line(items: Sequence[str], label: bool = False) -> str:
        parts = [it.rjust(w) if numeric[i] and not (label and i == 0) else it.ljust(w)
                 for i, (it, w) in enumerate(zip(items, widths, strict=True))]
        return (indent + "  ".join(parts)).rstrip()

    return "\n".join([line(list(headers), label=True), *(line(r) for r in cells)])


def fields(rows: Sequence[tuple[str, Any, str]], *, digits: int = 3, indent: str = "") -> str:
    """A summary: ``label  value unit`` per row; labels aligned, numbers right-aligned in one
    column, text values starting where that column starts."""
    if not rows:
        return ""
    labels = max(len(r[0]) for r in rows)
    values = [fmt(r[1], digits) for r in rows]
    width = max([1, *(len(v) for r, v in zip(rows, values, strict=True) if _is_number(r[1]))])
    out = []
    for (label, value, unit), text in zip(rows, values, strict=True):
        cell = text.rjust(width) if _is_number(value) or value is None else text
        out.append(f"{indent}{label.ljust(labels)}  {cell} {unit}".rstrip())
    return "\n".join(out)


# Key suffixes that carry the unit (``duration_s``, ``max_abs_err_deg``, ``first_fault_t``).
_UNITS = (("_deg", "deg"), ("_ms", "ms"), ("_s", "s"), ("_t", "s"), ("_m", "m"), ("_hz", "Hz"),
          ("_pct", "%"))


def summary_rows(summary: Mapping[str, Any]) -> list[tuple[str, Any, str]]:
    """A flat summary dictionary as :func:`fields` rows: ``first_fault_t`` ->
    ``("first fault", 70.6, "s")``; nested dictionaries as ``key value, ...``."""
    rows = []
    for key, value in summary.items():
        unit = ""
        for suffix, name in _UNITS:
            if key.endswith(suffix):
                key, unit = key[: -len(suffix)], name
                break
        rows.append((key.replace("_", " "), value, unit))
    return rows


def jsonable(value: Any) -> Any:
    """``value`` for ``json.dumps``: NaN and infinities (nothing measured) as ``null``,
    tuples as lists, recursively."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, Mapping):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [jsonable(v) for v in value]
    return value


# --------------------------------------------------------------------------- reports

#: Markdown emphasis and code marks, dropped on the console (``**best**`` -> ``best``).
_MARKS = ("**", "`")


def plain(text: str) -> str:
    """A line of Markdown text as the console shows it: no heading ``#``, bold or code marks,
    no ``*emphasis*`` around a whole cell."""
    stripped = text.lstrip("#")
    if stripped != text and stripped.startswith(" "):
        text = stripped[1:]
    for mark in _MARKS:
        text = text.replace(mark, "")
    if len(text) > 2 and text[0] == "*" and text[-1] == "*" and "*" not in text[1:-1]:
        text = text[1:-1]
    return text


class Table:
    """One table of a report, rendered as Markdown for a file (:meth:`markdown`) or aligned for
    the console (:meth:`console`, as :func:`table`). ``right`` names the columns right-aligned
    in the Markdown (``---:``); on the console the columns of numbers are right-aligned, text
    left-aligned. Cells are preformatted text (the report's own rounding) or numbers
    (:func:`fmt`)."""

    def __init__(self, headers: Sequence[str], right: Sequence[int] = (), keep: int = 1
                 ) -> None:
        self.headers = list(headers)
        self.right = set(right)
        self.keep = keep  # key columns repeated when a wide table is wrapped (console)
        self.rows: list[list[Any]] = []

    def add(self, *cells: Any) -> None:
        if len(cells) != len(self.headers):
            raise ValueError(f"{len(cells)} cells for {len(self.headers)} columns")
        self.rows.append(list(cells))

    def markdown(self) -> str:
        def line(cells: Sequence[Any]) -> str:
            return "|" + "|".join(f" {c} " if c != "" else " "
                                  for c in (fmt(x) if not isinstance(x, str) else x
                                            for x in cells)) + "|"

        sep = "|" + "".join("---:|" if i in self.right else "---|"
                            for i in range(len(self.headers)))
        return "\n".join([line(self.headers), sep, *(line(r) for r in self.rows)])

    def console(self, indent: str = "", width: int | None = None) -> str:
        """Aligned columns. A table wider than ``width`` (default: the terminal's, when
        standard output is one; never wrapped into a pipe or file) is printed as several, each
        repeating the first :attr:`keep` (key) columns, as pandas wraps a wide frame."""
        cells = [[plain(fmt(c)) for c in row] for row in self.rows]
        right = [bool(self.rows) and all(
            _is_number(r[i]) or r[i] is None or _looks_numeric(r[i]) for r in self.rows)
            for i in range(len(self.headers))]
        widths = [max([len(h), *(len(r[i]) for r in cells)])
                  for i, h in enumerate(self.headers)]
        if width is None and sys.stdout.isatty():
            width = shutil.get_terminal_size((120, 24)).columns

        def line(items: Sequence[str], cols: Sequence[int]) -> str:
            parts = [items[i].rjust(widths[i]) if right[i] else items[i].ljust(widths[i])
                     for i in cols]
            return (indent + "  ".join(parts)).rstrip()

        groups = _column_groups(widths, width - len(indent) if width else None, self.keep)
        return "\n\n".join("\n".join([line(self.headers, g), *(line(r, g) for r in cells)])
                           for g in groups)


def _column_groups(widths: Sequence[int], width: int | None, keep: int = 1
                   ) -> list[list[int]]:
    """Columns in groups that fit ``width`` (2 spaces between), each starting with the first
    ``keep`` columns; one group when ``width`` is None or the table fits."""
    everything = list(range(len(widths)))
    keep = max(0, min(keep, len(widths) - 1))
    if width is None or sum(widths) + 2 * (len(widths) - 1) <= width:
        return [everything]
    head = everything[:keep]
    head_w = sum(widths[:keep]) + 2 * max(0, keep - 1)
    groups: list[list[int]] = []
    group, used = list(head), head_w
    for i in everything[keep:]:
        if len(group) > keep and used + 2 + widths[i] > width:
            groups.append(group)
            group, used = list(head), head_w
        group.append(i)
        used += 2 + widths[i] if group[:-1] else widths[i]
    groups.append(group)
    return groups


def _looks_numeric(cell: Any) -> bool:
    """A preformatted number (``"0.35"``, ``"-"`` for none), right-aligned like one."""
    if not isinstance(cell, str):
        return False
    if cell in (DASH, "–", ""):
        return True
    try:
        float(cell)
    except ValueError:
        return False
    return True


Block = str | Table


def report_markdown(blocks: Sequence[Block]) -> str:
    """A report (lines of Markdown text and tables) as Markdown, one block a line."""
    return "\n".join(b.markdown() if isinstance(b, Table) else b for b in blocks)


def report_console(blocks: Sequence[Block]) -> str:
    """The same report for the console: aligned tables, text without Markdown marks."""
    return "\n".join(b.console() if isinstance(b, Table) else plain(b) for b in blocks)
