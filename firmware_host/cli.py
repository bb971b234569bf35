"""The ``fdi-bridge`` command line.

Commands are listed in tables ``{name: (module, help)}`` and imported only when used: the parser
is built for the one command on the command line (``fdi-bridge --help`` imports no command at
all), so ``fdi-bridge replay`` never pays for what ``sim insgnss`` needs. A module exposes
``add_arguments(parser)`` and ``run(args) -> int``; where a command's module is heavy (it
imports pymavlink or numpy) and its ``--help`` should not be, the table names a light
argument-definition module for ``add_arguments`` as ``"ARGS_MODULE:RUN_MODULE"``
(``replay``: :mod:`firmware_host.commands.replay_args`).

The logging options ``-v``/``--verbose``, ``-q``/``--quiet`` and ``--log-level`` are accepted
before the command and after it (``fdi-bridge run -v ...`` as gpsd's and MAVProxy's users
type it); ``--version`` prints the installed version.

Only this module configures logging, prints and chooses the exit status: 0 success, 1 failure
of the job, 2 bad configuration or usage.

It is also the one door to the developer tools (:mod:`firmware_host.devtools`: simulators,
harnesses, eval, bench, fuzz, soak, fleet, the demos): nothing else of the product imports them.
Before it imports a command whose module is under ``firmware_host.devtools`` (or a product
command's option that runs one, :data:`DEV_OPTIONS`) it checks that the ``dev`` extra is
installed (:data:`DEV_EXTRA_MODULES`); without it, one line says how to get it, exit 2.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import importlib.util
import logging
import os
import sys
import traceback
from collections.abc import Sequence
from typing import TYPE_CHECKING, NoReturn, Protocol

import firmware_host
from fdi.errors import ConfigError, ConfigErrors, FdiBridgeError, UsageError

if TYPE_CHECKING:  # imported by name when asked for: --help imports no command module
    from firmware_host.commands.docgen import ParserTree

log = logging.getLogger("fdi_bridge")


class Command(Protocol):
    def add_arguments(self, parser: argparse.ArgumentParser) -> None: ...

    def run(self, args: argparse.Namespace) -> int: ...


# Top-level commands: name -> (module, help); module "ARGS:RUN" splits the two (module doc).
COMMANDS: dict[str, tuple[str, str]] = {
    "demo": ("", "run a built-in demo with no hardware (rover by default; demo rov: the ROV)"),
    "replay": (
        "firmware_host.commands.replay_args:firmware_host.commands.replay",
        "replay a capture or NMEA log through a pty into a pipeline",
    ),
    "record": (
        "firmware_host.commands.record",
        "record a serial port's raw bytes to a capture file",
    ),
    "run": ("firmware_host.commands.run", "run on the vehicle with the configured ports"),
    "calibrate": (
        "firmware_host.commands.calibrate",
        "calibrate the rover's drift test once, on recordings of clean drives",
    ),
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
        "seeded mutation fuzzer for the NMEA/Outland/MAVLink input and the whole pipeline",
    ),
    "soak": (
        "firmware_host.devtools.soak",
        "rover + ROV together, accelerated, faults and port drops",
    ),
    "fleet": (
        "firmware_host.devtools.fleet",
        "evaluate (and sweep) a configuration over a whole directory of logs, on Dask",
    ),
    "mavlink": (
        "firmware_host.commands.mavlink",
        "MAVLink passthrough between autopilot and ground stations",
    ),
    "presets": ("firmware_host.commands.presets", "list the packaged configuration presets"),
    "config": (
        "firmware_host.commands.config_cmd",
        "check a configuration file, or show it with every default filled in",
    ),
    "completion": (
        "firmware_host.commands.completion",
        "print a shell completion script generated from this parser",
    ),
    "man": ("firmware_host.commands.manpage", "print the fdi-bridge(1) man page (roff)"),
    "docs": ("firmware_host.commands.reference",
             "write the reference pages (config keys, commands) generated from the code"),
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
    "rover-frozen": (
        "firmware_host.devtools.rover_frozen",
        "rover: a frozen receiver on a curved path, the output against the truth (issue 42)",
    ),
    "ramp-oracle": (
        "firmware_host.devtools.ramp_oracle",
        "rover: the most any detector can find of a slow ramp in time, per receiver",
    ),
    "rov": ("firmware_host.devtools.sim_rov", "ROV compass faults and fault-tolerant heading hold"),
    "rov-harness": (
        "firmware_host.devtools.rov_harness",
        "ROV done-means: both plants x seeds, with and without the gyro (issue 14)",
    ),
    "ardusub-harness": (
        "firmware_host.devtools.ardusub_harness",
        "ArduSub ROV in closed loop on the calibrated simulator, over seeds (issue 41)",
    ),
    "ardusub-calib": (
        "firmware_host.devtools.ardusub_calib",
        "the simulated ArduSub's yaw against the real SITL captures (fit and check)",
    ),
    "insgnss": (
        "firmware_host.devtools.insgnss_sim",
        "INS/GNSS three-zone robust filter: paper scenarios",
    ),
    "insgnss-report": (
        "firmware_host.devtools.insgnss_report",
        "INS/GNSS: every scenario, seed and preset, the tables of docs/insgnss.md",
    ),
}

# ``fdi-bridge demo KIND``: KIND -> module with ``run(args) -> int`` and ``add_arguments``.
DEMO_COMMANDS: dict[str, tuple[str, str]] = {
    "rover": (
        "firmware_host.devtools.demo_rover",
        "GPS fault isolation on a generated 10-minute rover run",
    ),
    "rov": ("firmware_host.devtools.demo_rov", "ROV compass drift 30 deg with and without FT"),
    "insgnss": ("firmware_host.devtools.demo_insgnss",
                "live INS/GNSS against a simulated autopilot, compared with sim insgnss"),
}

# One example per command, shown at the end of its --help (issue 17).
EXAMPLES: dict[str, str] = {
    "demo": "fdi-bridge demo --duration 120 --out demo-out",
    "demo rover": "fdi-bridge demo rover --duration 120 --out demo-out",
    "demo rov": "fdi-bridge demo rov --drift 20 --out rov-demo",
    "demo insgnss": "fdi-bridge demo insgnss --scenario paper-random --seed 3 --out ins-demo",
    "replay": "fdi-bridge replay --config rover run/rover.nmea --out replayed",
    "record": "fdi-bridge record /dev/ttyUSB0 --baud 115200 --duration 600 --out gps.cap",
    "run": "fdi-bridge run --config rover --out run-out --record rec",
    "calibrate": "fdi-bridge calibrate clean-drive.cap --config rover --out rover-mine.toml",
    "eval": "fdi-bridge eval replayed --truth run/truth.jsonl   (or: fdi-bridge eval --suite "
            "--quick)",
    "bench": "fdi-bridge bench --duration 10 --json bench.json",
    "doctor": "fdi-bridge doctor --config rover",
    "fuzz": "fdi-bridge fuzz --seconds 5 --codec nmea --out fuzz.json",
    "soak": "fdi-bridge soak --minutes 10 --out soak.json",
    "fleet": "fdi-bridge fleet logs/ --workers 2 --sweep rover.detector.gate_sigmas=4,6,8 "
             "--out fleet-out",
    "mavlink": "fdi-bridge mavlink --autopilot udpin:127.0.0.1:14555 --gcs "
               "udpout:127.0.0.1:14550 --seconds 60",
    "presets": "fdi-bridge presets --json",
    "config": "fdi-bridge config check rover   (or: fdi-bridge config show my-rover.toml)",
    "completion": "fdi-bridge completion bash --out ~/.fdi-bridge.bash   (then: source it)",
    "man": "fdi-bridge man --out fdi-bridge.1 && man -l fdi-bridge.1",
    "docs": "fdi-bridge docs --out docs/reference   (--check: exit 1 when they are stale)",
    "sim": "fdi-bridge sim rover --duration 60 --out run",
    "sim rover": "fdi-bridge sim rover --duration 60 --kinds jump,ramp --out run",
    "sim rover-harness": "fdi-bridge sim rover-harness --seeds 1,2 --rates 10 --duration 600",
    "sim rover-frozen": "fdi-bridge sim rover-frozen --seeds 1-3 --rates 1,10",
    "sim ramp-oracle": "fdi-bridge sim ramp-oracle --seeds 1-3 --models gm,coarse",
    "sim rov": "fdi-bridge sim rov --fault drift:30@70 --out rov-run",
    "sim rov-harness": "fdi-bridge sim rov-harness --seeds 1-3 --scenarios step,burst",
    "sim ardusub-harness": "fdi-bridge sim ardusub-harness --seeds 1-3 --scenarios clean",
    "sim ardusub-calib": "fdi-bridge sim ardusub-calib --fit att",
    "sim insgnss": "fdi-bridge sim insgnss --scenario paper-single --out ins-run",
    "sim insgnss-report": "fdi-bridge sim insgnss-report --seeds 1-2 --out insgnss.md",
}

# The developer tools and what they need: the ``dev`` extra of pyproject.toml (tqdm, matplotlib,
# dask[distributed]), found by name without importing it.
DEVTOOLS = "firmware_host.devtools."
DEV_EXTRA_MODULES = ("tqdm", "matplotlib", "dask", "distributed")
# A product command's option that runs a developer tool: (command, option's dest) -> module
# with ``run(args) -> int`` (the options are the command's own).
DEV_OPTIONS: dict[tuple[str, str], str] = {
    ("mavlink", "bench"): "firmware_host.devtools.router_bench",
}

LOG_LEVELS = ("debug", "info", "warning", "error", "critical")
_VALUE_OPTIONS = ("--log-level",)  # global options that take a value


def _load(module: str) -> Command:
    return importlib.import_module(module)


def is_dev(spec: str) -> bool:
    """Whether a table's module spec (``"ARGS:RUN"`` or one module) is a developer tool."""
    return any(m.startswith(DEVTOOLS) for m in spec.split(":"))


def dev_extra_missing() -> list[str]:
    """The modules of the ``dev`` extra that are not installed (looked up, not imported)."""
    return [m for m in DEV_EXTRA_MODULES if importlib.util.find_spec(m) is None]


def _require_dev(name: str, spec: str) -> None:
    """Before importing a developer tool: without the ``dev`` extra, say how to get it, exit 2."""
    if is_dev(spec) and dev_extra_missing():
        print(f"fdi-bridge {name} is a developer tool: pip install 'fdi-bridge[dev]'",
              file=sys.stderr)
        raise SystemExit(2)


def _args_module(spec: str) -> str:
    return spec.split(":", 1)[0]


def _run_module(spec: str) -> str:
    return spec.rsplit(":", 1)[-1]


def version() -> str:
    import importlib.metadata  # ~40 ms: only when the version is asked for (--version)

    try:
        return importlib.metadata.version("fdi-bridge")
    except importlib.metadata.PackageNotFoundError:  # a source tree on PYTHONPATH
        return firmware_host.__version__


class _VersionAction(argparse.Action):
    """``--version``: the installed version, looked up only when asked for."""

    def __init__(self, option_strings: Sequence[str], dest: str = argparse.SUPPRESS,
                 default: str = argparse.SUPPRESS, help: str | None = None) -> None:
        super().__init__(option_strings, dest, nargs=0, default=default, help=help)

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace,
                 values: object, option_string: str | None = None) -> NoReturn:
        sys.stdout.write(f"fdi-bridge {version()}\n")  # on stdout, as argparse's own
        parser.exit()


def _logging_options(parser: argparse.ArgumentParser, *, sub: bool) -> None:
    """``-v``/``-q``/``--log-level``; after the command they count too (``dest`` ``*_sub``)."""
    suffix = "_sub" if sub else ""
    default = argparse.SUPPRESS if sub else None
    group = parser.add_argument_group("logging")
    group.add_argument("-v", "--verbose", action="count", dest="verbose" + suffix,
                       default=default if sub else 0,
                       help="more log output (-vv: debug)")
    group.add_argument("-q", "--quiet", action="count", dest="quiet" + suffix,
                       default=default if sub else 0,
                       help="less log output (errors only; -qq: critical only)")
    group.add_argument("--log-level", choices=LOG_LEVELS, dest="log_level" + suffix,
                       default=default, help="set the log level (overrides -v/-q)")


def _command_of(argv: Sequence[str]) -> tuple[str | None, str | None]:
    """The command (and ``sim``/``demo`` kind) named on the command line, skipping the global
    options before it."""
    rest = list(argv)
    while rest and rest[0].startswith("-"):
        opt = rest.pop(0)
        if opt in _VALUE_OPTIONS and rest:
            rest.pop(0)
    if not rest:
        return None, None
    command = rest.pop(0)
    kind = rest[0] if rest and not rest[0].startswith("-") else None
    return command, kind


class _Parser(argparse.ArgumentParser):
    """A usage error is one line (what was wrong, and where the help is), exit 2."""

    _args: Sequence[str] | None = None

    def parse_known_args(self, args: Sequence[str] | None = None,  # type: ignore[override]
                         namespace: argparse.Namespace | None = None,
                         ) -> tuple[argparse.Namespace, list[str]]:
        self._args = None if args is None else list(args)  # for error(): the words it saw
        return super().parse_known_args(args, namespace)

    def error(self, message: str) -> NoReturn:
        arg_errors = importlib.import_module("firmware_host.commands.arg_errors")  # light
        message = arg_errors.unknown_option_error(self, self._args, message)
        self.exit(2, f"{self.prog}: error: {message} (see: {self.prog} --help)\n")


class _HelpFormatter(argparse.RawDescriptionHelpFormatter,
                     argparse.ArgumentDefaultsHelpFormatter):
    """Defaults shown where there is one to show (not ``None`` or ``False``) and the help text
    does not state it already."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        if (action.default is None or action.default is False
                or action.default is argparse.SUPPRESS
                or "default" in (action.help or "")):
            return action.help
        return super()._get_help_string(action)


def _epilog(key: str, extra: str = "") -> str:
    example = f"example:\n  {EXAMPLES[key]}" if key in EXAMPLES else ""
    return "\n\n".join(x for x in (extra, example) if x)


def _subparser(sub: argparse._SubParsersAction[_Parser], name: str,
               help_text: str, key: str | None = None,
               extra: str = "") -> _Parser:
    return sub.add_parser(name, help=help_text, description=help_text,
                          epilog=_epilog(key or name, extra), formatter_class=_HelpFormatter)


def build_parser(argv: Sequence[str] | None = None) -> argparse.ArgumentParser:
    """The parser; only the command named in ``argv`` gets its arguments (and is imported).
    ``argv=None``: every command's (imports all of them; for documentation tools)."""
    command, kind = _command_of(argv) if argv is not None else (None, None)
    everything = argv is None
    no_dev = everything and bool(dev_extra_missing())  # documents: the product's commands
    parser = _Parser(
        prog="fdi-bridge",
        description="Fault detection and isolation between navigation sensors and a controller.",
        allow_abbrev=False,  # _command_of skips the global options by their full names
    )
    parser.add_argument("--version", action=_VersionAction,
                        help="show program's version number and exit")
    _logging_options(parser, sub=False)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, (module, help_text) in COMMANDS.items():
        others = "other demos: " + ", ".join(f"fdi-bridge demo {k}" for k in DEMO_COMMANDS
                                             if k != "rover") if name == "demo" else ""
        p = _subparser(sub, name, help_text, extra=others)
        if name == "demo":  # parsed by _demo_args; here for the list of commands and -h
            p.add_argument("kind", nargs="?", default="rover", choices=sorted(DEMO_COMMANDS),
                           help="which demo: " + "; ".join(
                               f"{k}: {h}" for k, (_, h) in DEMO_COMMANDS.items()))
            p.add_argument("demo_args", nargs=argparse.REMAINDER,
                           help="the demo's own options (see: fdi-bridge demo KIND -h)")
            continue
        if everything or name == command:
            if no_dev and is_dev(module):
                continue
            _require_dev(name, module)
            _logging_options(p, sub=True)
            p.set_defaults(_module=_run_module(module))
            _load(_args_module(module)).add_arguments(p)
    sim = _subparser(sub, "sim", "simulate a vehicle and its sensors")
    ssub = sim.add_subparsers(dest="sim_kind", metavar="KIND", required=True)
    for skind, (smod, shelp) in SIM_COMMANDS.items():
        sp = _subparser(ssub, skind, shelp, key=f"sim {skind}")
        if everything or (command == "sim" and skind == kind):
            if no_dev and is_dev(smod):
                continue
            _require_dev(f"sim {skind}", smod)
            _logging_options(sp, sub=True)
            sp.set_defaults(_module=_run_module(smod))
            _load(_args_module(smod)).add_arguments(sp)
    return parser


def demo_parser(kind: str) -> argparse.ArgumentParser:
    """``fdi-bridge demo KIND``'s own parser."""
    dmod, dhelp = DEMO_COMMANDS[kind]
    others = ", ".join(f"fdi-bridge demo {k}" for k in DEMO_COMMANDS if k != kind)
    dparser = _Parser(prog=f"fdi-bridge demo {kind}", description=dhelp,
                      epilog=_epilog(f"demo {kind}", f"other demos: {others}"),
                      formatter_class=_HelpFormatter)
    _logging_options(dparser, sub=True)
    _load(_args_module(dmod)).add_arguments(dparser)
    return dparser


def parser_tree() -> ParserTree:
    """The whole command line for the documents generated from it (``completion``, ``man``):
    every command; without the dev extra, the product's only (the developer tools' options
    and the demos left out)."""
    docgen = importlib.import_module("firmware_host.commands.docgen")
    demos = {} if dev_extra_missing() else {k: demo_parser(k) for k in DEMO_COMMANDS}
    tree: ParserTree = docgen.ParserTree(top=build_parser(None), demos=demos,
                                         formatter=_HelpFormatter, version=version())
    return tree


def _demo_args(argv: list[str]) -> argparse.Namespace | None:
    """``fdi-bridge [options] demo [KIND] [options]``: the KIND's own parser takes the options."""
    command, _ = _command_of(argv)
    if command != "demo":
        return None
    head = argv[: argv.index("demo")]
    top = _Parser(prog="fdi-bridge", add_help=False)
    _logging_options(top, sub=False)
    glob = top.parse_args(head)
    rest = argv[argv.index("demo") + 1:]
    kind = "rover"
    if rest and not rest[0].startswith("-"):
        kind = rest.pop(0)
    if kind not in DEMO_COMMANDS:
        known = ", ".join(sorted(DEMO_COMMANDS))
        print(f"fdi-bridge demo: error: unknown demo {kind!r} (known: {known})", file=sys.stderr)
        raise SystemExit(2)
    dmod = DEMO_COMMANDS[kind][0]
    _require_dev("demo" if kind == "rover" else f"demo {kind}", dmod)
    args = demo_parser(kind).parse_args(rest)
    for key, value in vars(glob).items():
        setattr(args, key, value)
    args.command = "demo"
    args._module = _run_module(dmod)
    return args


def _log_level(args: argparse.Namespace) -> int:
    name = getattr(args, "log_level_sub", None) or args.log_level
    if name:
        return int(getattr(logging, name.upper()))
    verbose = args.verbose + getattr(args, "verbose_sub", 0)
    quiet = args.quiet + getattr(args, "quiet_sub", 0)
    steps = max(-2, min(2, verbose - quiet))
    return {-2: logging.CRITICAL, -1: logging.ERROR, 0: logging.WARNING, 1: logging.INFO,
            2: logging.DEBUG}[steps]


def _setup_logging(level: int) -> None:
    logging.basicConfig(level=level, format="%(asctime)s %(levelname)s %(name)s: %(message)s")


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        return _main(argv)
    except OSError as err:  # a path the command line names that cannot even be looked at
        checks = importlib.import_module("firmware_host.commands.checks")  # --help stays light
        print(f"fdi-bridge: error: {checks.os_error_text('', err)}", file=sys.stderr)
        return 2
    except Exception as err:  # the last line of defence: one line, no traceback (issue 17)
        verbose = _verbose_argv(argv)
        hint = "" if verbose else " (run with -v for the traceback)"
        print(f"fdi-bridge: internal error: {type(err).__name__}: {err}{hint}", file=sys.stderr)
        if verbose:
            traceback.print_exc(file=sys.stderr)
        return 1


def _verbose_argv(argv: Sequence[str]) -> bool:
    """``-v`` (or ``--log-level info|debug``) anywhere on the command line."""
    for i, a in enumerate(argv):
        if a == "--verbose" or (a.startswith("-v") and set(a[1:]) == {"v"}):
            return True
        if a == "--log-level" and i + 1 < len(argv) and argv[i + 1] in ("debug", "info"):
            return True
        if a in ("--log-level=debug", "--log-level=info"):
            return True
    return False


def _main(argv: list[str]) -> int:
    args = _demo_args(argv)
    if args is None:
        parser = build_parser(argv)
        args = parser.parse_args(argv)
        if args.command is not None and not hasattr(args, "_module"):
            parser = build_parser(None)  # the command was not where _command_of looked
            args = parser.parse_args(argv)
        if args.command is None:
            parser.print_help()
            return 2
    for (command, option), dev_module in DEV_OPTIONS.items():
        if args.command == command and getattr(args, option, False):
            _require_dev(f"{command} --{option.replace('_', '-')}", dev_module)
            args._module = dev_module
    level = _log_level(args)
    _setup_logging(level)
    name = _command_name(args)
    args.parser_tree = parser_tree  # for the documents generated from the parser
    try:
        module = _load(args._module)
        return int(module.run(args))
    except UsageError as err:
        print(f"fdi-bridge {name}: error: {err}", file=sys.stderr)
        return 2
    except ConfigErrors as err:
        print(f"fdi-bridge: configuration error: {len(err.errors)} errors in {err.file}:",
              file=sys.stderr)
        for e in err.errors:
            print(f"  {e}", file=sys.stderr)
        return 2
    except ConfigError as err:
        print(f"fdi-bridge: configuration error: {err}", file=sys.stderr)
        return 2
    except FdiBridgeError as err:
        print(f"fdi-bridge {name}: {str(err).removeprefix(f'{name}: ')}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("fdi-bridge: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # `fdi-bridge ... | head`: the reader has gone, nothing to say
        with contextlib.suppress(OSError):
            sys.stdout = open(os.devnull, "w")  # noqa: SIM115 - no flush error at exit
        return 1
    except OSError as err:  # a file or device the checks could not foresee (disk full, EIO)
        where = f": {err.filename}" if err.filename else ""
        print(f"fdi-bridge {name}: {err.strerror or err}{where}", file=sys.stderr)
        if level <= logging.INFO:
            traceback.print_exc(file=sys.stderr)
        return 1


def _command_name(args: argparse.Namespace) -> str:
    sub = getattr(args, "sim_kind", None) if args.command == "sim" else None
    if args.command == "demo":
        sub = str(args._module).rsplit("_", 1)[-1]
    return " ".join(x for x in (args.command, sub) if x)


if __name__ == "__main__":
    sys.exit(main())
