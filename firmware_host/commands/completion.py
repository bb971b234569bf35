"""``fdi-bridge completion bash``: print a bash completion script generated from the parser
(:func:`firmware_host.commands.docgen.bash_completion`)."""

from __future__ import annotations

import argparse
import sys

from firmware_host.commands.checks import output_file_arg
from firmware_host.commands.docgen import bash_completion


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("shell", choices=("bash",),
                        help="the shell (bash; zsh reads it too after bashcompinit)")
    parser.add_argument("--out", type=output_file_arg, default=None,
                        help="write the script to this file instead of printing it")


def run(args: argparse.Namespace) -> int:
    script = bash_completion(args.parser_tree())
    if args.out is not None:
        args.out.write_text(script, encoding="utf-8")
        print(f"wrote {args.out} (load it with: source {args.out})")
        return 0
    sys.stdout.write(script)
    return 0
