"""The ``fdi-bridge`` command line.

Commands are listed in tables ``{name: "module:attribute"}`` and imported only when used (the
python-can backend pattern), so ``fdi-bridge replay`` never pays for what ``sim insgnss`` needs.
Each target module exposes ``add_arguments(parser)`` and ``run(args) -> int``; the attribute named
in the table is a small object or module with those two functions.

Only this module configures logging, prints and chooses the exit status: 0 success, 1 failure
of the job, 2 bad configuration or usage.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys
from collections.abc import Sequence
from typing import Any, Protocol

from fdi.errors import ConfigError, FdiBridgeError

log = logging.getLogger("fdi_bridge")


class Command(Protocol):
    def add_arguments(self, parser: argparse.ArgumentParser) -> None: ...

    def run(self, args: argparse.Namespace) -> int: ...


# Top-level commands: name -> (module, help).
COMMANDS: dict[str, tuple[str, str]] = {
    "demo": ("firmware_host.demo", "run a built-in demo with no hardware (rover by default)"),
    "replay": ("firmware_host.replay", "replay a capture or NMEA log through a pty into a pipeline"),
    "record": ("firmware_host.record", "record a serial port's raw bytes to a capture file"),
    "run": ("firmware_host.run", "run on the vehicle with the configured ports"),
    "bench": ("firmware_host.bench", "benchmarks: per-epoch time, throughput, loop jitter"),
}

# ``fdi-bridge sim KIND``: KIND -> (module, help).
SIM_COMMANDS: dict[str, tuple[str, str]] = {
    "rover": ("firmware_host.rover_sim", "generate a rover NMEA run with injected GPS faults"),
}

# ``fdi-bridge demo KIND``: KIND -> module with ``run_demo(args) -> int`` and ``add_arguments``.
DEMO_COMMANDS: dict[str, tuple[str, str]] = {
    "rover": ("firmware_host.rover_demo", "GPS fault isolation on a generated 10-minute rover run"),
}


def _load(module: str) -> Command:
    return importlib.import_module(module)  # type: ignore[return-value]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="fdi-bridge",
        description="Fault detection and isolation between navigation sensors and a controller.",
    )
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more log output")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, (module, help_text) in COMMANDS.items():
        p = sub.add_parser(name, help=help_text, description=help_text)
        if name == "demo":
            dsub = p.add_subparsers(dest="demo_kind", metavar="KIND")
            for kind, (dmod, dhelp) in DEMO_COMMANDS.items():
                dp = dsub.add_parser(kind, help=dhelp, description=dhelp)
                dp.set_defaults(_module=dmod)
                _load(dmod).add_arguments(dp)
            p.set_defaults(_module=DEMO_COMMANDS["rover"][0], _demo_default=True)
            continue
        p.set_defaults(_module=module)
        _load(module).add_arguments(p)
    sim = sub.add_parser("sim", help="simulate a vehicle and its sensors", description="simulate")
    ssub = sim.add_subparsers(dest="sim_kind", metavar="KIND", required=True)
    for kind, (smod, shelp) in SIM_COMMANDS.items():
        sp = ssub.add_parser(kind, help=shelp, description=shelp)
        sp.set_defaults(_module=smod)
        _load(smod).add_arguments(sp)
    return parser


def _setup_logging(verbosity: int) -> None:
    level = logging.WARNING - 10 * min(verbosity, 2)
    logging.basicConfig(level=level, format="%(asctime)s %(levelname)s %(name)s: %(message)s")


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 2
    _setup_logging(args.verbose)
    if getattr(args, "_demo_default", False) and getattr(args, "demo_kind", None) is None:
        # ``fdi-bridge demo`` alone: the rover demo with its defaults.
        dparser = argparse.ArgumentParser(prog="fdi-bridge demo rover")
        mod = _load(DEMO_COMMANDS["rover"][0])
        mod.add_arguments(dparser)
        defaults: Any = dparser.parse_args([])
        defaults.verbose = args.verbose
        args = defaults
        args._module = DEMO_COMMANDS["rover"][0]
    module = _load(args._module)
    try:
        return int(module.run(args))
    except ConfigError as err:
        print(f"fdi-bridge: configuration error: {err}", file=sys.stderr)
        return 2
    except FdiBridgeError as err:
        print(f"fdi-bridge: {err}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("fdi-bridge: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
