"""``fdi-bridge man``: print the ``fdi-bridge(1)`` man page generated from the parser
(:func:`firmware_host.commands.docgen.man_page`), in roff."""

from __future__ import annotations

import argparse
import sys

from firmware_host.commands.checks import output_file_arg
from firmware_host.commands.docgen import man_page


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", type=output_file_arg, default=None,
                        help="write the page to this file (e.g. fdi-bridge.1; read it with "
                             "man -l FILE) instead of printing it")


def run(args: argparse.Namespace) -> int:
    page = man_page(args.parser_tree())
    if args.out is not None:
        args.out.write_text(page, encoding="utf-8")
        print(f"wrote {args.out} (read it with: man -l {args.out})")
        return 0
    sys.stdout.write(page)
    return 0
