"""``fdi-bridge presets``: the packaged configuration presets, by name, with what each holds.

A name from this list is accepted wherever a ``--config`` is (``run --config rov``), from any
directory (:func:`firmware_host.runtime.config.resolve_config_path`).
"""

from __future__ import annotations

import argparse
import json

from fdi.errors import ConfigError
from firmware_host.runtime.config import load_bridge_file, preset_names, presets_dir


def presets() -> list[dict[str, str]]:
    """One row per preset: name, tables, description (or the error that stops it loading)."""
    rows = []
    for name in preset_names():
        path = presets_dir() / f"{name}.toml"
        try:
            bf = load_bridge_file(path)
            rows.append({"name": name, "tables": ", ".join(bf.sections),
                         "description": bf.description, "path": str(path)})
        except ConfigError as err:
            rows.append({"name": name, "tables": "?", "description": f"does not load: {err}",
                         "path": str(path)})
    return rows


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", action="store_true", help="one JSON object per preset")


def run(args: argparse.Namespace) -> int:
    rows = presets()
    if args.json:
        for row in rows:
            print(json.dumps(row))
        return 0
    width = max([len("NAME"), *(len(r["name"]) for r in rows)])
    twidth = max([len("TABLES"), *(len(r["tables"]) for r in rows)])
    print(f"{'NAME':<{width}}  {'TABLES':<{twidth}}  DESCRIPTION")
    for r in rows:
        print(f"{r['name']:<{width}}  {r['tables']:<{twidth}}  {r['description']}")
    print(f"\n{len(rows)} presets in {presets_dir()} (use: --config NAME)")
    return 0
