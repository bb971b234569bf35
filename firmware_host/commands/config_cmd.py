"""``fdi-bridge config check FILE`` and ``fdi-bridge config show FILE``.

``check`` loads the file (a path or a preset name) exactly as every command does
(:func:`firmware_host.runtime.config.load_bridge_file`) and reports every error of it at once
(exit 2), or which tables it has and what ``fdi-bridge run`` would do with it (exit 0).
``show`` prints the effective configuration: each table the file has, with every key, the
defaults filled in, as TOML that loads back to the same configuration.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from typing import Any

from fdi.errors import ConfigError
from firmware_host.runtime.config import BridgeFile, load_bridge_file, run_mode


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)  # a valid TOML basic string
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    raise TypeError(f"no TOML spelling for {value!r}")


def _is_table(value: Any) -> bool:
    return dataclasses.is_dataclass(value) and not isinstance(value, type)


def _is_table_array(value: Any) -> bool:
    return isinstance(value, list | tuple) and bool(value) and all(_is_table(v) for v in value)


def _emit(obj: Any, name: str, out: list[str], header: str = "table") -> None:
    """``obj`` (a dataclass) as the TOML table ``name``: its keys, then its sub-tables."""
    fields = [f for f in dataclasses.fields(obj) if f.metadata.get("toml", True)]
    if name:
        out.append(f"\n[[{name}]]" if header == "array" else f"\n[{name}]")
    unset = []
    for f in fields:
        value = getattr(obj, f.name)
        if value is None:
            unset.append(f.name)
        elif not _is_table(value) and not _is_table_array(value):
            out.append(f"{f.name} = {_toml_value(value)}")
    for key in unset:
        out.append(f"# {key}: not set")
    for f in fields:
        value = getattr(obj, f.name)
        dotted = f"{name}.{f.name}" if name else f.name
        if _is_table(value):
            _emit(value, dotted, out)
        elif _is_table_array(value):
            for item in value:
                _emit(item, dotted, out, header="array")


def effective_toml(bf: BridgeFile) -> str:
    """The configuration as TOML, every default stated (sections the file lacks are left out)."""
    out = [f"# effective configuration of {bf.path or '(built-in defaults)'}",
           f"name = {_toml_value(bf.name)}", f"description = {_toml_value(bf.description)}"]
    for section in ("rover", "rov", "insgnss", "mavlink", "recorder"):
        value = getattr(bf, section)
        if value is not None:
            _emit(value, section, out)
    return "\n".join(out) + "\n"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("action", choices=("check", "show"),
                        help="check: validate and report every error; show: the effective "
                             "configuration with its defaults, as TOML")
    parser.add_argument("file", help="a config file or a preset name (fdi-bridge presets)")


def run(args: argparse.Namespace) -> int:
    bf = load_bridge_file(args.file)  # ConfigError: the CLI prints every error, exit 2
    if args.action == "show":
        print(effective_toml(bf), end="")
        return 0
    try:
        mode = f"fdi-bridge run runs the {run_mode(bf)}"
        if run_mode(bf) == "mavlink":
            mode = "fdi-bridge run runs the MAVLink router" + (
                " with the rover" if bf.rover is not None else "")
    except ConfigError as err:
        mode = f"not for fdi-bridge run ({err.expected}, found {err.found})"
    print(f"{bf.path}: ok; tables {', '.join(bf.sections) or '(none)'}; {mode}")
    return 0
