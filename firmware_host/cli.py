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
from typing import Protocol

from fdi.errors import ConfigError, FdiBridgeError

log = logging.getLogger("fdi_bridge")


class Command(Protocol):
    def add_arguments(self, parser: argparse.ArgumentParser) -> None: ...

    def run(self, args: argparse.Namespace) -> int: ...


# Top-level commands: name -> (module, help).
COMMANDS: dict[str, tuple[str, str]] = {
    "demo": ("", "run a built-in demo with no hardware (rover by default)"),
    "replay": (
        "firmware_host.commands.replay",
        "replay a capture or NMEA log through a pty into a pipeline",
    ),
    "record": (
        "firmware_host.commands.record",
        "record a serial port's raw bytes to a capture file",
    ),
    "run": ("firmware_host.commands.run", "run on the vehicle with the configured ports"),
    "eval": (
        "firmware_host.devtools.eval",
        "score detectors against the truth, beside the baselines",
    ),
    "bench": (
        "firmware_host.devtools.bench",
        "benchmarks: per-epoch time, throughput, loop jitter",
    ),
    "doctor": (
        "firmware_host.commands.doctor",
        "start-up checks: config, ports, permissions, endpoints",
    ),
    "fuzz": (
        "firmware_host.devtools.fuzz",
        "seeded mutation fuzzer for the NMEA/Outland/MAVLink input",
    ),
    "soak": (
        "firmware_host.devtools.soak",
        "rover + ROV together, accelerated, faults and port drops",
    ),
    "mavlink": (
        "firmware_host.mavlink.router",
        "MAVLink passthrough between autopilot and ground stations",
    ),
}

# ``fdi-bridge sim KIND``: KIND -> (module, help).
SIM_COMMANDS: dict[str, tuple[str, str]] = {
    "rover": (
        "firmware_host.devtools.rover_sim",
        "generate a rover NMEA run with injected GPS faults",
    ),
    "rover-harness": (
        "firmware_host.devtools.rover_harness",
        "rover done-means: a preset over every error model x seed x rate (issue 13)",
    ),
    "rov": ("firmware_host.rov.app", "ROV compass faults and fault-tolerant heading hold"),
    "insgnss": (
        "firmware_host.devtools.insgnss_sim",
        "INS/GNSS three-zone robust filter: paper scenarios",
    ),
    "insgnss-report": (
        "firmware_host.devtools.insgnss_report",
        "INS/GNSS: every scenario, seed and preset as the Markdown tables of docs/insgnss.md",
    ),
}

# ``fdi-bridge demo KIND``: KIND -> module with ``run_demo(args) -> int`` and ``add_arguments``.
DEMO_COMMANDS: dict[str, tuple[str, str]] = {
    "rover": (
        "firmware_host.commands.demo_rover",
        "GPS fault isolation on a generated 10-minute rover run",
    ),
    "rov": ("firmware_host.commands.demo_rov", "ROV compass drift 30 deg with and without FT"),
}


def _load(module: str) -> Command:
    return importlib.import_module(module)


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
            p.add_argument("kind", nargs="?", default="rover", choices=sorted(DEMO_COMMANDS),
                           help="which demo (default: rover)")
            p.add_argument("demo_args", nargs=argparse.REMAINDER,
                           help="the demo's own options (see: fdi-bridge demo KIND -h)")
            p.set_defaults(_demo=True)
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


def _demo_args(argv: list[str]) -> argparse.Namespace | None:
    """``fdi-bridge [-v] demo [KIND] [options]``: the KIND's own parser takes the options."""
    verbose = 0
    rest = list(argv)
    while rest and rest[0] in ("-v", "--verbose", "-vv"):
        verbose += 2 if rest.pop(0) == "-vv" else 1
    if not rest or rest[0] != "demo":
        return None
    rest.pop(0)
    kind = "rover"
    if rest and not rest[0].startswith("-"):
        kind = rest.pop(0)
    if kind not in DEMO_COMMANDS:
        known = ", ".join(sorted(DEMO_COMMANDS))
        raise SystemExit(f"fdi-bridge demo: unknown demo {kind!r} (known: {known})")
    dmod, dhelp = DEMO_COMMANDS[kind]
    dparser = argparse.ArgumentParser(prog=f"fdi-bridge demo {kind}", description=dhelp)
    _load(dmod).add_arguments(dparser)
    args = dparser.parse_args(rest)
    args.verbose = verbose
    args.command = "demo"
    args._module = dmod
    return args


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    args = _demo_args(argv)
    if args is None:
        parser = build_parser()
        args = parser.parse_args(argv)
        if args.command is None:
            parser.print_help()
            return 2
    _setup_logging(args.verbose)
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
