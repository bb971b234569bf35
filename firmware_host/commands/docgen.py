"""Documents generated from the command line's own parser: a bash completion script and a man
page (``fdi-bridge completion bash``, ``fdi-bridge man``).

Both walk the whole parser, handed in by the command line as a :class:`ParserTree`
(:func:`firmware_host.cli.parser_tree`: ``build_parser`` with no command line, which imports
every command; only these two commands ask for it), so a new command or option is completed
and documented without anyone editing a list. The tree comes from the CLI, a layer above:
this module never imports it.
"""

from __future__ import annotations

import argparse
import copy
import datetime as dt
import re
from dataclasses import dataclass, field
from pathlib import Path


@dataclass(frozen=True)
class ParserTree:
    """The whole command line as the CLI builds it: the top parser (every command and ``sim``
    kind), each ``demo`` kind's own parser, the formatter of ``--help`` and the version."""

    top: argparse.ArgumentParser
    demos: dict[str, argparse.ArgumentParser]
    formatter: type[argparse.HelpFormatter]
    version: str


@dataclass
class Option:
    """One option of a command: its flags, whether it takes a value, its choices, its help."""

    flags: list[str]
    metavar: str | None
    choices: list[str]
    help: str


@dataclass
class CommandDoc:
    """One command (``replay``, ``sim rover``, ``demo rov``) as the documents need it."""

    path: str
    description: str
    usage: str
    options: list[Option] = field(default_factory=list)
    positionals: list[Option] = field(default_factory=list)
    subcommands: list[str] = field(default_factory=list)
    epilog: str = ""


def _subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def _help(parser: argparse.ArgumentParser, action: argparse.Action,
          formatter_class: type[argparse.HelpFormatter]) -> str:
    """The help text as ``--help`` shows it (defaults expanded), on one line."""
    if not action.help or action.help is argparse.SUPPRESS:
        return ""
    formatter = formatter_class(parser.prog)
    shown = copy.copy(action)  # the parser's own action stays as it is
    shown.help = formatter._get_help_string(action)
    return " ".join(formatter._expand_help(shown).split())


def _doc(path: str, parser: argparse.ArgumentParser,
         formatter_class: type[argparse.HelpFormatter]) -> CommandDoc:
    doc = CommandDoc(path, parser.description or "", " ".join(parser.format_usage().split()),
                     epilog=parser.epilog or "")
    subs = _subparsers(parser)
    doc.subcommands = list(subs)
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            continue
        choices = [str(c) for c in action.choices] if action.choices else []
        takes_value = action.nargs != 0
        metavar = None
        if takes_value:
            metavar = action.metavar if isinstance(action.metavar, str) else (
                action.dest.upper() if action.option_strings else action.dest)
        opt = Option(list(action.option_strings), metavar, choices,
                     _help(parser, action, formatter_class))
        if action.option_strings:
            doc.options.append(opt)
        elif action.dest != "demo_args":
            doc.positionals.append(opt)
    return doc


def commands(tree: ParserTree) -> list[CommandDoc]:
    """The top level, every command, every ``sim`` and ``demo`` kind, in ``--help`` order."""
    fmt = tree.formatter
    out = [_doc("", tree.top, fmt)]
    for name, parser in _subparsers(tree.top).items():
        if name == "demo":
            demo = _doc("demo", parser, fmt)
            demo.subcommands = list(tree.demos)
            out.append(demo)
            out += [_doc(f"demo {k}", p, fmt) for k, p in tree.demos.items()]
            continue
        out.append(_doc(name, parser, fmt))
        out += [_doc(f"{name} {k}", p, fmt) for k, p in _subparsers(parser).items()]
    return out


# --------------------------------------------------------------------------- bash completion


def _words(items: list[str]) -> str:
    return " ".join(items).replace('"', "")


def bash_completion(tree: ParserTree) -> str:
    """A bash completion script: ``source <(fdi-bridge completion bash)``, or save it as
    ``/etc/bash_completion.d/fdi-bridge``. It completes commands, ``sim``/``demo`` kinds,
    each command's options and the values of options with choices; other values and the
    positional arguments complete as file names."""
    docs = commands(tree)
    paths = [d.path for d in docs if d.path]
    lines = [
        "# bash completion for fdi-bridge, generated from its parser by",
        "# `fdi-bridge completion bash` (regenerate it after an upgrade).",
        "_fdi_bridge() {",
        '    local cur="${COMP_WORDS[COMP_CWORD]}" prev="${COMP_WORDS[COMP_CWORD-1]}"',
        '    local path="" at=0 i w',
        "    for ((i = 1; i < COMP_CWORD; i++)); do",
        '        w="${COMP_WORDS[i]}"',
        '        [[ "$w" == -* ]] && continue',
        '        case "${path:+$path }$w" in',
        "            " + "|".join(f'"{p}"' for p in paths) + ')',
        '                path="${path:+$path }$w"; at=$i ;;',
        "        esac",
        "    done",
        '    local opts="" subs="" values=""',
        '    case "$path" in',
    ]
    for d in docs:
        # the words right after the command: its kinds, or its first argument's choices
        firsts = d.subcommands or next((p.choices for p in d.positionals if p.choices), [])
        opts = [f for o in d.options for f in o.flags]
        values = [f for o in d.options if o.metavar is not None for f in o.flags]
        lines.append(f'        "{d.path}") opts="{_words(opts)}"; subs="{_words(firsts)}"'
                     f'; values="{_words(values)}" ;;')
    lines += ["    esac", '    case "$path|$prev" in']
    for d in docs:
        for o in d.options:
            if o.choices:
                flags = "|".join(f'"{d.path}|{f}"' for f in o.flags)
                lines.append(f'        {flags}) COMPREPLY=($(compgen -W "{_words(o.choices)}"'
                             ' -- "$cur")); return ;;')
    lines += [
        "    esac",
        '    if [[ " $values " == *" $prev "* ]]; then',
        "        COMPREPLY=()  # a value: file names (complete -o default)",
        "        return",
        "    fi",
        '    if [[ "$cur" == -* ]]; then',
        '        COMPREPLY=($(compgen -W "$opts" -- "$cur"))',
        '    elif [[ -n "$subs" && $COMP_CWORD -eq $((at + 1)) ]]; then',
        '        COMPREPLY=($(compgen -W "$subs" -- "$cur"))',
        "    else",
        "        COMPREPLY=()  # a positional argument: file names",
        "    fi",
        "}",
        "complete -o default -F _fdi_bridge fdi-bridge",
    ]
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------- man page


def _roff(text: str) -> str:
    """Text for roff: backslashes and hyphens escaped, no line starting with a control
    character."""
    text = text.replace("\\", "\\e").replace("-", "\\-")
    return re.sub(r"^([.'])", r"\\&\1", text, flags=re.M)


def _option_head(o: Option) -> str:
    flags = ", ".join(f"\\fB{_roff(f)}\\fR" for f in o.flags) if o.flags else \
        f"\\fI{_roff(o.metavar or '')}\\fR"
    if o.flags and o.metavar is not None:
        value = "{" + ",".join(o.choices) + "}" if o.choices else o.metavar
        flags += f" \\fI{_roff(value)}\\fR"
    return flags


#: Options of every command (help and logging): in the man page once, under OPTIONS.
COMMON = {"-h", "-v", "-q", "--log-level"}

EXIT_STATUS = (
    ("0", "success (a bench figure that misses its goal too, unless --strict)"),
    ("1", "the job failed at run time (a port, a file, damaged input, an internal error)"),
    ("2", "usage or configuration error: one line naming what was wrong"),
    ("130", "interrupted (^C); long jobs write their partial results first"),
)


def man_page(tree: ParserTree, date: dt.date | None = None) -> str:
    """``fdi-bridge(1)`` in roff (``man -l fdi-bridge.1``): synopsis, every command with its
    options (defaults as ``--help`` shows them) and example, the exit status."""
    docs = commands(tree)
    top, rest = docs[0], docs[1:]
    day = (date or dt.date.today()).isoformat()
    out = [
        f'.TH FDI\\-BRIDGE 1 "{day}" "fdi-bridge {_roff(tree.version)}" "User Commands"',
        ".SH NAME",
        "fdi\\-bridge \\- " + _roff(top.description.rstrip(".")),
        ".SH SYNOPSIS",
        "\\fBfdi\\-bridge\\fR [\\fIOPTIONS\\fR] \\fICOMMAND\\fR [\\fIARGS\\fR]",
        ".SH DESCRIPTION",
        _roff("Every command has --help with its defaults and an example. The logging options "
              "(-v, -q, --log-level) are accepted before and after the command. Generated from "
              "the parser by `fdi-bridge man`."),
        ".SH OPTIONS",
    ]
    for o in top.options:
        out += [".TP", _option_head(o), _roff(o.help)]
    out.append(".SH COMMANDS")
    for d in rest:
        out += [f".SS {_roff('fdi-bridge ' + d.path)}", _roff(d.description)]
        if d.subcommands and not d.options and not d.positionals:
            out += [".PP", _roff("kinds: " + ", ".join(d.subcommands))]
        for o in d.positionals + d.options:
            if not set(o.flags) & COMMON:  # on every command: said once, at the top
                out += [".TP", _option_head(o), _roff(o.help)]
        example = d.epilog.split("example:\n", 1)
        if len(example) == 2:
            out += [".PP", "Example:", ".RS", ".nf", _roff(example[1].strip()), ".fi", ".RE"]
    out.append(".SH EXIT STATUS")
    for code, text in EXIT_STATUS:
        out += [".TP", f"\\fB{code}\\fR", _roff(text)]
    out += [".SH SEE ALSO", "The project's README.md and docs/ (architecture, evaluation; "
            "reference/config.md: every configuration key, from \\fBfdi\\-bridge docs\\fR)."]
    return "\n".join(out) + "\n"


# --------------------------------------------------------------------------- markdown reference


_OUTSIDE = str(Path(__file__).resolve().parents[3]) + "/"  # the checkout's parent directory


def _md(text: str) -> str:
    """One line for a table cell; a default under the checkout's parent directory (the shared
    corpus) as the path relative to the project (``../shared/corpus``), the same on every
    machine."""
    return " ".join(text.split()).replace("|", "\\|").replace(_OUTSIDE, "../")


def cli_reference(tree: ParserTree) -> str:
    """``docs/reference/cli.md``: every command with its usage, arguments (defaults as
    ``--help`` shows them) and example, from the parser (``fdi-bridge docs``)."""
    docs = commands(tree)
    top, rest = docs[0], docs[1:]
    out = [
        "# Command-line reference",
        "",
        "Generated from the parser by `fdi-bridge docs --out docs/reference`; do not edit (a "
        "test fails when this page is not what the generator writes). `fdi-bridge COMMAND -h` "
        "prints the same; `fdi-bridge man` writes it as a man page.",
        "",
        _md(top.description),
        "",
        "Options of every command (before or after it): "
        + ", ".join(f"`{', '.join(o.flags)}`" for o in top.options) + ".",
        "",
        "| command | what it does |",
        "|---|---|",
    ]
    out += [f"| [`{d.path}`](#fdi-bridge-{d.path.replace(' ', '-')}) | {_md(d.description)} |"
            for d in rest]
    out.append("")
    for d in rest:
        example = d.epilog.split("example:\n", 1)
        how = f"Usage: `{d.usage.removeprefix('usage: ')}`."
        if len(example) == 2:
            how += f" Example: `{' '.join(example[1].split())}`."
        out += [f"## fdi-bridge {d.path}", "", _md(d.description), "", how, ""]
        if d.subcommands and not d.options and not d.positionals:
            out += ["Kinds: " + ", ".join(f"`{s}`" for s in d.subcommands) + ".", ""]
        rows = [o for o in d.positionals + d.options if not set(o.flags) & COMMON]
        if rows:
            out += ["| argument | value | description |", "|---|---|---|"]
            for o in rows:
                name = ", ".join(o.flags) if o.flags else (o.metavar or "")
                value = "{" + ",".join(o.choices) + "}" if o.choices else (
                    o.metavar if o.flags and o.metavar else "")
                out.append(f"| `{name}` | {f'`{value}`' if value else ''} | {_md(o.help)} |")
            out.append("")
    return "\n".join(out).rstrip("\n") + "\n"
