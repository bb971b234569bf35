"""``fdi-bridge docs``: the reference pages, generated from the code (``docs/reference/``).

``config.md`` walks the configuration schema from :class:`~firmware_host.runtime.config.BridgeFile`
down (every table, every key a file may set) and writes each key's type, default, unit, range and
doc from the dataclass field: the type from its hint, the default from the section's own default
object (a nested table's default is its parent's), the range from the bounds the loader checks
(``ge``/``gt``/``le``/``lt``/``ne``/``off``, :mod:`drivers.configload`), a ``Literal``'s values,
a URL field's kind (:data:`~firmware_host.runtime.config.URL_KINDS`), or the field's ``choices``
or ``range`` metadata; the unit and the doc from ``metadata["unit"]`` and ``metadata["doc"]``.
``cli.md`` is the command line's own parser (:func:`firmware_host.commands.docgen.cli_reference`).

:func:`missing` lists the keys without a doc, a unit (numbers) or a range, which a test keeps
empty, as ArduPilot checks every parameter's ``@Param`` block.
"""

from __future__ import annotations

import argparse
import dataclasses
import re
import sys
import types
import typing
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, get_args, get_origin, get_type_hints

from drivers.configload import MAX_MAGNITUDE, toml_fields
from firmware_host.commands.docgen import ParserTree, cli_reference
from firmware_host.runtime import config

REGENERATE = "fdi-bridge docs --out docs/reference"


@dataclass(frozen=True)
class Key:
    """One key of a table as the reference shows it."""

    name: str
    type: str
    default: str
    unit: str
    range: str
    doc: str


@dataclass(frozen=True)
class Table:
    """One TOML table (``[rover.detector]``) with its keys."""

    path: str
    array: bool  # [[path]]: an array of tables
    cls: type[Any]
    doc: str
    keys: list[Key]


# --------------------------------------------------------------------------- the schema walk


def _strip_optional(tp: Any) -> tuple[Any, bool]:
    if get_origin(tp) in (typing.Union, types.UnionType):
        args = [a for a in get_args(tp) if a is not type(None)]
        if len(args) == 1:
            return args[0], True
    return tp, False


def _item(tp: Any) -> Any | None:
    """The item type of ``tuple[X, ...]`` / ``list[X]``, else None."""
    if get_origin(tp) in (tuple, list):
        args = [a for a in get_args(tp) if a is not Ellipsis]
        return args[0] if args else Any
    return None


def _is_table(tp: Any) -> bool:
    return dataclasses.is_dataclass(tp) and isinstance(tp, type)


def _type_name(tp: Any) -> str:
    tp, _ = _strip_optional(tp)
    item = _item(tp)
    if item is not None:
        return f"list of {_type_name(item)}"
    if get_origin(tp) is Literal:
        return "string" if all(isinstance(a, str) for a in get_args(tp)) else "int"
    names = {bool: "bool", int: "int", float: "float", str: "string"}
    return names.get(tp, str(tp))


def _toml(value: Any) -> str:
    """A default as a TOML file would write it."""
    if value is None:
        return "(not set)"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, tuple | list):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        cls = type(value)
        given = []
        for f in toml_fields(cls).values():
            v = getattr(value, f.name)
            required = (f.default is dataclasses.MISSING
                        and f.default_factory is dataclasses.MISSING)
            if required or (f.default is not dataclasses.MISSING and v != f.default):
                given.append(f"{f.name} = {_toml(v)}")
        return "{" + ", ".join(given) + "}"
    return repr(value)


def _number(x: Any) -> str:
    if isinstance(x, float) and x.is_integer() and abs(x) < 1e5:
        return str(int(x))
    if not isinstance(x, float):
        return str(x)
    return re.sub(r"e\+?(-?)0*(\d)", r"e\1\2", f"{x:g}")  # 1e6, 1e-5


def number_range(meta: typing.Mapping[str, Any], integer: bool) -> str:
    """The bounds of a numeric field, as the loader applies them ("" when it has none)."""
    lo = "[" + _number(meta["ge"]) if "ge" in meta else (
        "(" + _number(meta["gt"]) if "gt" in meta else None)
    hi = _number(meta["le"]) + "]" if "le" in meta else (
        _number(meta["lt"]) + ")" if "lt" in meta else None)
    if lo is None and hi is None:
        return ""
    if lo is None:
        lo = "(-inf" if integer else "[" + _number(-MAX_MAGNITUDE)
    if hi is None:
        hi = "inf)" if integer else _number(MAX_MAGNITUDE) + "]"
    text = f"{lo}, {hi}"
    if "off" in meta:
        text = f"{_number(meta['off'])} or {text}"
    if "ne" in meta:
        text += f", not {_number(meta['ne'])}"
    return text


def _range(tp: Any, meta: typing.Mapping[str, Any]) -> str:
    tp, _ = _strip_optional(tp)
    item = _item(tp)
    if item is not None:
        inner = _range(item, meta)
        return f"each {inner}" if inner and _numeric(item) else inner
    if get_origin(tp) is Literal:
        return ", ".join(_toml(a) for a in get_args(tp))
    if tp is bool:
        return "true, false"
    if tp in (int, float):
        return number_range(meta, tp is int)
    if "choices" in meta:
        return ", ".join(_toml(c) for c in meta["choices"])
    if "url" in meta:
        return config.URL_KINDS[str(meta["url"])]
    return str(meta.get("range", ""))


def _meta(cls: type[Any], f: dataclasses.Field[Any]) -> typing.Mapping[str, Any]:
    """A field's metadata; the drivers' SerialSettings.url is a URL of kind "serial" (the
    config loader's own table of such fields)."""
    kind = config._URL_FIELDS_ELSEWHERE.get((cls, f.name))
    return {**f.metadata, "url": kind} if kind else f.metadata


def _cell(text: str) -> str:
    return " ".join(text.split()).replace("|", "\\|")


def _class_doc(cls: type[Any]) -> str:
    """The first paragraph of a class's docstring, its Sphinx roles as plain code."""
    doc = (cls.__doc__ or "").strip()
    if doc.startswith(cls.__name__ + "("):  # the one dataclasses writes: none of its own
        return ""
    doc = doc.split("\n\n")[0]
    doc = re.sub(r":\w+:`~?([^`]+)`", lambda m: "`" + m.group(1).split(".")[-1] + "`", doc)
    return " ".join(doc.replace("``", "`").split())


def _default_of(cls: type[Any]) -> Any:
    try:
        return cls()
    except TypeError:  # a required key (an endpoint's url): no default object
        return None


def tables() -> list[Table]:
    """Every table of a configuration file, in file order (sections, then their sub-tables)."""
    out: list[Table] = []

    def walk(cls: type[Any], obj: Any, path: str, array: bool) -> None:
        hints = get_type_hints(cls)
        keys: list[Key] = []
        subs: list[tuple[type[Any], Any, str, bool]] = []
        for name, f in toml_fields(cls).items():
            tp, _ = _strip_optional(hints[name])
            value = getattr(obj, name) if obj is not None else (
                f.default if f.default is not dataclasses.MISSING else dataclasses.MISSING)
            sub = f"{path}.{name}" if path else name
            item = _item(tp)
            if _is_table(tp):
                subs.append((tp, value if value is not None else _default_of(tp), sub, False))
                continue
            if item is not None and _is_table(item):
                keys.append(Key(name, f"array of tables [[{sub}]]", _toml(value), "", "",
                                _cell(str(f.metadata.get("doc", _class_doc(item))))))
                subs.append((item, None, sub, True))
                continue
            meta = _meta(cls, f)
            default = "(required)" if value is dataclasses.MISSING else _toml(value)
            keys.append(Key(name, _type_name(tp), default, str(meta.get("unit", "")),
                            _cell(_range(tp, meta)), _cell(str(meta.get("doc", "")))))
        out.append(Table(path, array, cls, _class_doc(cls), keys))
        for sub_cls, sub_obj, sub_path, sub_array in subs:
            walk(sub_cls, sub_obj, sub_path, sub_array)

    walk(config.BridgeFile, config.BridgeFile(), "", False)
    return out


def _leaf_fields() -> Iterator[tuple[str, Any, typing.Mapping[str, Any]]]:
    """``(dotted key, type, metadata)`` of every key that holds a value (not a table)."""
    for table in tables():
        hints = get_type_hints(table.cls)
        for name, f in toml_fields(table.cls).items():
            tp, _ = _strip_optional(hints[name])
            item = _item(tp)
            if _is_table(tp) or (item is not None and _is_table(item)):
                continue
            yield (f"{table.path}.{name}" if table.path else name), tp, _meta(table.cls, f)


def _numeric(tp: Any) -> bool:
    item = _item(tp)
    return _numeric(item) if item is not None else tp in (int, float)


def lacks(tp: Any, meta: typing.Mapping[str, Any]) -> list[str]:
    """What a key of type ``tp`` with this metadata lacks of doc, unit (numbers) and range."""
    tp, _ = _strip_optional(tp)
    return [w for w, ok in (("doc", bool(meta.get("doc"))),
                            ("unit", not _numeric(tp) or bool(meta.get("unit"))),
                            ("range", bool(_range(tp, meta)))) if not ok]


def missing() -> list[str]:
    """Every key without a doc, a unit (a number) or a range, as ``key: no doc, no unit``."""
    return [f"{key}: no {', no '.join(what)}" for key, tp, meta in _leaf_fields()
            if (what := lacks(tp, meta))]


def config_reference() -> str:
    """``docs/reference/config.md``."""
    lines = [
        "# Configuration reference",
        "",
        f"Generated from the configuration's dataclasses by `{REGENERATE}`; do not edit (a "
        "test fails when this page is not what the generator writes).",
        "",
        "A file holds any of the sections below; a key it leaves out takes the default shown. "
        "`fdi-bridge config check FILE` validates a file and `fdi-bridge config show FILE` prints "
        "it with every default filled in. A range `[a, b]` includes its ends, `(a, b)` excludes "
        f"them; a float without an upper (lower) bound of its own is at most "
        f"{_number(MAX_MAGNITUDE)} (at least {_number(-MAX_MAGNITUDE)}). `0 or [a, b]`: 0 is "
        "accepted beside the range, meaning what the description says (mostly: off). Units: "
        "`m`, `s`, `Hz`, `deg`, `deg/s`, `m/s`, `%` "
        "(percent of full command or thrust), `σ` (standard deviations of the quantity tested), "
        "`epochs` and `samples` (counts), `-` (dimensionless).",
        "",
        "Sections: " + ", ".join(f"[`[{t.path}]`](#{_anchor(t.path)})"
                                 for t in tables() if t.path and "." not in t.path),
        "",
    ]
    for table in tables():
        head = "Top level" if not table.path else (
            f"[[{table.path}]]" if table.array else f"[{table.path}]")
        lines += [f"## {head}", ""]
        if table.doc:
            lines += [table.doc, ""]
        if table.keys:
            lines += ["| key | type | default | unit | range | description |",
                      "|---|---|---|---|---|---|"]
            for k in table.keys:
                lines.append(f"| `{k.name}` | {k.type} | `{k.default}` | {k.unit} | "
                             f"{k.range} | {k.doc} |".replace("`` ", "").replace(" ``", ""))
            lines.append("")
    return "\n".join(lines).rstrip("\n") + "\n"


def _anchor(path: str) -> str:
    return re.sub(r"[^a-z0-9 -]", "", f"[{path}]".lower()).replace(" ", "-")


def pages(tree: ParserTree) -> dict[str, str]:
    """The reference pages: file name -> text (``tree``: the whole parser,
    :func:`firmware_host.cli.parser_tree`, which the cli hands to its commands)."""
    return {"config.md": config_reference(), "cli.md": cli_reference(tree)}


# --------------------------------------------------------------------------- the command


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", type=Path, default=None,
                        help="write config.md and cli.md into this directory (e.g. "
                             "docs/reference) instead of printing them")
    parser.add_argument("--check", action="store_true",
                        help="write nothing; exit 1 when a page in --out differs from what "
                             "would be written, or when a config key has no doc, unit or range")


def run(args: argparse.Namespace) -> int:
    texts = pages(args.parser_tree())
    if args.check:
        problems = [f"config key {m}" for m in missing()]
        if args.out is not None:
            for name, text in texts.items():
                path = args.out / name
                if not path.is_file() or path.read_text(encoding="utf-8") != text:
                    problems.append(f"{path} is not current (regenerate: {REGENERATE})")
        for p in problems:
            print(p)
        return 1 if problems else 0
    if args.out is None:
        sys.stdout.write("\n".join(texts.values()))
        return 0
    args.out.mkdir(parents=True, exist_ok=True)
    for name, text in texts.items():
        (args.out / name).write_text(text, encoding="utf-8")
        print(f"wrote {args.out / name}")
    return 0


__all__ = ["Key", "Table", "config_reference", "lacks", "missing", "number_range", "pages",
           "tables"]
